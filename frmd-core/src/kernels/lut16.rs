//! Interpolated int16 activation tables (the 16x8 scheme's SiLU / Mish / GELU): 513 int16 knots
//! over the whole int16 input code range, one knot every 128 codes, linear interpolation in
//! integers. The lookup is TFLite's (`LUTLookup` for int16) in the convex form
//! `(t[i] (128 - f) + t[i+1] f + 64) >> 7`, so it needs no int16 slope, is branch-free and gives
//! the same bits on every target; the builder is frmd's own (its f32 activation definitions on
//! an exact grid of codes, with a midpoint correction); see `/work/notes/int16-design.md` 3.5.

use crate::quant::{round_to_i32, QuantError};

/// Knots of an int16 table: input codes `128 (j - 256)` for `j = 0..=512` (entry 512 is code
/// 32768, one past the range: the right end of the last segment).
pub const LUT16_LEN: usize = 513;

/// What a layer borrows (a baked `static`, or zero-copy from a blob): entry `j` is the output
/// code at input code `128 (j - 256)`.
pub type Lut16Table = [i16; LUT16_LEN];

/// The output code of `table` at input code `x`: with `i = (x >> 7) + 256` (0..=511) and
/// `f = x & 127`, `(t[i] (128 - f) + t[i+1] f + 64) >> 7`.
///
/// Equal to TFLite's `t[i] + ((t[i+1] - t[i]) f + 64) >> 7` (adding the multiple `128 t[i]`
/// commutes with the floor division), including where TFLite's int16 slope would overflow. The
/// result lies between `t[i]` and `t[i+1]`, so it needs no saturation; the products stay below
/// `2^22`.
#[inline(always)]
pub fn lookup(table: &Lut16Table, x: i16) -> i16 {
    let x = i32::from(x);
    // (x >> 7) + 256 is in 0..=511 for every i16; the mask lets the compiler see it.
    let index = (((x >> 7) + 256) & 511) as usize;
    let fraction = x & 127;
    let left = i32::from(table.get(index).copied().unwrap_or(0));
    let right = i32::from(table.get(index + 1).copied().unwrap_or(0));
    ((left * (128 - fraction) + right * fraction + 64) >> 7) as i16
}

/// Replaces every element of `data` by its value through `table`.
pub fn apply_in_place(table: &Lut16Table, data: &mut [i16]) {
    for value in data.iter_mut() {
        *value = lookup(table, *value);
    }
}

/// An int16 -> int16 function as an owned table (see [`Lut16Table`]).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Lut16 {
    /// The knots, entry `j` at input code `128 (j - 256)`.
    pub table: Lut16Table,
}

impl Lut16 {
    /// Wraps a baked table.
    pub const fn from_table(table: Lut16Table) -> Self {
        Self { table }
    }

    /// The table of `f` from symmetric int16 input codes at scale `input_scale` to symmetric
    /// int16 output codes at scale `output_scale` (f32 arithmetic with frmd's libm-based
    /// activations, so a re-export gives the same bytes on every host):
    ///
    /// - `v_j = clamp(round(f(input_scale * 128 (j - 256)) / output_scale))` for `j = 0..=512`
    ///   (`128 (j - 256)` is exact in f32, the product rounds once; rounding half away from zero,
    ///   clamped to the int16 range);
    /// - `mid_j` the same at the segment's midpoint code `128 (j - 256) + 64`, `j < 512`;
    /// - `lin_j = (v_j + v_{j+1} + 1) >> 1` (what the lookup gives at the midpoint);
    /// - `t_j = clamp(v_j - round_half_away((lin_j - mid_j) / 2))`, `t_512 = v_512`.
    ///
    /// The correction lowers each segment by half its midpoint error (TFLite's
    /// `LUTPopulateInt16` does the same on its own, slightly different grid), which halves the
    /// interpolation error of curved segments. Fails if a scale is not finite and positive or
    /// `f` returns a non-finite value.
    pub fn build<F: Fn(f32) -> f32>(
        f: F,
        input_scale: f32,
        output_scale: f32,
    ) -> Result<Self, QuantError> {
        let valid = |s: f32| s.is_finite() && s > 0.0;
        if !(valid(input_scale) && valid(output_scale)) {
            return Err(QuantError::InvalidScale);
        }
        let code = |input_code: i32| -> Result<i32, QuantError> {
            let y = f(input_scale * input_code as f32);
            if !y.is_finite() {
                return Err(QuantError::NonFiniteValue);
            }
            Ok(round_to_i32(y / output_scale).clamp(i32::from(i16::MIN), i32::from(i16::MAX)))
        };
        let knot = |j: usize| 128 * (j as i32 - 256);
        let mut values = [0_i32; LUT16_LEN];
        for (j, value) in values.iter_mut().enumerate() {
            *value = code(knot(j))?;
        }
        let mut table = [0_i16; LUT16_LEN];
        for (j, (slot, pair)) in table.iter_mut().zip(values.windows(2)).enumerate() {
            let [left, right] = [pair.first(), pair.get(1)].map(|v| v.copied().unwrap_or(0));
            let midpoint = code(knot(j) + 64)?;
            let interpolated = (left + right + 1) >> 1;
            let error = interpolated - midpoint;
            // round_half_away(error / 2) for an integer error.
            let correction = (error + error.signum()) / 2;
            *slot = (left - correction).clamp(i32::from(i16::MIN), i32::from(i16::MAX)) as i16;
        }
        if let (Some(last), Some(value)) = (table.last_mut(), values.last()) {
            *last = *value as i16;
        }
        Ok(Self { table })
    }

    /// The output code at input code `x`.
    #[inline]
    pub fn lookup(&self, x: i16) -> i16 {
        lookup(&self.table, x)
    }

    /// Replaces every element of `data` by its value through the table.
    pub fn apply_in_place(&self, data: &mut [i16]) {
        apply_in_place(&self.table, data);
    }
}

#[cfg(test)]
mod tests;
