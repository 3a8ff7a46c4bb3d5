//! Calibration rows ([`CalibrationSet`]) and their file, `calibration.safetensors` beside a
//! student checkpoint: `cond` [R, m O + 2 K] f32 (normalized `[obs history, y0, v0]` rows from the
//! training windows) and metadata `seed` (the noise seed), so that exporting needs only the
//! checkpoint directory.
use anyhow::{bail, Context};
use frmd_core::rng::Rng;
use std::collections::BTreeMap;
use std::path::Path;

/// Calibration conditions: rows of `[obs history, y0, v0]` in normalized units (v0 per second),
/// as in training windows. Noise is drawn per row from `frmd_core::rng::Rng::new(seed + row)`.
#[derive(Clone, Debug, PartialEq)]
pub struct CalibrationSet {
    /// Width of one row (`m O + 2 K`).
    pub cond_dim: usize,
    /// Row-major conditions.
    pub cond: Vec<f32>,
    /// Seed of the per-row noise streams.
    pub seed: u64,
}

impl CalibrationSet {
    /// Number of whole rows.
    pub fn rows(&self) -> usize {
        self.cond.len().checked_div(self.cond_dim).unwrap_or(0)
    }

    /// Row `row` (empty past the end).
    pub fn row(&self, row: usize) -> &[f32] {
        let start = row.saturating_mul(self.cond_dim);
        self.cond
            .get(start..start.saturating_add(self.cond_dim))
            .unwrap_or(&[])
    }

    /// Noise of row `row` for `steps` steps of `traj` values.
    pub fn noise(&self, row: usize, steps: usize, traj: usize) -> Vec<f32> {
        let mut rng = Rng::new(self.seed.wrapping_add(row as u64));
        let mut z = vec![0.0; steps * traj];
        rng.fill_gaussian(&mut z);
        z
    }
}

/// Writes `set` to `path`.
pub fn write(path: &Path, set: &CalibrationSet) -> anyhow::Result<()> {
    let rows = set.rows();
    if rows * set.cond_dim != set.cond.len() || rows == 0 {
        bail!(
            "calibration set: {} values are not whole rows of {}",
            set.cond.len(),
            set.cond_dim
        );
    }
    let bytes: Vec<u8> = set.cond.iter().flat_map(|v| v.to_le_bytes()).collect();
    let view = safetensors::tensor::TensorView::new(
        safetensors::Dtype::F32,
        vec![rows, set.cond_dim],
        &bytes,
    )
    .context("calibration tensor")?;
    let meta = BTreeMap::from([("seed".to_string(), set.seed.to_string())]);
    let data = crate::safetensors_bytes::serialize([("cond", view)], &meta)
        .context("serializing calibration")?;
    crate::artifact::write_atomic(path, &data)
}

/// Reads a calibration file, checking its row width against `cond_dim`.
pub fn read(path: &Path, cond_dim: usize) -> anyhow::Result<CalibrationSet> {
    let bytes = std::fs::read(path).with_context(|| format!("reading {}", path.display()))?;
    let (_, meta) = safetensors::SafeTensors::read_metadata(&bytes)
        .with_context(|| path.display().to_string())?;
    let seed = meta
        .metadata()
        .as_ref()
        .and_then(|m| m.get("seed"))
        .and_then(|s| s.parse().ok())
        .with_context(|| format!("{}: missing or bad metadata `seed`", path.display()))?;
    let file = safetensors::SafeTensors::deserialize(&bytes)
        .with_context(|| path.display().to_string())?;
    let view = file
        .tensor("cond")
        .with_context(|| format!("{}: tensor `cond`", path.display()))?;
    if view.dtype() != safetensors::Dtype::F32
        || view.shape().len() != 2
        || view.shape()[1] != cond_dim
    {
        bail!(
            "{}: tensor `cond` is {:?} {:?}, expected F32 [rows, {cond_dim}]",
            path.display(),
            view.dtype(),
            view.shape()
        );
    }
    let cond: Vec<f32> = view
        .data()
        .chunks_exact(4)
        .map(|c| f32::from_le_bytes([c[0], c[1], c[2], c[3]]))
        .collect();
    if cond.iter().any(|v| !v.is_finite()) {
        bail!("{}: non-finite calibration value", path.display());
    }
    Ok(CalibrationSet {
        cond_dim,
        cond,
        seed,
    })
}
