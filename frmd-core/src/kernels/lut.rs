//! 256-entry int8 lookup-table activations (Mish, SiLU, GELU, ...), built by the exporter from an
//! f32 function and the input/output quantization parameters.

use crate::quant::{dequantize, quantize, QuantError, QuantParams};

/// The outputs of an int8 -> int8 function for the input codes -128, -127, ..., 127, in that
/// order: what a layer borrows (from a baked `static` or, zero-copy, from a blob).
pub type LutTable = [i8; 256];

/// The output code of `table` for input code `x`.
#[inline]
pub fn lookup(table: &LutTable, x: i8) -> i8 {
    // `x + 128` maps -128..=127 to 0..=255, always in bounds.
    let index = (i32::from(x) + 128) as usize;
    table.get(index).copied().unwrap_or(x)
}

/// [`apply_in_place`] eight codes at a time: one 64-bit load and one store per eight codes, the
/// lookups on the word's bytes in registers (same results). The byte loop stores each code beside
/// the one it loads next; on the AMD EPYC (Zen 4) of this project's machine that cost ~30 cycles
/// per code (~2 us per 256-wide layer, this version 26-58 ns), so the x86 int8 path takes this
/// one (docs/design.md section 8).
pub fn apply_in_place_by_words(table: &LutTable, data: &mut [i8]) {
    let (words, rest) = data.as_chunks_mut::<8>();
    for word in words {
        let codes = u64::from_le_bytes(word.map(|code| code as u8));
        let mut mapped = 0_u64;
        for byte in 0..8 {
            let code = (codes >> (8 * byte)) as u8 as i8;
            mapped |= u64::from(lookup(table, code) as u8) << (8 * byte);
        }
        *word = mapped.to_le_bytes().map(|byte| byte as i8);
    }
    apply_in_place(table, rest);
}

/// Replaces every element of `data` by its entry in `table`.
pub fn apply_in_place(table: &LutTable, data: &mut [i8]) {
    for value in data.iter_mut() {
        *value = lookup(table, *value);
    }
}

/// An int8 -> int8 function as an owned table: `table[x + 128]` is the output for input code `x`.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Lut8 {
    /// Outputs for the input codes -128, -127, ..., 127, in that order.
    pub table: LutTable,
}

impl Lut8 {
    /// Wraps a baked table.
    pub const fn from_table(table: [i8; 256]) -> Self {
        Self { table }
    }

    /// `table[q + 128] = quantize(f(dequantize(q, input)), output)` for every int8 code `q`
    /// (rounding: [`crate::quant::quantize`], half away from zero, saturating to int8).
    ///
    /// The result is within half an output step of `f` wherever `f` stays inside the output range.
    /// Fails if either parameter set is invalid or `f` returns a non-finite value.
    pub fn build<F: Fn(f32) -> f32>(
        f: F,
        input: QuantParams,
        output: QuantParams,
    ) -> Result<Self, QuantError> {
        input.validate()?;
        output.validate()?;
        let mut table = [0_i8; 256];
        for (code, slot) in (i8::MIN..=i8::MAX).zip(table.iter_mut()) {
            let y = f(dequantize(code, input));
            if !y.is_finite() {
                return Err(QuantError::NonFiniteValue);
            }
            *slot = quantize(y, output);
        }
        Ok(Self { table })
    }

    /// The output code for input code `x`.
    #[inline]
    pub fn lookup(&self, x: i8) -> i8 {
        lookup(&self.table, x)
    }

    /// Replaces every element of `data` by its table entry.
    pub fn apply_in_place(&self, data: &mut [i8]) {
        apply_in_place(&self.table, data);
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::kernels::activation::{gelu, mish, silu};

    #[test]
    fn word_lookups_equal_byte_lookups() {
        // A table with a distinct entry per code, on every length around the 8-code words.
        let mut table = [0_i8; 256];
        for (i, t) in table.iter_mut().enumerate() {
            *t = (i.wrapping_mul(97) ^ 0x5A) as u8 as i8;
        }
        for len in 0..=41 {
            let data: [i8; 41] = core::array::from_fn(|i| (i as u8).wrapping_mul(151) as i8);
            let (mut bytes, mut words) = (data, data);
            apply_in_place(&table, &mut bytes[..len]);
            apply_in_place_by_words(&table, &mut words[..len]);
            assert_eq!(bytes, words, "length {len}");
            assert!(words[..len]
                .iter()
                .zip(&data)
                .all(|(&w, &x)| w == lookup(&table, x)));
        }
    }

    #[test]
    fn index_order() {
        let mut table = [0_i8; 256];
        for (i, t) in table.iter_mut().enumerate() {
            *t = (i as i32 - 128) as i8;
        }
        let lut = Lut8::from_table(table);
        for x in i8::MIN..=i8::MAX {
            assert_eq!(lut.lookup(x), x);
        }
        let mut data = [-128_i8, -1, 0, 1, 127];
        let negate = Lut8::build(
            |v| -v,
            QuantParams::new(1.0, 0).unwrap(),
            QuantParams::new(1.0, 0).unwrap(),
        )
        .unwrap();
        negate.apply_in_place(&mut data);
        assert_eq!(data, [127, 1, 0, -1, -127]);
    }

    #[test]
    fn activations_within_one_lsb() {
        type Activation = fn(f32) -> f32;
        let functions: [(&str, Activation); 3] = [("silu", silu), ("mish", mish), ("gelu", gelu)];
        let input_ranges = [(-8.0_f32, 8.0_f32), (-3.0, 5.0), (-0.5, 12.0), (-20.0, 1.0)];
        for (name, f) in functions {
            for (lo, hi) in input_ranges {
                let input = QuantParams::from_range(lo, hi).unwrap();
                // Output range from the function's values on the input grid.
                let (mut omin, mut omax) = (f32::MAX, f32::MIN);
                for q in i8::MIN..=i8::MAX {
                    let y = f(input.dequantize(q));
                    omin = omin.min(y);
                    omax = omax.max(y);
                }
                let output = QuantParams::from_range(omin, omax).unwrap();
                let lut = Lut8::build(f, input, output).unwrap();
                let lo_real = output.dequantize(i8::MIN);
                let hi_real = output.dequantize(i8::MAX);
                for q in i8::MIN..=i8::MAX {
                    let exact = f(input.dequantize(q));
                    let got = output.dequantize(lut.lookup(q));
                    let target = exact.clamp(lo_real, hi_real);
                    assert!(
                        (got - target).abs() <= 0.5001 * output.scale,
                        "{name} [{lo},{hi}] q={q}: {got} vs {exact} (scale {})",
                        output.scale
                    );
                }
            }
        }
    }

    #[test]
    fn build_rejects_bad_inputs() {
        let ok = QuantParams::new(0.1, 0).unwrap();
        let bad = QuantParams {
            scale: 0.0,
            zero_point: 0,
        };
        assert_eq!(Lut8::build(silu, bad, ok), Err(QuantError::InvalidScale));
        assert_eq!(Lut8::build(silu, ok, bad), Err(QuantError::InvalidScale));
        let zp = QuantParams {
            scale: 1.0,
            zero_point: 200,
        };
        assert_eq!(Lut8::build(silu, zp, ok), Err(QuantError::InvalidZeroPoint));
        assert_eq!(
            Lut8::build(|v| v.ln(), ok, ok),
            Err(QuantError::NonFiniteValue)
        );
    }
}
