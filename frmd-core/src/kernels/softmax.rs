//! Numerically stable f32 softmax (attention rows), on FPU parts, with a branch-free exponential
//! so that a row's instruction count does not depend on its values.

use super::KernelError;

/// `values[i] <- exp(values[i] - max) / sum_j exp(values[j] - max)` ([`exp_nonpositive`],
/// sequential f32 sum). Subtracting the maximum keeps every exponent `<= 0`, so nothing overflows
/// and the sum is at least 1.
///
/// `-inf` entries are allowed (masked positions; they get probability 0). Errors: an empty slice,
/// any NaN or `+inf`, or no finite entry at all.
pub fn softmax_in_place(values: &mut [f32]) -> Result<(), KernelError> {
    if values.is_empty() {
        return Err(KernelError::Empty);
    }
    let mut max = f32::NEG_INFINITY;
    for v in values.iter() {
        if v.is_nan() || *v == f32::INFINITY {
            return Err(KernelError::NonFinite);
        }
        max = max.max(*v);
    }
    if !max.is_finite() {
        return Err(KernelError::NonFinite);
    }
    let mut sum = 0.0_f32;
    for v in values.iter_mut() {
        *v = exp_nonpositive(*v - max);
        sum += *v;
    }
    for v in values.iter_mut() {
        *v /= sum;
    }
    Ok(())
}

/// Below this the exponential is returned as 0 (`exp(-87) = 1.6e-38`, the smallest normal f32 is
/// `1.2e-38`): every scale `2^k` below stays a normal number.
const EXP_FLOOR: f32 = -87.0;

/// `exp(x)` for `x <= 0` (larger `x` are taken as 0) without a branch on `x`, so that its
/// instruction count is the same for every input (libm's `expf` takes shortcuts for some ranges):
/// `x = k ln2 + r` with `k = round(x / ln2)` (the 1.5 x 2^23 rounding trick) and `r` by a
/// two-part `ln2` (Cody-Waite: `k ln2_hi` is exact for `|k| <= 2^9`), `exp(r)` by its Taylor
/// polynomial of degree 7 on `|r| <= ln2 / 2` (truncation below 3e-9), then the exponent bits
/// of `2^k` as a multiplier. Every operation is one rounded f32 operation (no fused
/// multiply-add), so every target gives the same bits; the relative error against the exact
/// value is within a few ulp. `x < -87` (and `-inf`) gives 0 by a select, not a branch.
#[inline]
pub fn exp_nonpositive(x: f32) -> f32 {
    const LOG2_E: f32 = core::f32::consts::LOG2_E;
    // ln 2 = LN2_HI + LN2_LO, LN2_HI with its low 9 mantissa bits zero.
    const LN2_HI: f32 = f32::from_bits(0x3f31_7200);
    const LN2_LO: f32 = f32::from_bits(0x35bf_be8e);
    // 1.5 x 2^23: adding it rounds to an integer, which then sits in the low mantissa bits.
    const ROUND: f32 = 12_582_912.0;
    const ROUND_BITS: i32 = 0x4b40_0000;
    let clamped = x.clamp(EXP_FLOOR, 0.0);
    let shifted = clamped * LOG2_E + ROUND;
    let k = shifted - ROUND;
    let r = (clamped - k * LN2_HI) - k * LN2_LO;
    let mut p = 1.0 / 5040.0;
    for c in [
        1.0 / 720.0,
        1.0 / 120.0,
        1.0 / 24.0,
        1.0 / 6.0,
        0.5,
        1.0,
        1.0,
    ] {
        p = p * r + c;
    }
    // k is in [-126, 0]: 2^k is a normal f32 with exponent field k + 127.
    let k_int = (shifted.to_bits() as i32).wrapping_sub(ROUND_BITS);
    let scale = f32::from_bits((k_int.wrapping_add(127) as u32) << 23);
    let y = p * scale;
    if x < EXP_FLOOR {
        0.0
    } else {
        y
    }
}

#[cfg(test)]
mod tests {
    extern crate std;
    use super::*;
    use crate::rng::Rng;
    use std::vec::Vec;

    #[test]
    fn sums_to_one_and_matches_f64() {
        let mut rng = Rng::new(5);
        for len in [1_usize, 2, 5, 14, 64, 300] {
            for spread in [0.1_f32, 3.0, 40.0] {
                let mut x: Vec<f32> = (0..len).map(|_| rng.gaussian() * spread + 50.0).collect();
                let original = x.clone();
                softmax_in_place(&mut x).unwrap();
                let sum: f32 = x.iter().sum();
                assert!(
                    (sum - 1.0).abs() < 1e-5,
                    "len {len} spread {spread}: sum {sum}"
                );
                let max = original.iter().fold(f64::MIN, |m, v| m.max(f64::from(*v)));
                let denom: f64 = original.iter().map(|v| (f64::from(*v) - max).exp()).sum();
                for (p, v) in x.iter().zip(&original) {
                    let want = (f64::from(*v) - max).exp() / denom;
                    assert!((f64::from(*p) - want).abs() < 1e-6, "{p} vs {want}");
                }
            }
        }
    }

    #[test]
    fn exp_matches_f64_within_a_few_ulp() {
        let mut rng = Rng::new(11);
        let grid = (0..=87_000).map(|i| -(i as f32) / 1000.0);
        let random = (0..20_000).map(|_| EXP_FLOOR * rng.uniform());
        let mut worst = 0.0_f64;
        for x in grid
            .chain(random)
            .chain([0.0, -0.0, -1e-30, -86.999, EXP_FLOOR])
        {
            let got = f64::from(exp_nonpositive(x));
            let want = f64::from(x).exp();
            let relative = (got - want).abs() / want;
            worst = worst.max(relative);
            assert!(relative < 5e-7, "exp({x}) = {got}, want {want}");
        }
        std::println!("worst relative error {worst:e}");
        assert!(worst > 0.0, "the check compares something");
        assert_eq!(exp_nonpositive(0.0), 1.0);
        for x in [-87.001, -100.0, -1e30, f32::NEG_INFINITY] {
            assert_eq!(exp_nonpositive(x), 0.0, "{x}");
        }
        // Positive arguments are taken as 0.
        assert_eq!(exp_nonpositive(3.0), 1.0);
    }

    #[test]
    fn large_logits_and_masking() {
        let mut x = [1000.0_f32, 1000.0, f32::NEG_INFINITY, -1000.0];
        softmax_in_place(&mut x).unwrap();
        assert_eq!(x, [0.5, 0.5, 0.0, 0.0]);
    }

    #[test]
    fn rejects_bad_rows() {
        assert_eq!(softmax_in_place(&mut []), Err(KernelError::Empty));
        assert_eq!(
            softmax_in_place(&mut [1.0, f32::NAN]),
            Err(KernelError::NonFinite)
        );
        assert_eq!(
            softmax_in_place(&mut [1.0, f32::INFINITY]),
            Err(KernelError::NonFinite)
        );
        assert_eq!(
            softmax_in_place(&mut [f32::NEG_INFINITY; 3]),
            Err(KernelError::NonFinite)
        );
    }
}
