//! The normalization stored in `frmd.json`: per-dimension min/max of observations and actions,
//! fitted on the training data and applied with the runtime's own formula.
use anyhow::bail;
use frmd_core::policy::{denormalize_value, normalize_value};
use serde::{Deserialize, Serialize};

/// Per-dimension affine map from raw units to [-1, 1], fitted on training min/max: the bounds
/// that the runtime's `frmd_core::policy::RangeNormalizer` bakes, applied with the same formula
/// (`frmd_core::policy::normalize_value`). Constant dimensions (max == min) map to 0.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Normalizer {
    /// Per-dimension minimum (raw units).
    pub min: Vec<f32>,
    /// Per-dimension maximum (raw units).
    pub max: Vec<f32>,
}

/// Normalizers for observations and actions, fitted together on a training set.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Normalization {
    /// Observations.
    pub obs: Normalizer,
    /// Actions.
    pub action: Normalizer,
}

impl Normalization {
    /// Sizes `obs_dim`/`action_dim`, finite bounds and `min <= max` in every dimension; the
    /// first violation is named (`normalization.obs.min[2]`).
    pub fn validate(&self, obs_dim: usize, action_dim: usize) -> anyhow::Result<()> {
        for (name, n, dim) in [
            ("obs", &self.obs, obs_dim),
            ("action", &self.action, action_dim),
        ] {
            for (bound, values) in [("min", &n.min), ("max", &n.max)] {
                if values.len() != dim {
                    bail!("normalization.{name}.{bound} has {} values, expected {dim} (the model's {name} dimension)", values.len());
                }
                if let Some(i) = values.iter().position(|v| !v.is_finite()) {
                    bail!(
                        "normalization.{name}.{bound}[{i}] is {}, expected a finite number",
                        values[i]
                    );
                }
            }
            if let Some(i) = (0..dim).find(|&i| n.min[i] > n.max[i]) {
                bail!(
                    "normalization.{name}.min[{i}] is {} above max[{i}] {}, expected min <= max",
                    n.min[i],
                    n.max[i]
                );
            }
        }
        Ok(())
    }
}

impl Normalizer {
    /// Per-dimension min/max over the rows of `data` ([rows, dim], row-major). Non-finite values
    /// are ignored; a dimension without finite values gets min = max = 0.
    pub fn fit(data: &[f32], dim: usize) -> Self {
        let mut min = vec![f32::INFINITY; dim];
        let mut max = vec![f32::NEG_INFINITY; dim];
        if dim > 0 {
            for row in data.chunks_exact(dim) {
                for ((lo, hi), &v) in min.iter_mut().zip(max.iter_mut()).zip(row) {
                    if v.is_finite() {
                        *lo = lo.min(v);
                        *hi = hi.max(v);
                    }
                }
            }
        }
        for (lo, hi) in min.iter_mut().zip(max.iter_mut()) {
            if *lo > *hi {
                (*lo, *hi) = (0.0, 0.0);
            }
        }
        Self { min, max }
    }

    /// Widens every dimension whose range is above 0 but below `min_range` to `min_range`,
    /// centred on its midpoint, so sensor jitter in a nearly constant dimension does not become a
    /// full-scale input. Exactly constant dimensions stay constant (they map to 0).
    pub fn with_min_range(mut self, min_range: f32) -> Self {
        for (lo, hi) in self.min.iter_mut().zip(self.max.iter_mut()) {
            let range = *hi - *lo;
            if range > 0.0 && range < min_range {
                let mid = 0.5 * (*lo + *hi);
                (*lo, *hi) = (mid - 0.5 * min_range, mid + 0.5 * min_range);
            }
        }
        self
    }

    /// Number of dimensions.
    pub fn dim(&self) -> usize {
        self.min.len()
    }

    /// Raw to [-1, 1] in place; `x` holds whole rows of `dim` values (a trailing partial row is
    /// mapped with the leading dimensions). Constant dimensions map to 0.
    pub fn normalize(&self, x: &mut [f32]) {
        if self.min.is_empty() {
            return;
        }
        for row in x.chunks_mut(self.min.len()) {
            for ((v, &lo), &hi) in row.iter_mut().zip(&self.min).zip(&self.max) {
                *v = normalize_value(*v, lo, hi);
            }
        }
    }

    /// [-1, 1] to raw in place (inverse of [`Normalizer::normalize`]; constant dimensions map to
    /// their constant).
    pub fn denormalize(&self, x: &mut [f32]) {
        if self.min.is_empty() {
            return;
        }
        for row in x.chunks_mut(self.min.len()) {
            for ((v, &lo), &hi) in row.iter_mut().zip(&self.min).zip(&self.max) {
                *v = denormalize_value(*v, lo, hi);
            }
        }
    }

    /// Normalized units per raw unit for each dimension (0 for constant dimensions); rates and
    /// other differences scale by this factor.
    pub fn scale(&self) -> Vec<f32> {
        self.min
            .iter()
            .zip(&self.max)
            .map(|(&lo, &hi)| if hi > lo { 2.0 / (hi - lo) } else { 0.0 })
            .collect()
    }
}
