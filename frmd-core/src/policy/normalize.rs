//! Per-dimension min/max normalization to `[-1, 1]` (docs/design.md s.4). [`normalize_value`] and
//! [`denormalize_value`] are the one definition, also used by the exporter's fitted
//! `frmd_formats::checkpoint::Normalizer` (which training uses), so the firmware sees
//! bit-identical model inputs:
//! `normalized = 2 (raw - min) / (max - min) - 1`, `raw = (normalized + 1) 0.5 (max - min) + min`;
//! a constant dimension (`max == min`) maps to 0 and back to its constant. Rates (differences per
//! second) scale by `2 / (max - min)` (0 for constant dimensions).

use super::dims::{fixed_row_pairs, fixed_rows};
use super::PolicyError;

/// One raw value to `[-1, 1]` with its dimension's bounds (0 for a constant dimension). The one
/// definition of the formula: the runtime's [`RangeNormalizer`] and the exporter's fitted
/// `frmd_formats::checkpoint::Normalizer` both call it.
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

/// Baked min/max of every dimension (raw units), borrowed (`&'static` baked arrays or blob
/// sections). Invariant (checked by [`Self::validate`]): equal lengths, every bound finite and
/// `min[i] <= max[i]`. Each method processes the common length of its slices.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct RangeNormalizer<'a> {
    /// Per-dimension minimum over the training data (raw units).
    pub min: &'a [f32],
    /// Per-dimension maximum over the training data (raw units).
    pub max: &'a [f32],
}

impl<'a> RangeNormalizer<'a> {
    /// Unchecked constructor usable in `const` items; [`Self::validate`] checks the invariant.
    pub const fn new(min: &'a [f32], max: &'a [f32]) -> Self {
        Self { min, max }
    }

    /// Number of dimensions.
    pub fn len(&self) -> usize {
        self.min.len()
    }

    /// Whether there are no dimensions.
    pub fn is_empty(&self) -> bool {
        self.min.is_empty()
    }

    /// Checks equal lengths, that every bound is finite and `min <= max`.
    pub fn validate(&self) -> Result<(), PolicyError> {
        let ok = self.min.len() == self.max.len()
            && self
                .min
                .iter()
                .zip(self.max)
                .all(|(lo, hi)| lo.is_finite() && hi.is_finite() && lo <= hi);
        if ok {
            Ok(())
        } else {
            Err(PolicyError::InvalidNormalization)
        }
    }

    /// Raw to normalized, element-wise.
    pub fn normalize(&self, raw: &[f32], out: &mut [f32]) {
        for (((o, v), lo), hi) in out.iter_mut().zip(raw).zip(self.min).zip(self.max) {
            *o = normalize_value(*v, *lo, *hi);
        }
    }

    /// Normalized to raw, element-wise (constant dimensions give their constant).
    #[inline]
    pub fn denormalize(&self, normalized: &[f32], out: &mut [f32]) {
        for (((o, v), lo), hi) in out.iter_mut().zip(normalized).zip(self.min).zip(self.max) {
            *o = denormalize_value(*v, *lo, *hi);
        }
    }

    /// Raw rate (units/s) to normalized rate (normalized units/s): `rate * 2 / (max - min)`.
    pub fn normalize_rate(&self, raw: &[f32], out: &mut [f32]) {
        for (((o, v), lo), hi) in out.iter_mut().zip(raw).zip(self.min).zip(self.max) {
            *o = if hi > lo { *v * 2.0 / (hi - lo) } else { 0.0 };
        }
    }

    /// Normalized rate to raw rate: `rate * 0.5 (max - min)` (0 for constant dimensions).
    #[inline]
    pub fn denormalize_rate(&self, normalized: &[f32], out: &mut [f32]) {
        for (((o, v), lo), hi) in out.iter_mut().zip(normalized).zip(self.min).zip(self.max) {
            *o = if hi > lo { *v * 0.5 * (hi - lo) } else { 0.0 };
        }
    }

    /// A trajectory (`[n][k]` positions and rates, `k` = [`Self::len`]) to raw units:
    /// [`Self::denormalize`] and [`Self::denormalize_rate`] per query time. `N` and `K` are the
    /// caller's capacities: when the sizes equal them, the loops have constant trip counts.
    pub fn denormalize_trajectory<const N: usize, const K: usize>(
        &self,
        normalized: (&[f32], &[f32]),
        out: (&mut [f32], &mut [f32]),
    ) {
        let fixed = (
            fixed_rows::<1, K>(self.min),
            fixed_rows::<1, K>(self.max),
            fixed_rows::<N, K>(normalized.0),
            fixed_rows::<N, K>(normalized.1),
        );
        if let (Some(mut min), Some(mut max), Some(positions), Some(velocities)) = fixed {
            if let (Some(min), Some(max), Some(outputs)) = (
                min.next(),
                max.next(),
                fixed_row_pairs::<N, K>(out.0, out.1),
            ) {
                let fixed = Self { min, max };
                for ((pos, vel), (pos_out, vel_out)) in positions.zip(velocities).zip(outputs) {
                    fixed.denormalize(pos, pos_out);
                    fixed.denormalize_rate(vel, vel_out);
                }
            }
            return;
        }
        let k = self.len().max(1);
        let rows = normalized
            .0
            .chunks_exact(k)
            .zip(normalized.1.chunks_exact(k))
            .zip(out.0.chunks_exact_mut(k).zip(out.1.chunks_exact_mut(k)));
        for ((pos, vel), (pos_out, vel_out)) in rows {
            self.denormalize(pos, pos_out);
            self.denormalize_rate(vel, vel_out);
        }
    }
}
