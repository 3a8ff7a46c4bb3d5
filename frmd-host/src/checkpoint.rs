//! Checkpoints: `model.safetensors` (plain f32 tensors, candle VarMap layout) + `frmd.json`
//! (format version, role, model config, ProDMP and sigma configs, normalization, dataset digest,
//! training summary and the expected list of tensors). Loading validates every tensor's name,
//! dtype and shape against the config and names what is wrong.
use crate::data::Normalization;
use crate::models::init::sorted_vars;
use crate::models::{ModelConfig, OwnedNetwork, ProDmpConfig};
use anyhow::{bail, Context};
use candle_core::{Device, Tensor};
use frmd_core::sigma::SigmaConfig;
use serde::{Deserialize, Serialize};
use std::path::Path;

/// Version of the checkpoint layout written by this code.
pub const FORMAT_VERSION: u32 = 1;
pub const WEIGHTS_FILE: &str = "model.safetensors";
pub const CONFIG_FILE: &str = "frmd.json";

/// Which method a checkpoint holds.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum Role {
    Teacher,
    Student,
    Dp,
}

/// `frmd_core::sigma::SigmaConfig` as JSON.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct SigmaJson {
    pub sigma_min: f64,
    pub sigma_max: f64,
    pub rho: f64,
    pub sigma_data: f64,
}

impl From<SigmaConfig> for SigmaJson {
    fn from(s: SigmaConfig) -> Self {
        SigmaJson { sigma_min: s.sigma_min, sigma_max: s.sigma_max, rho: s.rho, sigma_data: s.sigma_data }
    }
}

impl From<SigmaJson> for SigmaConfig {
    fn from(s: SigmaJson) -> Self {
        SigmaConfig { sigma_min: s.sigma_min, sigma_max: s.sigma_max, rho: s.rho, sigma_data: s.sigma_data }
    }
}

/// `frmd_core::prodmp::ProDmpConfig` as JSON (for the exporter; must equal the policy
/// convention for the model's sizes).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct ProDmpJson {
    pub num_dof: usize,
    pub num_basis: usize,
    pub tau: f64,
    pub delay: f64,
    pub alpha: f64,
    pub alpha_phase: f64,
    pub bandwidth_factor: f64,
    pub num_basis_outside: usize,
    pub dt: f64,
    pub weights_scale: f64,
    pub goal_scale: f64,
    pub relative_goal: bool,
    pub auto_scale_basis: bool,
}

impl From<&ProDmpConfig> for ProDmpJson {
    fn from(c: &ProDmpConfig) -> Self {
        ProDmpJson {
            num_dof: c.num_dof,
            num_basis: c.num_basis,
            tau: c.tau,
            delay: c.delay,
            alpha: c.alpha,
            alpha_phase: c.alpha_phase,
            bandwidth_factor: c.bandwidth_factor,
            num_basis_outside: c.num_basis_outside,
            dt: c.dt,
            weights_scale: c.weights_scale,
            goal_scale: c.goal_scale,
            relative_goal: c.relative_goal,
            auto_scale_basis: c.auto_scale_basis,
        }
    }
}

/// Where the training data came from.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct DatasetInfo {
    pub task: String,
    pub path: String,
    /// FNV-1a 64 of the data file's bytes, hex.
    pub digest: String,
    pub windows: usize,
}

/// One tensor the weights file must contain.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct TensorSpec {
    pub name: String,
    pub dtype: String,
    pub shape: Vec<usize>,
}

/// Contents of `frmd.json`.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct CheckpointMeta {
    pub format_version: u32,
    pub role: Role,
    pub model: ModelConfig,
    pub prodmp: Option<ProDmpJson>,
    pub sigma: SigmaJson,
    /// Observation and action normalization (raw units <-> [-1, 1]).
    pub normalization: Option<Normalization>,
    pub dataset: DatasetInfo,
    /// Free-form training summary (steps, seed, losses, timings, evaluation results).
    pub training: serde_json::Value,
    pub tensors: Vec<TensorSpec>,
}

/// FNV-1a 64-bit digest as 16 hex digits.
pub fn fnv1a_hex(bytes: &[u8]) -> String {
    let mut hash: u64 = 0xcbf2_9ce4_8422_2325;
    for &b in bytes {
        hash = (hash ^ u64::from(b)).wrapping_mul(0x100_0000_01b3);
    }
    format!("{hash:016x}")
}

/// Names and shapes of the variables a model config implies, sorted by name.
pub fn expected_tensors(model: &ModelConfig) -> anyhow::Result<Vec<TensorSpec>> {
    let net = OwnedNetwork::new_seeded(model, 0, &Device::Cpu)?;
    Ok(sorted_vars(&net.varmap)
        .into_iter()
        .map(|(name, var)| TensorSpec { name, dtype: "F32".into(), shape: var.dims().to_vec() })
        .collect())
}

impl CheckpointMeta {
    /// A description of `net` for `role`; fill in dataset, normalization and training after.
    pub fn describe(role: Role, net: &OwnedNetwork, sigma: SigmaConfig) -> anyhow::Result<Self> {
        let model = net.net.config().clone();
        Ok(CheckpointMeta {
            format_version: FORMAT_VERSION,
            role,
            prodmp: model.prodmp().as_ref().map(ProDmpJson::from),
            tensors: expected_tensors(&model)?,
            model,
            sigma: sigma.into(),
            normalization: None,
            dataset: DatasetInfo::default(),
            training: serde_json::Value::Null,
        })
    }

    /// Checks the config's internal consistency (version, sizes, ProDMP, sigma, tensor list).
    pub fn validate(&self) -> anyhow::Result<()> {
        if self.format_version != FORMAT_VERSION {
            bail!("{CONFIG_FILE}: format_version {} is not supported (expected {FORMAT_VERSION})", self.format_version);
        }
        self.model.validate().with_context(|| format!("{CONFIG_FILE}: model"))?;
        SigmaConfig::from(self.sigma).validate().map_err(|e| anyhow::anyhow!("{CONFIG_FILE}: sigma: {e}"))?;
        let expected_prodmp = self.model.prodmp().as_ref().map(ProDmpJson::from);
        if self.prodmp != expected_prodmp {
            bail!("{CONFIG_FILE}: prodmp config {:?} differs from the policy convention for this model ({:?})", self.prodmp, expected_prodmp);
        }
        match (self.role, self.prodmp.is_some()) {
            (Role::Dp, true) => bail!("{CONFIG_FILE}: a DP checkpoint must have a raw head"),
            (Role::Teacher | Role::Student, false) => bail!("{CONFIG_FILE}: teacher and student checkpoints need a ProDMP head"),
            _ => {}
        }
        let expected = expected_tensors(&self.model)?;
        if self.tensors != expected {
            bail!("{CONFIG_FILE}: tensor list does not match the model config ({} listed, {} implied)", self.tensors.len(), expected.len());
        }
        Ok(())
    }
}

/// Writes `model.safetensors` and `frmd.json` into `dir` (created if needed).
pub fn save(dir: &Path, meta: &CheckpointMeta, net: &OwnedNetwork) -> anyhow::Result<()> {
    std::fs::create_dir_all(dir).with_context(|| format!("creating {}", dir.display()))?;
    net.varmap.save(dir.join(WEIGHTS_FILE)).with_context(|| format!("writing {}", dir.join(WEIGHTS_FILE).display()))?;
    let json = serde_json::to_string_pretty(meta)?;
    std::fs::write(dir.join(CONFIG_FILE), json).with_context(|| format!("writing {}", dir.join(CONFIG_FILE).display()))?;
    Ok(())
}

/// Reads and validates a checkpoint; every tensor is checked against `frmd.json`.
pub fn load(dir: &Path) -> anyhow::Result<(CheckpointMeta, OwnedNetwork)> {
    let config_path = dir.join(CONFIG_FILE);
    let text = std::fs::read_to_string(&config_path).with_context(|| format!("reading {}", config_path.display()))?;
    let meta: CheckpointMeta = serde_json::from_str(&text).with_context(|| format!("parsing {}", config_path.display()))?;
    meta.validate()?;
    let weights_path = dir.join(WEIGHTS_FILE);
    let bytes = std::fs::read(&weights_path).with_context(|| format!("reading {}", weights_path.display()))?;
    let tensors = safetensors::SafeTensors::deserialize(&bytes)
        .map_err(|e| anyhow::anyhow!("{WEIGHTS_FILE} is not a valid safetensors file: {e}"))?;
    let mut present: Vec<String> = tensors.names().into_iter().map(|n| n.to_string()).collect();
    present.sort();
    let expected: Vec<&str> = meta.tensors.iter().map(|t| t.name.as_str()).collect();
    let missing: Vec<&str> = expected.iter().copied().filter(|n| !present.iter().any(|p| p == n)).collect();
    let unexpected: Vec<&String> = present.iter().filter(|p| !expected.contains(&p.as_str())).collect();
    if !missing.is_empty() || !unexpected.is_empty() {
        bail!("{WEIGHTS_FILE} does not match {CONFIG_FILE}: missing tensors {missing:?}, unexpected tensors {unexpected:?}");
    }
    let net = OwnedNetwork::new_seeded(&meta.model, 0, &Device::Cpu)?;
    for (name, var) in sorted_vars(&net.varmap) {
        let spec = meta.tensors.iter().find(|t| t.name == name).context("internal: spec list")?;
        let view = tensors.tensor(&name).map_err(|e| anyhow::anyhow!("tensor `{name}`: {e}"))?;
        if view.dtype() != safetensors::Dtype::F32 {
            bail!("tensor `{name}`: dtype {:?} in {WEIGHTS_FILE}, F32 expected", view.dtype());
        }
        if view.shape() != spec.shape.as_slice() {
            bail!("tensor `{name}`: shape {:?} in {WEIGHTS_FILE}, {:?} expected from {CONFIG_FILE}", view.shape(), spec.shape);
        }
        let values: Vec<f32> = view.data().chunks_exact(4).map(|c| f32::from_le_bytes([c[0], c[1], c[2], c[3]])).collect();
        if let Some(bad) = values.iter().position(|v| !v.is_finite()) {
            bail!("tensor `{name}`: non-finite value {} at flat index {bad}", values[bad]);
        }
        var.set(&Tensor::from_vec(values, spec.shape.as_slice(), &Device::Cpu)?)?;
    }
    Ok((meta, net))
}

#[cfg(test)]
mod tests;
