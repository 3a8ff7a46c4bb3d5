//! int8 x int8 -> int32 dot product.

use super::KernelError;

/// `sum_i a[i] * b[i]` with int32 accumulation, wrapping on overflow (two's complement).
///
/// Each product lies in `[-16256, 16384]`, so overflow needs more than 131072 terms; the layers of
/// this crate are far smaller. Returns [`KernelError::OperandLength`] if the lengths differ.
pub fn dot_i8(a: &[i8], b: &[i8]) -> Result<i32, KernelError> {
    if a.len() != b.len() {
        return Err(KernelError::OperandLength);
    }
    Ok(dot_i8_prefix(a, b))
}

/// Dot product over the common prefix of `a` and `b` (callers check the lengths).
///
/// Independent accumulators keep the multiply-accumulate pipeline busy: four on Arm cores with
/// the DSP extension (Cortex-M4 `MLA`/`SMLABB` without register spills), sixteen on hosts so they
/// vectorize the loop (SSE2 `pmaddwd`). Arm cores without it (Cortex-M0: eight low registers, no
/// multiply pipeline) take one: four spilled accumulators cost 34-38 instructions per four
/// products there, one costs 6 per product. Wrapping int32 addition is associative and
/// commutative, so the result is identical to a sequential sum either way.
#[inline]
pub(crate) fn dot_i8_prefix(a: &[i8], b: &[i8]) -> i32 {
    #[cfg(all(target_arch = "arm", frmd_arm_dsp))]
    const LANES: usize = 4;
    #[cfg(all(target_arch = "arm", not(frmd_arm_dsp)))]
    const LANES: usize = 1;
    #[cfg(not(target_arch = "arm"))]
    const LANES: usize = 16;
    let len = a.len().min(b.len());
    let (a, b) = (a.get(..len).unwrap_or(&[]), b.get(..len).unwrap_or(&[]));
    let (a_blocks, a_tail) = a.as_chunks::<LANES>();
    let (b_blocks, b_tail) = b.as_chunks::<LANES>();
    let mut sums = [0_i32; LANES];
    for (x, y) in a_blocks.iter().zip(b_blocks) {
        for ((sum, p), q) in sums.iter_mut().zip(x).zip(y) {
            *sum = sum.wrapping_add(i32::from(*p) * i32::from(*q));
        }
    }
    let mut total = sums.iter().fold(0_i32, |acc, s| acc.wrapping_add(*s));
    for (x, y) in a_tail.iter().zip(b_tail) {
        total = total.wrapping_add(i32::from(*x) * i32::from(*y));
    }
    total
}

/// `sum_i a[i] * b[i]` of int8 `a` and int16 `b` over their common prefix, int32 wrapping (the
/// first layer of a 16-bit input plane; each product lies in `[-4194304, 4194304]`).
#[inline]
pub(crate) fn dot_i8_i16_prefix(a: &[i8], b: &[i16]) -> i32 {
    a.iter().zip(b).fold(0_i32, |sum, (w, x)| {
        sum.wrapping_add(i32::from(*w) * i32::from(*x))
    })
}

/// An input element type of the row kernels.
pub(crate) trait RowInput: Copy {
    /// `sum_i row[i] * input[i]` over the common prefix (int32, wrapping).
    fn dot(row: &[i8], input: &[Self]) -> i32;
    /// The value as a sign-extended halfword (low 16 bits of the `u32`).
    #[cfg(frmd_arm_dsp)]
    fn half(self) -> u32;
    /// The input as int8 codes, if it is int8.
    #[cfg(any(frmd_arm_dsp, target_arch = "aarch64"))]
    fn as_i8(input: &[Self]) -> Option<&[i8]>;
    /// The input as int16 codes, if it is int16.
    #[cfg(any(frmd_arm_dsp, target_arch = "aarch64"))]
    fn as_i16(input: &[Self]) -> Option<&[i16]>;
}

impl RowInput for i8 {
    #[inline(always)]
    fn dot(row: &[i8], input: &[i8]) -> i32 {
        dot_i8_prefix(row, input)
    }
    #[cfg(frmd_arm_dsp)]
    #[inline(always)]
    fn half(self) -> u32 {
        u32::from(i16::from(self) as u16)
    }
    #[cfg(any(frmd_arm_dsp, target_arch = "aarch64"))]
    #[inline(always)]
    fn as_i8(input: &[i8]) -> Option<&[i8]> {
        Some(input)
    }
    #[cfg(any(frmd_arm_dsp, target_arch = "aarch64"))]
    #[inline(always)]
    fn as_i16(_: &[i8]) -> Option<&[i16]> {
        None
    }
}

impl RowInput for i16 {
    #[inline(always)]
    fn dot(row: &[i8], input: &[i16]) -> i32 {
        dot_i8_i16_prefix(row, input)
    }
    #[cfg(frmd_arm_dsp)]
    #[inline(always)]
    fn half(self) -> u32 {
        u32::from(self as u16)
    }
    #[cfg(any(frmd_arm_dsp, target_arch = "aarch64"))]
    #[inline(always)]
    fn as_i8(_: &[i16]) -> Option<&[i8]> {
        None
    }
    #[cfg(any(frmd_arm_dsp, target_arch = "aarch64"))]
    #[inline(always)]
    fn as_i16(input: &[i16]) -> Option<&[i16]> {
        Some(input)
    }
}

#[cfg(test)]
pub(crate) mod tests {
    extern crate std;
    use super::*;
    use crate::rng::SplitMix64;
    use std::vec::Vec;

    /// Row sums in i64 (no wrapping possible at these sizes).
    /// `sum w x` of one row and an int8 or int16 input, in int64 (exact).
    pub(crate) fn wide_dot(row: &[i8], input: crate::kernels::LayerInput<'_>) -> i64 {
        let products = |x: &mut dyn Iterator<Item = i64>| -> i64 {
            row.iter().zip(x).map(|(w, x)| i64::from(*w) * x).sum()
        };
        match input {
            crate::kernels::LayerInput::Int8(x) => products(&mut x.iter().map(|v| i64::from(*v))),
            crate::kernels::LayerInput::Int16(x) => products(&mut x.iter().map(|v| i64::from(*v))),
        }
    }

    pub(crate) fn wide_row_sums(weights: &[i8], input: &[i8]) -> Vec<i64> {
        weights
            .chunks_exact(input.len())
            .map(|row| {
                row.iter()
                    .zip(input)
                    .map(|(w, x)| i64::from(*w) * i64::from(*x))
                    .sum()
            })
            .collect()
    }

    /// Random shapes (row counts not multiples of 4, column counts not multiples of 16), one
    /// case in five with only -128/127 entries.
    pub(crate) fn random_cases(seed: u64, mut check: impl FnMut(&[i8], &[i8])) {
        let mut rng = SplitMix64::new(seed);
        for case in 0..300 {
            let columns = 1 + (rng.next_u64() % 300) as usize;
            let rows = 1 + (rng.next_u64() % 11) as usize;
            let extreme = case % 5 == 0;
            let mut byte = || {
                let bits = rng.next_u64();
                match (extreme, bits % 2) {
                    (true, 0) => -128,
                    (true, _) => 127,
                    (false, _) => (bits >> 8) as i8,
                }
            };
            let weights: Vec<i8> = (0..rows * columns).map(|_| byte()).collect();
            let input: Vec<i8> = (0..columns).map(|_| byte()).collect();
            check(&weights, &input);
        }
    }

    fn naive(a: &[i8], b: &[i8]) -> i64 {
        a.iter()
            .zip(b)
            .map(|(x, y)| i64::from(*x) * i64::from(*y))
            .sum()
    }

    #[test]
    fn matches_wide_sum_on_random_lengths() {
        let mut rng = SplitMix64::new(7);
        for len in 0..200_usize {
            let a: [i8; 256] = core::array::from_fn(|_| rng.next_u64() as i8);
            let b: [i8; 256] = core::array::from_fn(|_| rng.next_u64() as i8);
            let got = dot_i8(&a[..len], &b[..len]).unwrap();
            assert_eq!(i64::from(got), naive(&a[..len], &b[..len]), "len {len}");
        }
    }

    #[test]
    fn extreme_values() {
        let a = [-128_i8; 37];
        let b = [-128_i8; 37];
        assert_eq!(dot_i8(&a, &b).unwrap(), 37 * 16384);
        let c = [127_i8; 37];
        assert_eq!(dot_i8(&a, &c).unwrap(), -37 * 16256);
    }

    #[test]
    fn wraps_like_twos_complement() {
        // 131073 products of 16384 exceed i32::MAX; the result wraps instead of panicking.
        static A: [i8; 131_073] = [-128; 131_073];
        let got = dot_i8(&A, &A).unwrap();
        let wide = 131_073_i64 * 16384;
        assert_eq!(got, wide as i32);
    }

    #[test]
    fn length_mismatch_is_an_error() {
        assert_eq!(dot_i8(&[1, 2], &[1]), Err(KernelError::OperandLength));
    }
}
