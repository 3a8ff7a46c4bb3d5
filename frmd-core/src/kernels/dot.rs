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
/// Independent accumulators keep the multiply-accumulate pipeline busy: four on Arm (Cortex-M4
/// `MLA`/`SMLABB` without register spills), sixteen elsewhere so hosts vectorize the loop (SSE2
/// `pmaddwd`). Wrapping int32 addition is associative and commutative, so the result is identical
/// to a sequential sum either way.
#[inline]
pub(crate) fn dot_i8_prefix(a: &[i8], b: &[i8]) -> i32 {
    #[cfg(target_arch = "arm")]
    const LANES: usize = 4;
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

/// The fully connected layer's matrix-vector product: `emit(dot(row, input))` for every row of
/// the row-major `weights` in order. On Arm cores with the DSP extension (`cfg(frmd_arm_dsp)`) it
/// is the `SMLAD` kernel of `kernels::dsp`; elsewhere the row-blocked kernel of `kernels::matvec`
/// (with an AVX2 build on x86-64). All give the sums of [`dot_i8_prefix`].
#[cfg(not(frmd_arm_dsp))]
pub(crate) use super::matvec::for_each_row_dot;

#[cfg(frmd_arm_dsp)]
pub(crate) use super::dsp::for_each_row_dot;

#[cfg(test)]
mod tests {
    use super::*;
    use crate::rng::SplitMix64;

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
