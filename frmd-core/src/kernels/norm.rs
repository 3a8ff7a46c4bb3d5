//! f32 LayerNorm over one feature vector (the transformer-lite's pre-norm), on FPU parts.

use super::KernelError;

/// `output[i] = (x[i] - mean) / sqrt(var + epsilon) * gamma[i] + beta[i]`, with
/// `mean = sum(x) / n` and the biased variance `var = sum((x - mean)^2) / n` (PyTorch / candle
/// `LayerNorm`), both summed sequentially in f32 (two passes, so no cancellation from
/// `E[x^2] - mean^2`).
///
/// Errors: empty input, `gamma`/`beta`/`output` lengths differing from the input, or `epsilon`
/// not finite and positive.
pub fn layer_norm(
    input: &[f32],
    gamma: &[f32],
    beta: &[f32],
    epsilon: f32,
    output: &mut [f32],
) -> Result<(), KernelError> {
    if output.len() != input.len() {
        return Err(KernelError::OutputLength);
    }
    let (mean, inv_std) = statistics(input, gamma, beta, epsilon)?;
    let lanes = input.iter().zip(gamma).zip(beta).zip(output.iter_mut());
    for (((x, g), b), out) in lanes {
        *out = (x - mean) * inv_std * g + b;
    }
    Ok(())
}

/// [`layer_norm`] writing back into `values`.
pub fn layer_norm_in_place(
    values: &mut [f32],
    gamma: &[f32],
    beta: &[f32],
    epsilon: f32,
) -> Result<(), KernelError> {
    let (mean, inv_std) = statistics(values, gamma, beta, epsilon)?;
    for ((x, g), b) in values.iter_mut().zip(gamma).zip(beta) {
        *x = (*x - mean) * inv_std * g + b;
    }
    Ok(())
}

/// Checks the arguments and returns `(mean, 1 / sqrt(var + epsilon))`.
fn statistics(
    input: &[f32],
    gamma: &[f32],
    beta: &[f32],
    epsilon: f32,
) -> Result<(f32, f32), KernelError> {
    if input.is_empty() {
        return Err(KernelError::Empty);
    }
    if gamma.len() != input.len() || beta.len() != input.len() {
        return Err(KernelError::AffineLength);
    }
    if !(epsilon.is_finite() && epsilon > 0.0) {
        return Err(KernelError::Epsilon);
    }
    let count = input.len() as f32;
    let mean = input.iter().sum::<f32>() / count;
    let variance = input
        .iter()
        .map(|x| {
            let centered = x - mean;
            centered * centered
        })
        .sum::<f32>()
        / count;
    Ok((mean, 1.0 / libm::sqrtf(variance + epsilon)))
}

#[cfg(test)]
mod tests {
    extern crate std;
    use super::*;
    use crate::rng::Rng;
    use std::{vec, vec::Vec};

    fn reference(x: &[f32], gamma: &[f32], beta: &[f32], eps: f64) -> Vec<f64> {
        let n = x.len() as f64;
        let mean = x.iter().map(|v| f64::from(*v)).sum::<f64>() / n;
        let var = x
            .iter()
            .map(|v| (f64::from(*v) - mean).powi(2))
            .sum::<f64>()
            / n;
        x.iter()
            .zip(gamma)
            .zip(beta)
            .map(|((v, g), b)| {
                (f64::from(*v) - mean) / (var + eps).sqrt() * f64::from(*g) + f64::from(*b)
            })
            .collect()
    }

    #[test]
    fn matches_f64_reference() {
        let mut rng = Rng::new(11);
        for len in [1_usize, 2, 3, 7, 64, 128, 257] {
            for offset in [0.0_f32, 3.0, -100.0] {
                let x: Vec<f32> = (0..len).map(|_| rng.gaussian() * 2.5 + offset).collect();
                let gamma: Vec<f32> = (0..len).map(|_| 1.0 + 0.3 * rng.gaussian()).collect();
                let beta: Vec<f32> = (0..len).map(|_| 0.2 * rng.gaussian()).collect();
                let mut out = vec![0.0_f32; len];
                layer_norm(&x, &gamma, &beta, 1e-5, &mut out).unwrap();
                let want = reference(&x, &gamma, &beta, 1e-5);
                let mut in_place = x.clone();
                layer_norm_in_place(&mut in_place, &gamma, &beta, 1e-5).unwrap();
                assert_eq!(in_place, out);
                for (got, want) in out.iter().zip(&want) {
                    assert!(
                        (f64::from(*got) - want).abs() < 2e-4,
                        "len {len}: {got} vs {want}"
                    );
                }
            }
        }
    }

    #[test]
    fn normalizes_to_zero_mean_unit_variance() {
        let x = [1.0_f32, 2.0, 3.0, 4.0];
        let ones = [1.0_f32; 4];
        let zeros = [0.0_f32; 4];
        let mut out = [0.0_f32; 4];
        layer_norm(&x, &ones, &zeros, 1e-12, &mut out).unwrap();
        let mean: f32 = out.iter().sum::<f32>() / 4.0;
        let var: f32 = out.iter().map(|v| v * v).sum::<f32>() / 4.0;
        assert!(mean.abs() < 1e-6 && (var - 1.0).abs() < 1e-5);
        // A constant vector normalizes to beta.
        let beta = [0.5_f32, -0.5, 1.0, 0.0];
        layer_norm(&[7.0; 4], &ones, &beta, 1e-5, &mut out).unwrap();
        assert_eq!(out, beta);
    }

    #[test]
    fn rejects_bad_arguments() {
        let mut out = [0.0_f32; 3];
        let three = [1.0_f32; 3];
        assert_eq!(
            layer_norm(&[], &[], &[], 1e-5, &mut []),
            Err(KernelError::Empty)
        );
        assert_eq!(
            layer_norm(&three, &three[..2], &three, 1e-5, &mut out),
            Err(KernelError::AffineLength)
        );
        assert_eq!(
            layer_norm(&three, &three, &three[..1], 1e-5, &mut out),
            Err(KernelError::AffineLength)
        );
        assert_eq!(
            layer_norm(&three, &three, &three, 1e-5, &mut out[..2]),
            Err(KernelError::OutputLength)
        );
        assert_eq!(
            layer_norm(&three, &three, &three, 0.0, &mut out),
            Err(KernelError::Epsilon)
        );
        assert_eq!(
            layer_norm(&three, &three, &three, f32::NAN, &mut out),
            Err(KernelError::Epsilon)
        );
    }
}
