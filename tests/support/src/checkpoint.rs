//! Student checkpoints with random weights, written without candle: `frmd.json` from a model
//! config and `model.safetensors` with every tensor it implies (or deliberately wrong shapes), plus
//! random calibration rows. Only frmd-formats types cross this module, so the exporter's own unit
//! tests can use it too.

use std::path::{Path, PathBuf};

use frmd_core::rng::Rng;
use frmd_core::sigma::SigmaConfig;
use frmd_formats::calibration::CalibrationSet;
use frmd_formats::checkpoint::{
    CheckpointMeta, ModelConfig, Normalization, Normalizer, Role, CONFIG_FILE, WEIGHTS_FILE,
};

/// How the random weights are drawn (a standard normal `g` per value, in tensor order).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Init {
    /// `g / sqrt(fan_in)`, fan-in the last dimension.
    FanIn,
    /// As a trained transformer: LayerNorm scales `1 + 0.1 g`, matrices `g / sqrt(fan_in)`, the
    /// output head a quarter of that (chunks span about [-1, 1], as a trained student's do; few
    /// step sampling feeds a step's output back in), everything else `0.1 g`.
    Transformer,
}

fn value(init: Init, name: &str, shape: &[usize], g: f32) -> f32 {
    match init {
        Init::FanIn => g / (*shape.last().unwrap_or(&1) as f32).sqrt(),
        Init::Transformer => {
            let fan_in = shape.get(1).copied().unwrap_or(1) as f32;
            if ["norm1.weight", "norm2.weight", "final_norm.weight"]
                .iter()
                .any(|n| name.ends_with(n))
            {
                1.0 + 0.1 * g
            } else if name == "transformer.head.weight" {
                0.25 * g / fan_in.sqrt()
            } else if shape.len() == 2 && !name.ends_with("pos_embedding") {
                g / fan_in.sqrt()
            } else {
                0.1 * g
            }
        }
    }
}

/// A fresh (emptied) temporary directory `frmd-<tag>-<pid>`.
pub fn scratch_dir(tag: &str) -> PathBuf {
    let dir = std::env::temp_dir().join(format!("frmd-{tag}-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(&dir).unwrap();
    dir
}

/// The normalization mapping `[-1, 1]` to itself.
pub fn unit_normalization(obs_dim: usize, action_dim: usize) -> Normalization {
    let unit = |dim| Normalizer {
        min: vec![-1.0; dim],
        max: vec![1.0; dim],
    };
    Normalization {
        obs: unit(obs_dim),
        action: unit(action_dim),
    }
}

/// Writes `frmd.json` for `meta` into `dir`.
pub fn write_meta(dir: &Path, meta: &CheckpointMeta) {
    std::fs::write(
        dir.join(CONFIG_FILE),
        serde_json::to_string_pretty(meta).unwrap(),
    )
    .unwrap();
}

/// Writes `model.safetensors` with the tensors `meta` lists, drawn as `init` says from
/// `Rng::new(seed)`; `tweak(name, shape)` may change a shape first (to write a mismatch).
pub fn write_weights(
    dir: &Path,
    meta: &CheckpointMeta,
    seed: u64,
    init: Init,
    tweak: impl Fn(&str, &mut Vec<usize>),
) {
    let mut rng = Rng::new(seed);
    let owned: Vec<(String, Vec<usize>, Vec<u8>)> = meta
        .tensors
        .iter()
        .map(|spec| {
            let mut shape = spec.shape.clone();
            tweak(&spec.name, &mut shape);
            let bytes = (0..shape.iter().product::<usize>())
                .flat_map(|_| value(init, &spec.name, &shape, rng.gaussian()).to_le_bytes())
                .collect();
            (spec.name.clone(), shape, bytes)
        })
        .collect();
    let views: Vec<(String, safetensors::tensor::TensorView<'_>)> = owned
        .iter()
        .map(|(name, shape, bytes)| {
            let view =
                safetensors::tensor::TensorView::new(safetensors::Dtype::F32, shape.clone(), bytes)
                    .unwrap();
            (name.clone(), view)
        })
        .collect();
    std::fs::write(
        dir.join(WEIGHTS_FILE),
        safetensors::serialize(views, None).unwrap(),
    )
    .unwrap();
}

/// Writes a checkpoint of `role` for `model` with `normalization` and random weights into `dir`
/// (default sigma schedule); returns its `frmd.json`.
pub fn write_checkpoint(
    dir: &Path,
    role: Role,
    model: &ModelConfig,
    normalization: Normalization,
    seed: u64,
    init: Init,
) -> CheckpointMeta {
    let mut meta = CheckpointMeta::describe(role, model, SigmaConfig::default());
    meta.normalization = Some(normalization);
    write_meta(dir, &meta);
    write_weights(dir, &meta, seed, init, |_, _| {});
    meta
}

/// `rows` random calibration conditions for `model` (values `0.5 g` clipped to [-1, 1], from
/// `Rng::new(seed)`) with noise seed `noise_seed`.
pub fn calibration_rows(
    model: &ModelConfig,
    rows: usize,
    seed: u64,
    noise_seed: u64,
) -> CalibrationSet {
    let mut rng = Rng::new(seed);
    CalibrationSet {
        cond_dim: model.cond_dim(),
        cond: (0..rows * model.cond_dim())
            .map(|_| (0.5 * rng.gaussian()).clamp(-1.0, 1.0))
            .collect(),
        seed: noise_seed,
    }
}
