//! How per-channel int8 weights are rounded onto their grid.
//!
//! [`WeightRounding::Nearest`] rounds every weight on its own. [`WeightRounding::Gptq`] (the
//! error feedback of Frantar et al. 2022, "GPTQ") rounds a layer's input columns one at a time
//! and moves each rounding error onto the columns not yet rounded, in proportion to how the
//! calibration inputs of that layer co-vary, so the layer's outputs on those inputs move as
//! little as the grid allows. Scales, grid and runtime are the same either way (the scales are
//! [`quantize_weights`]'s, every code comes from `frmd_core::quant::quantize_weight`): only
//! which neighbouring code a weight gets differs.
use std::fmt;
use std::str::FromStr;

use anyhow::{bail, Context};
use frmd_core::quant::quantize_weight;
use frmd_formats::checkpoint::BackboneConfig;

use crate::calibrate::{quantize_weights, QuantizedWeights};
use crate::fold::FloatLayer;

/// How weights are rounded to their int8 codes (see the module docs).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum WeightRounding {
    /// Each weight to its nearest code.
    Nearest,
    /// Column by column with error feedback over the calibration inputs' second moments.
    Gptq,
}

impl WeightRounding {
    /// The default of a backbone: GPTQ for the MLP (on four avoid and insert students of the
    /// recipe, 2,000 episodes each, it brought the int16 export from -7.1..-0.1 points of the
    /// float student to -0.8..+1.0; docs/experiments.md, "Weight rounding"), nearest for
    /// transformer-lite (no GPTQ path).
    pub fn recipe(backbone: &BackboneConfig) -> Self {
        match backbone {
            BackboneConfig::Mlp { .. } => Self::Gptq,
            BackboneConfig::Transformer { .. } => Self::Nearest,
        }
    }

    /// `requested`, or the backbone's default ([`Self::recipe`]).
    pub fn resolve(requested: Option<Self>, backbone: &BackboneConfig) -> Self {
        requested.unwrap_or_else(|| Self::recipe(backbone))
    }
}

impl FromStr for WeightRounding {
    type Err = anyhow::Error;

    fn from_str(s: &str) -> anyhow::Result<Self> {
        match s {
            "nearest" => Ok(Self::Nearest),
            "gptq" => Ok(Self::Gptq),
            _ => bail!("weight rounding {s:?}: expected nearest or gptq"),
        }
    }
}

impl fmt::Display for WeightRounding {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(match self {
            Self::Nearest => "nearest",
            Self::Gptq => "gptq",
        })
    }
}

/// The second moments `E[x x^T]` of a layer's inputs over the calibration rows.
#[derive(Clone, Debug, PartialEq)]
pub struct InputMoments {
    width: usize,
    /// Lower triangle (row-major `[width, width]`) of the running sum of `x x^T`.
    sum: Vec<f64>,
    count: usize,
}

impl InputMoments {
    /// No inputs yet, for a layer `width` inputs wide.
    pub fn new(width: usize) -> Self {
        InputMoments {
            width,
            sum: vec![0.0; width * width],
            count: 0,
        }
    }

    /// Adds one input vector (its length must be the width).
    pub fn add(&mut self, x: &[f32]) -> anyhow::Result<()> {
        if x.len() != self.width {
            bail!("layer input of {} values, expected {}", x.len(), self.width);
        }
        for (i, &xi) in x.iter().enumerate() {
            if xi == 0.0 {
                continue;
            }
            let row = &mut self.sum[i * self.width..i * self.width + i + 1];
            for (s, &xj) in row.iter_mut().zip(x) {
                *s += f64::from(xi) * f64::from(xj);
            }
        }
        self.count += 1;
        Ok(())
    }

    /// Input vectors added.
    pub fn count(&self) -> usize {
        self.count
    }

    /// `E[x x^T]` with `1 %` of its mean diagonal added to the diagonal (GPTQ's damping), full
    /// row-major; an input that was always zero gets 1 on its diagonal.
    fn damped(&self) -> Vec<f64> {
        let n = self.width;
        let count = self.count.max(1) as f64;
        let mut h = vec![0.0; n * n];
        for i in 0..n {
            for j in 0..=i {
                let v = self.sum[i * n + j] / count;
                h[i * n + j] = v;
                h[j * n + i] = v;
            }
        }
        let mean_diag = (0..n).map(|i| h[i * n + i]).sum::<f64>() / n.max(1) as f64;
        for i in 0..n {
            h[i * n + i] = if h[i * n + i] > 0.0 {
                h[i * n + i] + 0.01 * mean_diag
            } else {
                1.0
            };
        }
        h
    }
}

/// Lower Cholesky factor `L` of the symmetric positive definite row-major `a` (`a = L L^T`).
fn cholesky(a: &[f64], n: usize) -> anyhow::Result<Vec<f64>> {
    let mut l = vec![0.0; n * n];
    for i in 0..n {
        for j in 0..=i {
            let dot: f64 = (0..j).map(|k| l[i * n + k] * l[j * n + k]).sum();
            let v = a[i * n + j] - dot;
            if i == j {
                if !(v > 0.0 && v.is_finite()) {
                    bail!("second moments not positive definite at input {i}");
                }
                l[i * n + i] = v.sqrt();
            } else {
                l[i * n + j] = v / l[j * n + j];
            }
        }
    }
    Ok(l)
}

/// The inverse of the lower triangular `l`, lower triangular.
fn invert_lower(l: &[f64], n: usize) -> Vec<f64> {
    let mut inv = vec![0.0; n * n];
    for j in 0..n {
        inv[j * n + j] = 1.0 / l[j * n + j];
        for i in j + 1..n {
            let s: f64 = (j..i).map(|k| l[i * n + k] * inv[k * n + j]).sum();
            inv[i * n + j] = -s / l[i * n + i];
        }
    }
    inv
}

/// `layer`'s weights rounded as `rounding` says; `Gptq` needs the layer's input moments.
pub(crate) fn round_weights(
    layer: &FloatLayer,
    rounding: WeightRounding,
    moments: Option<&InputMoments>,
) -> anyhow::Result<QuantizedWeights> {
    let mut q = quantize_weights(layer)?;
    if rounding == WeightRounding::Nearest {
        return Ok(q);
    }
    let moments = moments.context("GPTQ rounding needs the layer's calibration inputs")?;
    let n = layer.in_features;
    if moments.width != n || moments.count == 0 {
        bail!(
            "GPTQ rounding: {} calibration inputs of width {}, the layer takes {n}",
            moments.count,
            moments.width
        );
    }
    // H^-1 = U^T U with U upper triangular: U = (lower Cholesky factor of H^-1)^T.
    let l = cholesky(&moments.damped(), n)?;
    let l_inv = invert_lower(&l, n);
    let mut h_inv = vec![0.0; n * n];
    for i in 0..n {
        for j in 0..=i {
            let s: f64 = (i..n).map(|k| l_inv[k * n + i] * l_inv[k * n + j]).sum();
            h_inv[i * n + j] = s;
            h_inv[j * n + i] = s;
        }
    }
    let u_t = cholesky(&h_inv, n).context("GPTQ rounding: inverse second moments")?;
    let rows = layer
        .weights
        .chunks_exact(n)
        .zip(q.weights.chunks_exact_mut(n));
    for ((row, codes), &scale) in rows.zip(&q.scales) {
        let mut w: Vec<f64> = row.iter().map(|&v| f64::from(v)).collect();
        for i in 0..n {
            let code = quantize_weight(w[i] as f32, scale);
            codes[i] = code;
            let err = (w[i] - f64::from(code) * f64::from(scale)) / u_t[i * n + i];
            for j in i + 1..n {
                w[j] -= err * u_t[j * n + i];
            }
        }
    }
    Ok(q)
}

#[cfg(test)]
mod tests {
    use super::*;
    use frmd_core::kernels::Activation;
    use frmd_core::rng::SplitMix64;

    /// A seeded layer and inputs whose columns are strongly correlated.
    fn layer_and_inputs(out: usize, n: usize, rows: usize) -> (FloatLayer, Vec<Vec<f32>>) {
        let mut rng = SplitMix64::new(0x9e37_79b9);
        let mut next = move || (rng.next_u64() >> 40) as f32 / (1u64 << 24) as f32 - 0.5;
        let weights = (0..out * n).map(|_| next()).collect();
        let inputs = (0..rows)
            .map(|_| {
                let common = next() * 4.0;
                (0..n).map(|_| common + 0.3 * next()).collect()
            })
            .collect();
        let layer = FloatLayer {
            in_features: n,
            out_features: out,
            weights,
            bias: vec![0.0; out],
            activation: Activation::Identity,
        };
        (layer, inputs)
    }

    fn output_error(layer: &FloatLayer, q: &QuantizedWeights, inputs: &[Vec<f32>]) -> f64 {
        let n = layer.in_features;
        let mut total = 0.0;
        for x in inputs {
            for o in 0..layer.out_features {
                let (w, c) = (&layer.weights[o * n..][..n], &q.weights[o * n..][..n]);
                let exact: f64 = w.iter().zip(x).map(|(w, x)| f64::from(*w * *x)).sum();
                let coded: f64 = c
                    .iter()
                    .zip(x)
                    .map(|(c, x)| f64::from(*c) * f64::from(q.scales[o]) * f64::from(*x))
                    .sum();
                total += (exact - coded).powi(2);
            }
        }
        total
    }

    #[test]
    fn gptq_lowers_the_output_error_on_its_calibration_inputs() {
        let (layer, inputs) = layer_and_inputs(16, 40, 300);
        let mut moments = InputMoments::new(40);
        for x in &inputs {
            moments.add(x).unwrap();
        }
        let nearest = round_weights(&layer, WeightRounding::Nearest, None).unwrap();
        let gptq = round_weights(&layer, WeightRounding::Gptq, Some(&moments)).unwrap();
        assert_eq!(nearest.scales, gptq.scales, "same grid");
        assert_ne!(nearest.weights, gptq.weights);
        let (e_nearest, e_gptq) = (
            output_error(&layer, &nearest, &inputs),
            output_error(&layer, &gptq, &inputs),
        );
        assert!(
            e_gptq < 0.5 * e_nearest,
            "GPTQ {e_gptq:e} vs nearest {e_nearest:e}"
        );
        // Every code stays a neighbour-ish of the weight: within the int8 range.
        assert!(gptq.weights.iter().all(|&c| (-127..=127).contains(&c)));
    }

    #[test]
    fn gptq_needs_matching_moments_and_names_the_mismatch() {
        let (layer, _) = layer_and_inputs(4, 8, 1);
        assert!(round_weights(&layer, WeightRounding::Gptq, None).is_err());
        let empty = InputMoments::new(8);
        let error = round_weights(&layer, WeightRounding::Gptq, Some(&empty)).unwrap_err();
        assert!(
            error.to_string().contains("0 calibration inputs"),
            "{error}"
        );
        assert!(InputMoments::new(8).add(&[0.0; 7]).is_err());
    }

    #[test]
    fn rounding_names_parse_and_print() {
        for r in [WeightRounding::Nearest, WeightRounding::Gptq] {
            assert_eq!(r.to_string().parse::<WeightRounding>().unwrap(), r);
        }
        assert!("best".parse::<WeightRounding>().is_err());
    }
}
