//! Numerically stable f32 softmax (attention rows), on FPU parts.

use super::KernelError;

/// `values[i] <- exp(values[i] - max) / sum_j exp(values[j] - max)` (`libm::expf`, sequential f32
/// sum). Subtracting the maximum keeps every exponent `<= 0`, so nothing overflows and the sum is
/// at least 1.
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
        *v = libm::expf(*v - max);
        sum += *v;
    }
    for v in values.iter_mut() {
        *v /= sum;
    }
    Ok(())
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
