//! Checkpoints: `model.safetensors` (plain f32 tensors, candle VarMap layout) + `frmd.json`
//! (format version, role, model config, ProDMP and sigma configs, normalization, dataset digest,
//! training summary and the expected list of tensors). The schema, its validation and the
//! candle-free tensor reader live in `frmd_formats::checkpoint` (one definition, shared with the
//! exporter); this module adds candle save/load.
use crate::models::init::sorted_vars;
use crate::models::OwnedNetwork;
use anyhow::Context;
use candle_core::{Device, Tensor};
use frmd_formats::artifact::{write_atomic, write_atomic_with};
use std::path::Path;

pub use frmd_formats::checkpoint::{
    expected_tensors, fnv1a_hex, read_weights, CheckpointMeta, DatasetInfo, Role, TensorSpec,
    CALIBRATION_FILE, CONFIG_FILE, FORMAT_VERSION, WEIGHTS_FILE,
};

/// Writes `model.safetensors` and `frmd.json` into `dir` (created if needed).
pub fn save(dir: &Path, meta: &CheckpointMeta, net: &OwnedNetwork) -> anyhow::Result<()> {
    std::fs::create_dir_all(dir).with_context(|| format!("creating {}", dir.display()))?;
    write_atomic_with(&dir.join(WEIGHTS_FILE), |tmp| Ok(net.varmap.save(tmp)?))?;
    save_meta(dir, meta)
}

/// Rewrites `frmd.json` of a saved checkpoint (e.g. with the final evaluation added).
pub fn save_meta(dir: &Path, meta: &CheckpointMeta) -> anyhow::Result<()> {
    write_atomic(
        &dir.join(CONFIG_FILE),
        serde_json::to_string_pretty(meta)?.as_bytes(),
    )
}

/// Reads and validates a checkpoint; every tensor is checked against `frmd.json`.
pub fn load(dir: &Path) -> anyhow::Result<(CheckpointMeta, OwnedNetwork)> {
    let meta = CheckpointMeta::read(dir)?;
    let tensors = read_weights(dir, &meta).with_context(|| format!("{}", dir.display()))?;
    let net = OwnedNetwork::new_seeded(&meta.model, 0, &Device::Cpu)?;
    for (name, var) in sorted_vars(&net.varmap) {
        let tensor = tensors.get(&name).with_context(|| format!("{WEIGHTS_FILE}: variable `{name}` of the model is not in {CONFIG_FILE}'s tensor list"))?;
        var.set(&Tensor::from_vec(
            tensor.values.clone(),
            tensor.shape.as_slice(),
            &Device::Cpu,
        )?)?;
    }
    Ok((meta, net))
}

#[cfg(test)]
mod tests;
