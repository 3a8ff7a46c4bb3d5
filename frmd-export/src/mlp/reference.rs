//! Check (d) for an exported MLP: the whole quantized network run by frmd-core against a
//! wide-integer model of it ([`wide_network`]), on the caller's inputs and edge inputs.
use super::precision::ExportPrecision;
use super::quantized::QuantizedMlp;
use crate::reference::KernelCheck;
use anyhow::Context;
use frmd_core::model::mlp::InputPrecision;
use frmd_core::policy::{Network, QuantMlpNetwork};
use frmd_core::quant::{reference, QuantParams, FINE_INPUT_BITS};

/// frmd-core's [`QuantMlpNetwork`] over `policy`'s tensors (scratch `WIDTH`).
pub fn quantized_network<P: ExportPrecision, const WIDTH: usize>(
    policy: &QuantizedMlp<P>,
) -> anyhow::Result<QuantMlpNetwork<'_, P, WIDTH>> {
    let layers = policy.hidden_layers();
    QuantMlpNetwork::new(
        policy.input,
        policy.input_precision,
        &layers,
        policy.output_layer(),
        &policy.first_layer_biases,
    )
    .with_context(|| format!("int{} network", P::BITS))
}

/// The wide-integer model of the whole quantized network: i64 dot products, the i128
/// requantization model, tables read directly; returns the output layer's accumulators. Errors
/// if `policy` is inconsistent (widths, bias variants, table indices) or `input` has the wrong
/// length.
pub fn wide_network<P: ExportPrecision>(
    policy: &QuantizedMlp<P>,
    step: usize,
    input: &[f32],
) -> anyhow::Result<Vec<i64>> {
    policy
        .with_parts(|parts| frmd_core::blob::mlp_encoded_len(parts).map(|_| ()))
        .context("inconsistent policy")?;
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
        let bias: &[P::Acc] = if l == 0 && !policy.first_layer_biases.is_empty() {
            &policy.first_layer_biases[step * layer.out_features..(step + 1) * layer.out_features]
        } else {
            &layer.bias
        };
        x = (0..layer.out_features)
            .map(|o| {
                let row = &layer.weights[o * layer.in_features..(o + 1) * layer.in_features];
                let mut acc = bias[o].into()
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
                P::output(layer, &policy.luts, o, acc)
            })
            .collect();
    }
    let out = &policy.output;
    let bias: &[P::Acc] = if policy.hidden.is_empty() && !policy.first_layer_biases.is_empty() {
        &policy.first_layer_biases[step * out.out_features..(step + 1) * out.out_features]
    } else {
        &out.bias
    };
    Ok((0..out.out_features)
        .map(|o| {
            let row = &out.weights[o * out.in_features..(o + 1) * out.in_features];
            let acc: i64 = bias[o].into();
            acc + row
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
pub fn check_network<P: ExportPrecision, const WIDTH: usize>(
    policy: &QuantizedMlp<P>,
    inputs: &[Vec<f32>],
) -> anyhow::Result<KernelCheck> {
    let mut check = KernelCheck::new(if P::BITS == 8 {
        "int8 network accumulator mismatches vs wide model"
    } else {
        "int16-activation network accumulator mismatches vs wide model"
    });
    let mut net = quantized_network::<P, WIDTH>(policy)?;
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
                .context("quantized forward")?;
            let got: Vec<i64> = net.accumulators().iter().map(|&a| a.into()).collect();
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
