//! `model.safetensors` read as checked f32 tensors, and [`Checkpoint`]: a directory's config and
//! weights in memory.
use super::{CheckpointMeta, CONFIG_FILE, WEIGHTS_FILE};
use anyhow::{bail, Context};
use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

/// One f32 tensor read from the weights file.
#[derive(Clone, Debug, PartialEq)]
pub struct F32Tensor {
    /// Dimensions.
    pub shape: Vec<usize>,
    /// Row-major values.
    pub values: Vec<f32>,
}

/// Reads `dir/model.safetensors`, checking that it holds exactly the tensors `meta` lists, each
/// F32 with the listed shape and finite values.
pub fn read_weights(
    dir: &Path,
    meta: &CheckpointMeta,
) -> anyhow::Result<BTreeMap<String, F32Tensor>> {
    let path = dir.join(WEIGHTS_FILE);
    let bytes = std::fs::read(&path).with_context(|| format!("reading {}", path.display()))?;
    let tensors = safetensors::SafeTensors::deserialize(&bytes)
        .with_context(|| format!("{WEIGHTS_FILE} is not a valid safetensors file"))?;
    let mut present: Vec<String> = tensors.names().into_iter().map(|n| n.to_string()).collect();
    present.sort();
    let expected: Vec<&str> = meta.tensors.iter().map(|t| t.name.as_str()).collect();
    let missing: Vec<&str> = expected
        .iter()
        .copied()
        .filter(|n| !present.iter().any(|p| p == n))
        .collect();
    let unexpected: Vec<&String> = present
        .iter()
        .filter(|p| !expected.contains(&p.as_str()))
        .collect();
    if !missing.is_empty() || !unexpected.is_empty() {
        bail!("{WEIGHTS_FILE} does not match {CONFIG_FILE}: missing tensors {missing:?}, unexpected tensors {unexpected:?}");
    }
    let mut out = BTreeMap::new();
    for spec in &meta.tensors {
        let name = &spec.name;
        let view = tensors
            .tensor(name)
            .with_context(|| format!("tensor `{name}`"))?;
        if view.dtype() != safetensors::Dtype::F32 {
            bail!(
                "tensor `{name}`: dtype {:?} in {WEIGHTS_FILE}, F32 expected",
                view.dtype()
            );
        }
        if view.shape() != spec.shape.as_slice() {
            bail!(
                "tensor `{name}`: shape {:?} in {WEIGHTS_FILE}, {:?} expected from {CONFIG_FILE}",
                view.shape(),
                spec.shape
            );
        }
        let values: Vec<f32> = view
            .data()
            .chunks_exact(4)
            .map(|c| f32::from_le_bytes([c[0], c[1], c[2], c[3]]))
            .collect();
        if let Some(bad) = values.iter().position(|v| !v.is_finite()) {
            bail!(
                "tensor `{name}`: non-finite value {} at flat index {bad}",
                values[bad]
            );
        }
        out.insert(
            name.clone(),
            F32Tensor {
                shape: spec.shape.clone(),
                values,
            },
        );
    }
    Ok(out)
}

/// A validated checkpoint in memory: where it was read from, its config and every tensor.
#[derive(Clone, Debug)]
pub struct Checkpoint {
    /// The checkpoint directory.
    pub dir: PathBuf,
    /// `frmd.json`.
    pub meta: CheckpointMeta,
    /// `model.safetensors`, by name.
    pub tensors: BTreeMap<String, F32Tensor>,
}

impl Checkpoint {
    /// Reads and validates `dir` (config and weights).
    pub fn read(dir: &Path) -> anyhow::Result<Self> {
        let meta = CheckpointMeta::read(dir)?;
        let tensors = read_weights(dir, &meta)?;
        Ok(Checkpoint {
            dir: dir.to_path_buf(),
            meta,
            tensors,
        })
    }

    /// Values of tensor `name`.
    pub fn tensor(&self, name: &str) -> anyhow::Result<&[f32]> {
        self.tensors
            .get(name)
            .map(|t| t.values.as_slice())
            .with_context(|| format!("tensor `{name}` is missing from the checkpoint"))
    }
}
