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
    /// activations, each operation rounded once, so a re-export gives the same bytes on every
    /// host):
    ///
    /// - `y_j = f(input_scale * 128 (j - 256)) / output_scale` for `j = 0..=512` (`128 (j - 256)`
    ///   is exact in f32), `m_j` the same at the segment's midpoint code `128 (j - 256) + 64`;
    /// - the chord's midpoint error `e_j = (y_j + y_{j+1}) / 2 - m_j`;
    /// - `t_j = clamp(round(y_j - e_j / 2))` for `j < 512` (round half away from zero, clamped to
    ///   the int16 range), `t_512 = clamp(round(y_512))`.
    ///
    /// Lowering each segment's left knot by half its midpoint error (TFLite's `LUTPopulateInt16`
    /// does this too) splits the error of a curved segment between its knots and its middle,
    /// halving the worst case. Unlike TFLite, and unlike the first version of this design, the
    /// error comes from the unrounded values and the knot is rounded once: from rounded values
    /// the correction is one whole code of rounding noise wherever the curvature error is below
    /// a code (it raised SiLU's total error on +-1.5 by 68 %). Fails if a scale is not finite and
    /// positive or `f` returns a non-finite value.
    pub fn build<F: Fn(f32) -> f32>(
        f: F,
        input_scale: f32,
        output_scale: f32,
    ) -> Result<Self, QuantError> {
        let valid = |s: f32| s.is_finite() && s > 0.0;
        if !(valid(input_scale) && valid(output_scale)) {
            return Err(QuantError::InvalidScale);
        }
        let value = |input_code: i32| -> Result<f32, QuantError> {
            let y = f(input_scale * input_code as f32) / output_scale;
            if y.is_finite() {
                Ok(y)
            } else {
                Err(QuantError::NonFiniteValue)
            }
        };
        let code = |y: f32| round_to_i32(y).clamp(i32::from(i16::MIN), i32::from(i16::MAX)) as i16;
        let knot = |j: usize| 128 * (j as i32 - 256);
        let mut values = [0.0_f32; LUT16_LEN];
        for (j, v) in values.iter_mut().enumerate() {
            *v = value(knot(j))?;
        }
        let mut table = [0_i16; LUT16_LEN];
        for (j, (slot, pair)) in table.iter_mut().zip(values.windows(2)).enumerate() {
            let [left, right] = [pair.first(), pair.get(1)].map(|v| v.copied().unwrap_or(0.0));
            let error = (left + right) * 0.5 - value(knot(j) + 64)?;
            *slot = code(left - error * 0.5);
        }
        if let (Some(last), Some(y)) = (table.last_mut(), values.last()) {
            *last = code(*y);
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
