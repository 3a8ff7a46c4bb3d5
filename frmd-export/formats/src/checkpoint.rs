//! Checkpoints without candle: `frmd.json` (the one schema, also used by frmd-host's candle
//! loader) and `model.safetensors` read as plain f32 tensors. Every tensor's name, dtype and
//! shape is checked against the config and any mismatch is named.
//!
//! Variable names (candle `VarBuilder` prefixes; linear weights `[out, in]`):
//! - MLP: `mlp.layers.{i}.weight` / `.bias`, `i` = 0 .. hidden count (the last is the output);
//! - transformer: `transformer.{traj_in,cond_in,noise_in,head}.{weight,bias}`,
//!   `transformer.pos_embedding` `[n + 2, W]`, `transformer.final_norm.{weight,bias}` and per
//!   block `transformer.blocks.{i}.{norm1,qkv,proj,norm2,fc1,fc2}.{weight,bias}`.
mod config;
mod normalization;
mod weights;

pub use config::{Activation, BackboneConfig, HeadConfig, ModelConfig, ProDmpOutput};
pub use normalization::{Normalization, Normalizer};
pub use weights::{read_weights, Checkpoint, F32Tensor};

use anyhow::{bail, Context};
use frmd_core::prodmp::ProDmpConfig;
use frmd_core::sigma::SigmaConfig;
use serde::{Deserialize, Serialize};
use std::path::Path;

/// Version of the checkpoint layout.
pub const FORMAT_VERSION: u32 = 1;
/// Weights file inside a checkpoint directory.
pub const WEIGHTS_FILE: &str = "model.safetensors";
/// Config file inside a checkpoint directory.
pub const CONFIG_FILE: &str = "frmd.json";
/// Calibration inputs written beside a student checkpoint (see [`crate::calibration`]).
pub const CALIBRATION_FILE: &str = "calibration.safetensors";

/// Which method a checkpoint holds.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum Role {
    /// The multi-step diffusion teacher.
    Teacher,
    /// The one-step consistency student (what the exporter takes).
    Student,
    /// The diffusion-policy baseline.
    Dp,
}

/// The role as `frmd.json` spells it: `teacher`, `student`, `dp`.
impl std::fmt::Display for Role {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(match self {
            Role::Teacher => "teacher",
            Role::Student => "student",
            Role::Dp => "dp",
        })
    }
}

/// Where the training data came from.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct DatasetInfo {
    /// The task the demonstrations are of.
    pub task: String,
    /// The data file as given to training.
    pub path: String,
    /// FNV-1a 64 of the data file's bytes, hex.
    pub digest: String,
    /// Training windows cut from it.
    pub windows: usize,
}

/// One tensor the weights file must contain.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct TensorSpec {
    /// Variable name (candle `VarBuilder` path).
    pub name: String,
    /// Element type, `F32`.
    pub dtype: String,
    /// Dimensions.
    pub shape: Vec<usize>,
}

/// Contents of `frmd.json`.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct CheckpointMeta {
    /// [`FORMAT_VERSION`].
    pub format_version: u32,
    /// Which method the checkpoint holds.
    pub role: Role,
    /// The network.
    pub model: ModelConfig,
    /// The decoder of a ProDMP head (must equal [`ModelConfig::prodmp`], the policy convention
    /// for the model's sizes); `None` for a raw head.
    pub prodmp: Option<ProDmpConfig>,
    /// The noise schedule.
    pub sigma: SigmaConfig,
    /// Observation and action normalization (raw units <-> [-1, 1]).
    pub normalization: Option<Normalization>,
    /// The training data.
    pub dataset: DatasetInfo,
    /// Free-form training summary (steps, seed, losses, timings, evaluation results).
    pub training: serde_json::Value,
    /// The tensors of `model.safetensors` ([`expected_tensors`] of the model).
    pub tensors: Vec<TensorSpec>,
}

/// FNV-1a 64-bit digest as 16 hex digits.
pub fn fnv1a_hex(bytes: &[u8]) -> String {
    format!("{:016x}", frmd_core::hash::Fnv1a64::of(bytes))
}

/// Names and shapes of the variables a model config implies, sorted by name (the layout of
/// frmd-host's candle models; a frmd-host test checks it against their `VarMap`).
pub fn expected_tensors(model: &ModelConfig) -> Vec<TensorSpec> {
    let mut specs = Vec::new();
    let mut push = |name: String, shape: Vec<usize>| {
        specs.push(TensorSpec {
            name,
            dtype: "F32".into(),
            shape,
        })
    };
    let linear =
        |push: &mut dyn FnMut(String, Vec<usize>), prefix: &str, input: usize, output: usize| {
            push(format!("{prefix}.weight"), vec![output, input]);
            push(format!("{prefix}.bias"), vec![output]);
        };
    match &model.backbone {
        BackboneConfig::Mlp { hidden, .. } => {
            let mut width = model.cond_dim() + model.traj_dim() + model.embed_dim;
            for (i, &next) in hidden.iter().chain([&model.output_dim()]).enumerate() {
                linear(&mut push, &format!("mlp.layers.{i}"), width, next);
                width = next;
            }
        }
        BackboneConfig::Transformer { layers, width, .. } => {
            let w = *width;
            let tokens = model.horizon + 2;
            linear(&mut push, "transformer.traj_in", model.action_dim, w);
            linear(&mut push, "transformer.cond_in", model.cond_dim(), w);
            linear(&mut push, "transformer.noise_in", model.embed_dim, w);
            linear(
                &mut push,
                "transformer.head",
                tokens * w,
                model.output_dim(),
            );
            push("transformer.pos_embedding".into(), vec![tokens, w]);
            push("transformer.final_norm.weight".into(), vec![w]);
            push("transformer.final_norm.bias".into(), vec![w]);
            for i in 0..*layers {
                let p = format!("transformer.blocks.{i}");
                for norm in ["norm1", "norm2"] {
                    push(format!("{p}.{norm}.weight"), vec![w]);
                    push(format!("{p}.{norm}.bias"), vec![w]);
                }
                linear(&mut push, &format!("{p}.qkv"), w, 3 * w);
                linear(&mut push, &format!("{p}.proj"), w, w);
                linear(&mut push, &format!("{p}.fc1"), w, 4 * w);
                linear(&mut push, &format!("{p}.fc2"), 4 * w, w);
            }
        }
    }
    specs.sort_by(|a, b| a.name.cmp(&b.name));
    specs
}

impl CheckpointMeta {
    /// A description of a `model` for `role`; fill in dataset, normalization and training after.
    pub fn describe(role: Role, model: &ModelConfig, sigma: SigmaConfig) -> Self {
        CheckpointMeta {
            format_version: FORMAT_VERSION,
            role,
            prodmp: model.prodmp(),
            tensors: expected_tensors(model),
            model: model.clone(),
            sigma,
            normalization: None,
            dataset: DatasetInfo::default(),
            training: serde_json::Value::Null,
        }
    }

    /// Checks the config's internal consistency (version, sizes, ProDMP, sigma, tensor list); an
    /// error names the field (`model.horizon`, `sigma.sigma_max`, `tensors[3]`).
    pub fn validate(&self) -> anyhow::Result<()> {
        if self.format_version != FORMAT_VERSION {
            bail!(
                "format_version {} is not supported (expected {FORMAT_VERSION})",
                self.format_version
            );
        }
        self.model.validate()?;
        validate_sigma(&self.sigma)?;
        let expected_prodmp = self.model.prodmp();
        let same = match (&self.prodmp, &expected_prodmp) {
            (Some(a), Some(b)) => prodmp_matches(a, b),
            (a, b) => a == b,
        };
        if !same {
            bail!(
                "{}",
                first_difference("prodmp", &self.prodmp, &expected_prodmp)
            );
        }
        if let Some(norm) = &self.normalization {
            norm.validate(self.model.obs_dim, self.model.action_dim)?;
        }
        match (self.role, self.prodmp.is_some()) {
            (Role::Dp, true) => bail!("a DP checkpoint must have a raw head"),
            (Role::Teacher | Role::Student, false) => {
                bail!("teacher and student checkpoints need a ProDMP head")
            }
            _ => {}
        }
        let expected = expected_tensors(&self.model);
        if self.tensors != expected {
            let listed = |t: &TensorSpec| format!("`{}` {} {:?}", t.name, t.dtype, t.shape);
            let detail = match self
                .tensors
                .iter()
                .zip(&expected)
                .enumerate()
                .find(|(_, (a, b))| a != b)
            {
                Some((i, (have, want))) => format!(
                    "tensors[{i}] is {}, the model config implies {}",
                    listed(have),
                    listed(want)
                ),
                None if self.tensors.len() > expected.len() => format!(
                    "tensors[{}] {} is not implied by the model config",
                    expected.len(),
                    listed(&self.tensors[expected.len()])
                ),
                None => format!(
                    "tensor {} implied by the model config is not listed",
                    listed(&expected[self.tensors.len()])
                ),
            };
            bail!(
                "{detail} ({} listed, {} implied)",
                self.tensors.len(),
                expected.len()
            );
        }
        Ok(())
    }

    /// Reads and validates `dir/frmd.json`.
    pub fn read(dir: &Path) -> anyhow::Result<Self> {
        let path = dir.join(CONFIG_FILE);
        let bytes = std::fs::read(&path).with_context(|| format!("reading {}", path.display()))?;
        Self::from_json(&bytes).with_context(|| dir.display().to_string())
    }

    /// Parses and validates the bytes of a `frmd.json` (what [`Self::read`] does after reading
    /// the file; the entry point of the checkpoint-config fuzz target).
    pub fn from_json(bytes: &[u8]) -> anyhow::Result<Self> {
        let meta: CheckpointMeta = serde_json::from_slice(bytes).context(CONFIG_FILE)?;
        meta.validate().context(CONFIG_FILE)?;
        Ok(meta)
    }
}

/// The largest `sigma_max` a checkpoint may declare (EDM uses 80; far larger levels overflow the
/// samplers' f32 arithmetic).
pub const MAX_SIGMA: f64 = 1e4;

/// The sigma config field by field: finite, positive, `sigma_min < sigma_max <= MAX_SIGMA`.
fn validate_sigma(s: &SigmaConfig) -> anyhow::Result<()> {
    for (field, value) in [
        ("sigma_min", s.sigma_min),
        ("sigma_max", s.sigma_max),
        ("rho", s.rho),
        ("sigma_data", s.sigma_data),
    ] {
        if !(value.is_finite() && value > 0.0) {
            bail!("sigma.{field} is {value}, expected a finite number > 0");
        }
    }
    if s.sigma_max > MAX_SIGMA {
        bail!(
            "sigma.sigma_max is {}, expected at most {MAX_SIGMA}",
            s.sigma_max
        );
    }
    if s.sigma_min >= s.sigma_max {
        bail!(
            "sigma.sigma_min {} is not below sigma.sigma_max {}, expected sigma_min < sigma_max",
            s.sigma_min,
            s.sigma_max
        );
    }
    for (field, value) in [("rho", s.rho), ("sigma_data", s.sigma_data)] {
        if value > MAX_SIGMA {
            bail!("sigma.{field} is {value}, expected at most {MAX_SIGMA}");
        }
    }
    s.validate().context("sigma")
}

/// The first field in which `have` and `want` differ, as `path.field is X, expected Y`.
fn first_difference<T: Serialize>(path: &str, have: &T, want: &T) -> String {
    fn walk(path: String, have: &serde_json::Value, want: &serde_json::Value) -> Option<String> {
        use serde_json::Value;
        match (have, want) {
            (Value::Object(a), Value::Object(b)) => b.iter().find_map(|(k, w)| {
                walk(format!("{path}.{k}"), a.get(k).unwrap_or(&Value::Null), w)
            }),
            (Value::Number(a), Value::Number(b))
                if a.as_f64().zip(b.as_f64()).is_some_and(|(x, y)| {
                    x == y || (x - y).abs() <= 1e-12 * x.abs().max(y.abs())
                }) =>
            {
                None
            }
            (a, b) if a != b => Some(format!(
                "{path} is {a}, expected {b} (implied by the model config)"
            )),
            _ => None,
        }
    }
    let (have, want) = (
        serde_json::to_value(have).unwrap_or_default(),
        serde_json::to_value(want).unwrap_or_default(),
    );
    walk(path.to_string(), &have, &want)
        .unwrap_or_else(|| format!("{path} differs from the config the model implies"))
}

/// Equal up to the last bits of the f64 fields: serde_json's default parser may read a written
/// f64 back one unit in the last place off (e.g. tau = 12 x 0.0125f32 as f64), so a checkpoint's
/// recorded ProDMP config is compared with the recomputed one at a relative 1e-12.
pub fn prodmp_matches(a: &ProDmpConfig, b: &ProDmpConfig) -> bool {
    let close = |x: f64, y: f64| x == y || (x - y).abs() <= 1e-12 * x.abs().max(y.abs());
    let floats = |p: &ProDmpConfig| {
        [
            p.tau,
            p.delay,
            p.alpha,
            p.alpha_phase,
            p.bandwidth_factor,
            p.dt,
            p.weights_scale,
            p.goal_scale,
        ]
    };
    let exact = |p: &ProDmpConfig| {
        (
            p.num_dof,
            p.num_basis,
            p.num_basis_outside,
            p.relative_goal,
            p.auto_scale_basis,
        )
    };
    exact(a) == exact(b) && floats(a).iter().zip(floats(b)).all(|(&x, y)| close(x, y))
}
