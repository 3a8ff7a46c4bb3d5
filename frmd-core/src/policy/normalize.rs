//! Per-dimension min/max normalization to `[-1, 1]` (DESIGN.md s.4). [`normalize_value`] and
//! [`denormalize_value`] are the one definition, also used by the exporter's fitted
//! `frmd_export::checkpoint::Normalizer` (which training uses), so the firmware sees
//! bit-identical model inputs:
//! `normalized = 2 (raw - min) / (max - min) - 1`, `raw = (normalized + 1) 0.5 (max - min) + min`;
//! a constant dimension (`max == min`) maps to 0 and back to its constant. Rates (differences per
//! second) scale by `2 / (max - min)` (0 for constant dimensions).

use super::PolicyError;

/// One raw value to `[-1, 1]` with its dimension's bounds (0 for a constant dimension). The one
/// definition of the formula: the runtime's [`RangeNormalizer`] and the exporter's fitted
/// `frmd_export::checkpoint::Normalizer` both call it.
#[inline]
pub fn normalize_value(raw: f32, min: f32, max: f32) -> f32 {
    if max > min {
        2.0 * (raw - min) / (max - min) - 1.0
    } else {
        0.0
    }
}

/// Inverse of [`normalize_value`] (a constant dimension gives its constant).
#[inline]
pub fn denormalize_value(normalized: f32, min: f32, max: f32) -> f32 {
    if max > min {
        (normalized + 1.0) * 0.5 * (max - min) + min
    } else {
        min
    }
}

/// Baked min/max of `D` dimensions (raw units). Invariant (checked by [`Self::validate`]): every
/// bound finite and `min[i] <= max[i]`.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct RangeNormalizer<const D: usize> {
    /// Per-dimension minimum over the training data (raw units).
    pub min: [f32; D],
    /// Per-dimension maximum over the training data (raw units).
    pub max: [f32; D],
}

impl<const D: usize> RangeNormalizer<D> {
    /// Unchecked constructor usable in `const` items; [`Self::validate`] checks the invariant.
    pub const fn new(min: [f32; D], max: [f32; D]) -> Self {
        Self { min, max }
    }

    /// Checks that every bound is finite and `min <= max`.
    pub fn validate(&self) -> Result<(), PolicyError> {
        let ok = self
            .min
            .iter()
            .zip(&self.max)
            .all(|(lo, hi)| lo.is_finite() && hi.is_finite() && lo <= hi);
        if ok {
            Ok(())
        } else {
            Err(PolicyError::InvalidNormalization)
        }
    }

    /// Raw to normalized, element-wise.
    pub fn normalize(&self, raw: &[f32; D], out: &mut [f32; D]) {
        for (((o, v), lo), hi) in out.iter_mut().zip(raw).zip(&self.min).zip(&self.max) {
            *o = normalize_value(*v, *lo, *hi);
        }
    }

    /// Normalized to raw, element-wise (constant dimensions give their constant).
    pub fn denormalize(&self, normalized: &[f32; D], out: &mut [f32; D]) {
        for (((o, v), lo), hi) in out.iter_mut().zip(normalized).zip(&self.min).zip(&self.max) {
            *o = denormalize_value(*v, *lo, *hi);
        }
    }

    /// Raw rate (units/s) to normalized rate (normalized units/s): `rate * 2 / (max - min)`.
    pub fn normalize_rate(&self, raw: &[f32; D], out: &mut [f32; D]) {
        for (((o, v), lo), hi) in out.iter_mut().zip(raw).zip(&self.min).zip(&self.max) {
            *o = if hi > lo { *v * 2.0 / (hi - lo) } else { 0.0 };
        }
    }

    /// Normalized rate to raw rate: `rate * 0.5 (max - min)` (0 for constant dimensions).
    pub fn denormalize_rate(&self, normalized: &[f32; D], out: &mut [f32; D]) {
        for (((o, v), lo), hi) in out.iter_mut().zip(normalized).zip(&self.min).zip(&self.max) {
            *o = if hi > lo { *v * 0.5 * (hi - lo) } else { 0.0 };
        }
    }
}
