//! Bit-accuracy check (d) of docs/design.md section 6: frmd-core's int8 kernels against an independent
//! wide-integer model of the same formulas (`frmd_core::quant::reference`, i128 arithmetic with
//! floor divisions; i64 dot products here), on random and edge inputs.
use crate::QuantizedPolicy;
use frmd_core::model::mlp::InputPrecision;
use frmd_core::policy::{Int8MlpNetwork, Network};
use frmd_core::quant::{
    multiply_by_quantized_multiplier, reference, requantize_to_i8, QuantParams, FINE_INPUT_BITS,
    Q31_MANTISSA_MIN, SHIFT_MAX, SHIFT_MIN,
};
use frmd_core::rng::Rng;

/// Outcome of one check: how many cases ran and how many differed (the first is described).
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct KernelCheck {
    pub name: String,
    pub cases: u64,
    pub mismatches: u64,
    pub first_mismatch: Option<String>,
}

impl KernelCheck {
    fn new(name: &str) -> Self {
        KernelCheck {
            name: name.into(),
            cases: 0,
            mismatches: 0,
            first_mismatch: None,
        }
    }

    fn record(&mut self, equal: bool, describe: impl FnOnce() -> String) {
        self.cases += 1;
        if !equal {
            self.mismatches += 1;
            if self.first_mismatch.is_none() {
                self.first_mismatch = Some(describe());
            }
        }
    }

    pub fn passed(&self) -> bool {
        self.mismatches == 0 && self.cases > 0
    }
}

fn edge_accumulators() -> Vec<i32> {
    let mut values = vec![i32::MIN, i32::MIN + 1, -1, 0, 1, i32::MAX - 1, i32::MAX];
    for e in 0..31 {
        let p = 1_i32 << e;
        values.extend([p, p - 1, p + 1, -p, -p + 1, -p - 1]);
    }
    values
}

/// Requantization on all edge accumulators (INT32 ends, powers of two and neighbours) x edge
/// multipliers x every shift x zero points at the range ends x clamps, then `random` random cases,
/// and exact ties of the final rounding division.
pub fn check_requantization(random: u64, seed: u64) -> KernelCheck {
    let mut check = KernelCheck::new("requantization (edges, ties, random) vs i128 model");
    let multipliers = [
        0,
        1,
        Q31_MANTISSA_MIN,
        Q31_MANTISSA_MIN + 1,
        1_518_500_250,
        i32::MAX - 1,
        i32::MAX,
    ];
    let zero_points = [-128, -127, -1, 0, 1, 126, 127];
    let clamps = [
        (-128_i8, 127_i8),
        (0, 127),
        (-128, -128),
        (127, 127),
        (-5, 6),
    ];
    for &acc in &edge_accumulators() {
        for &m in &multipliers {
            for shift in SHIFT_MIN..=SHIFT_MAX {
                let got = multiply_by_quantized_multiplier(acc, m, shift);
                let want = reference::scale(acc, m, shift);
                check.record(got == want, || {
                    format!("scale acc={acc} m={m} shift={shift}: {got} vs {want}")
                });
                for &zp in &zero_points {
                    for &(lo, hi) in &clamps {
                        let got = requantize_to_i8(acc, m, shift, zp, lo, hi);
                        let want = reference::requantize(acc, m, shift, zp, lo, hi);
                        check.record(got == want, || format!("acc={acc} m={m} shift={shift} zp={zp} clamp={lo}..={hi}: {got} vs {want}"));
                    }
                }
            }
        }
    }
    // Ties: acc * m / 2^31 = h exactly (m = 2^30, acc even), h an odd multiple of 2^(r-1).
    for r in 1..=20_i32 {
        for odd in [-7_i64, -3, -1, 1, 3, 7] {
            let h = odd << (r - 1);
            let acc = (2 * h) as i32;
            let got = multiply_by_quantized_multiplier(acc, Q31_MANTISSA_MIN, -r);
            let want = reference::scale(acc, Q31_MANTISSA_MIN, -r);
            check.record(got == want, || {
                format!("tie acc={acc} shift={}: {got} vs {want}", -r)
            });
        }
    }
    let mut rng = Rng::new(seed);
    for _ in 0..random {
        let acc = rng.next_u32() as i32;
        let m = Q31_MANTISSA_MIN + (rng.next_u32() % (1 << 30)) as i32;
        let shift = SHIFT_MIN + (rng.next_u32() % (SHIFT_MAX - SHIFT_MIN + 1) as u32) as i32;
        let zp = (rng.next_u32() % 256) as i32 - 128;
        let got = requantize_to_i8(acc, m, shift, zp, i8::MIN, i8::MAX);
        let want = reference::requantize(acc, m, shift, zp, i8::MIN, i8::MAX);
        check.record(got == want, || {
            format!("random acc={acc} m={m} shift={shift} zp={zp}: {got} vs {want}")
        });
    }
    check
}

/// frmd-core's [`Int8MlpNetwork`] over `policy`'s tensors (scratch `WIDTH`).
pub fn int8_network<const WIDTH: usize>(
    policy: &QuantizedPolicy,
) -> anyhow::Result<Int8MlpNetwork<'_, WIDTH>> {
    let layers = policy.hidden_layers();
    Int8MlpNetwork::new(
        policy.input,
        policy.input_precision,
        &layers,
        policy.output_layer(),
        &policy.first_layer_biases,
    )
    .map_err(|e| anyhow::anyhow!("int8 network: {e}"))
}

/// The wide-integer model of the whole int8 network: i64 dot products, the i128 requantization
/// model, LUTs indexed directly; returns the output layer's accumulators. Errors if `policy` is
/// inconsistent (widths, bias variants, LUT indices) or `input` has the wrong length.
pub fn wide_network(
    policy: &QuantizedPolicy,
    step: usize,
    input: &[f32],
) -> anyhow::Result<Vec<i64>> {
    policy
        .with_parts(|parts| frmd_core::blob::mlp_encoded_len(parts).map(|_| ()))
        .map_err(|e| anyhow::anyhow!("inconsistent policy: {e}"))?;
    let first_in = policy
        .hidden
        .first()
        .map_or(policy.output.in_features, |l| l.in_features);
    let first_out = policy
        .hidden
        .first()
        .map_or(policy.output.out_features, |l| l.out_features);
    if input.len() != first_in {
        anyhow::bail!(
            "input has {} values, the network takes {first_in}",
            input.len()
        );
    }
    if !policy.first_layer_biases.is_empty()
        && (step + 1) * first_out > policy.first_layer_biases.len()
    {
        anyhow::bail!("no first-layer bias variant {step}");
    }
    let coarse: Vec<i64> = input
        .iter()
        .map(|&v| i64::from(policy.input.quantize(v)))
        .collect();
    // Two-plane input: the residual of each value after its coarse code, in steps of
    // `scale / 2^FINE_INPUT_BITS`, rounded half away from zero and saturated to int8.
    let fine_params = QuantParams {
        scale: policy.input.scale / (1_u32 << FINE_INPUT_BITS) as f32,
        zero_point: 0,
    };
    let fine: Vec<i64> = input
        .iter()
        .map(|&v| {
            i64::from(fine_params.quantize(v - policy.input.dequantize(policy.input.quantize(v))))
        })
        .collect();
    let two_plane = policy.input_precision == InputPrecision::TwoPlane;
    // 16-bit input: `round_half_away(v / (scale / 2^8)) + 2^8 zero_point + 2^7` (f32 division,
    // f64 rounding), saturated to int16.
    let wide_zero = i64::from(policy.input.zero_point) * 256 + 128;
    let wide: Vec<i64> = input
        .iter()
        .map(|&v| {
            (f64::from(v / fine_params.scale).round() as i64)
                .saturating_add(wide_zero)
                .clamp(-32768, 32767)
        })
        .collect();
    let mut x = if policy.input_precision == InputPrecision::Int16 && !policy.hidden.is_empty() {
        wide
    } else {
        coarse
    };
    for (l, layer) in policy.hidden.iter().enumerate() {
        let bias: &[i32] = if l == 0 && !policy.first_layer_biases.is_empty() {
            &policy.first_layer_biases[step * layer.out_features..(step + 1) * layer.out_features]
        } else {
            &layer.bias
        };
        x = (0..layer.out_features)
            .map(|o| {
                let row = &layer.weights[o * layer.in_features..(o + 1) * layer.in_features];
                let mut acc = i64::from(bias[o])
                    + row
                        .iter()
                        .zip(&x)
                        .map(|(w, v)| i64::from(*w) * v)
                        .sum::<i64>();
                if l == 0 && two_plane {
                    let fine_dot = row
                        .iter()
                        .zip(&fine)
                        .map(|(w, v)| i64::from(*w) * v)
                        .sum::<i64>();
                    acc = i64::from(reference::combine_planes(acc as i32, fine_dot as i32));
                }
                let q = reference::requantize(
                    acc as i32,
                    layer.multipliers[o],
                    layer.shifts[o],
                    layer.output_zero_point,
                    layer.activation_min,
                    layer.activation_max,
                );
                let q = match layer.lut {
                    Some(t) => policy.luts[t][(i32::from(q) + 128) as usize],
                    None => q,
                };
                i64::from(q)
            })
            .collect();
    }
    let out = &policy.output;
    let bias: &[i32] = if policy.hidden.is_empty() && !policy.first_layer_biases.is_empty() {
        &policy.first_layer_biases[step * out.out_features..(step + 1) * out.out_features]
    } else {
        &out.bias
    };
    Ok((0..out.out_features)
        .map(|o| {
            let row = &out.weights[o * out.in_features..(o + 1) * out.in_features];
            i64::from(bias[o])
                + row
                    .iter()
                    .zip(&x)
                    .map(|(w, v)| i64::from(*w) * v)
                    .sum::<i64>()
        })
        .collect())
}

/// The policy's int8 network (frmd-core) vs [`wide_network`] on `inputs` (f32 model inputs) for
/// every step, plus edge inputs: all values at the quantization range ends and beyond
/// (saturation), all at the zero point, and alternating ends.
pub fn check_network<const WIDTH: usize>(
    policy: &QuantizedPolicy,
    inputs: &[Vec<f32>],
) -> anyhow::Result<KernelCheck> {
    let mut check = KernelCheck::new("int8 network accumulators vs i64/i128 model");
    let mut net = int8_network::<WIDTH>(policy)?;
    let width = net.input_width();
    let lo = policy.input.dequantize(i8::MIN);
    let hi = policy.input.dequantize(i8::MAX);
    let mut all: Vec<Vec<f32>> = inputs.to_vec();
    all.push(vec![lo; width]);
    all.push(vec![hi; width]);
    all.push(vec![1e9; width]);
    all.push(vec![-1e9; width]);
    all.push(vec![0.0; width]);
    all.push(
        (0..width)
            .map(|i| if i % 2 == 0 { 1e9 } else { -1e9 })
            .collect(),
    );
    // Residuals of exactly +-half a coarse step (the fine plane's saturation and ties, the 16-bit
    // plane's ends) and of quarter steps.
    let step = policy.input.scale;
    all.push(
        (0..width)
            .map(|i| policy.input.dequantize(((i % 200) as i32 - 100) as i8) + 0.5 * step)
            .collect(),
    );
    all.push(
        (0..width)
            .map(|i| policy.input.dequantize(((i % 200) as i32 - 100) as i8) - 0.5 * step)
            .collect(),
    );
    all.push(
        (0..width)
            .map(|i| {
                policy.input.dequantize((i % 100) as i8)
                    + 0.25 * step * if i % 2 == 0 { 1.0 } else { -1.0 }
            })
            .collect(),
    );
    let mut out = vec![0.0; net.output_width()];
    for (n, input) in all.iter().enumerate() {
        if input.len() != width {
            anyhow::bail!(
                "check input {n} has {} values, the network takes {width}",
                input.len()
            );
        }
        for step in 0..policy.steps.len() {
            net.forward(step, input, &mut out)
                .map_err(|e| anyhow::anyhow!("int8 forward: {e}"))?;
            let got: Vec<i64> = net.accumulators().iter().map(|&a| i64::from(a)).collect();
            let want = wide_network(policy, step, input)?;
            check.record(got == want, || {
                format!(
                    "input {n} step {step}: first differing accumulator {:?}",
                    got.iter().zip(&want).position(|(a, b)| a != b)
                )
            });
        }
    }
    Ok(check)
}
