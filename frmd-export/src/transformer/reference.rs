//! Check (d) of docs/design.md section 6 for an exported transformer: every quantized linear
//! layer of the model (`traj_in`, `cond_in`, each block's `qkv`, `proj`, `fc1`, `fc2`, and `head`)
//! run by frmd-core's [`frmd_core::kernels::FullyConnected`] against an independent wide-integer
//! model with the exported weights: i64 dot products plus the bias; for `fc1` also the
//! requantization (the i128 models `frmd_core::quant::reference::requantize` for int8 and
//! `requantize16` for int16 codes) and the GELU table (a direct index, or the slope form of the
//! interpolation for int16). Inputs: random code rows and edge rows (all at the smallest code,
//! all at the largest, all at the layer's input zero point, alternating smallest / largest).
//!
//! The f32 parts of the transformer (LayerNorm, attention, residual) are not integer kernels and
//! are covered by check (a)/(b) instead.

use super::quantize::{QuantizedLinear, QuantizedTransformer};
use crate::mlp::ExportPrecision;
use crate::reference::KernelCheck;
use anyhow::Context;
use frmd_core::kernels::FcRequant;
use frmd_core::rng::Rng;

/// The code-width-dependent inputs of the check (the model itself is
/// [`WideModel`](crate::mlp::WideModel)'s).
pub trait WideCodes: ExportPrecision {
    /// A uniformly random code.
    fn random(rng: &mut Rng) -> Self;
    /// The code of input zero point `zero_point` (clamped to the code range).
    fn zero(zero_point: i32) -> Self;
}

impl WideCodes for i8 {
    fn random(rng: &mut Rng) -> i8 {
        rng.next_u32().to_le_bytes()[0] as i8
    }
    fn zero(zero_point: i32) -> i8 {
        zero_point.clamp(-128, 127) as i8
    }
}

impl WideCodes for i16 {
    fn random(rng: &mut Rng) -> i16 {
        rng.next_u32() as u16 as i16
    }
    fn zero(zero_point: i32) -> i16 {
        zero_point.clamp(-32768, 32767) as i16
    }
}

/// The exact accumulators (i128: no wrap for any bias).
fn wide_accumulators<P: WideCodes>(layer: &QuantizedLinear<P>, input: &[P]) -> Vec<i128> {
    layer
        .weights
        .chunks_exact(layer.in_features)
        .zip(&layer.bias)
        .map(|(row, bias)| {
            i128::from(Into::<i64>::into(*bias))
                + row
                    .iter()
                    .zip(input)
                    .map(|(w, x)| i128::from(*w) * i128::from(Into::<i16>::into(*x)))
                    .sum::<i128>()
        })
        .collect()
}

fn input_rows<P: WideCodes>(
    in_features: usize,
    zero_point: i32,
    random_rows: usize,
    rng: &mut Rng,
) -> Vec<Vec<P>> {
    let mut rows = vec![
        vec![P::MIN; in_features],
        vec![P::MAX; in_features],
        vec![P::zero(zero_point); in_features],
    ];
    rows.push(
        (0..in_features)
            .map(|i| if i % 2 == 0 { P::MIN } else { P::MAX })
            .collect(),
    );
    for _ in 0..random_rows {
        rows.push((0..in_features).map(|_| P::random(rng)).collect());
    }
    rows
}

/// Runs the check with `random_rows` random input rows per layer (plus 4 edge rows).
pub fn check_layers<P: WideCodes>(
    model: &QuantizedTransformer<P>,
    random_rows: usize,
    seed: u64,
) -> anyhow::Result<KernelCheck> {
    let mut check = KernelCheck::new(&format!(
        "int{} transformer layer mismatches vs wide model (every quantized linear layer, fc1 \
         requantization + GELU table)",
        P::BITS
    ));
    let mut rng = Rng::new(seed);
    let mut layers: Vec<(String, &QuantizedLinear<P>)> = vec![
        ("traj_in".into(), &model.traj_in),
        ("cond_in".into(), &model.cond_in),
    ];
    for (i, b) in model.blocks.iter().enumerate() {
        layers.extend([
            (format!("block {i} qkv"), &b.qkv),
            (format!("block {i} proj"), &b.proj),
            (format!("block {i} fc1"), &b.fc1),
            (format!("block {i} fc2"), &b.fc2),
        ]);
    }
    layers.push(("head".into(), &model.head));
    for (name, layer) in &layers {
        let fc = layer.fc();
        let mut acc = vec![<P::Acc>::default(); layer.out_features];
        let rows = input_rows::<P>(
            layer.in_features,
            layer.input.zero_point,
            random_rows,
            &mut rng,
        );
        for (r, input) in rows.iter().enumerate() {
            fc.accumulate(P::layer_input(input), &mut acc)
                .with_context(|| name.clone())?;
            let want = wide_accumulators(layer, input);
            let got: Vec<i128> = acc
                .iter()
                .map(|&a| i128::from(Into::<i64>::into(a)))
                .collect();
            check.record(got == want, || {
                format!(
                    "{name} row {r}: first differing accumulator {:?}",
                    got.iter().zip(&want).position(|(a, b)| a != b)
                )
            });
        }
    }
    // fc1: requantized codes and the GELU table.
    for (i, b) in model.blocks.iter().enumerate() {
        let requant = FcRequant {
            multipliers: &b.fc1_multipliers,
            shifts: &b.fc1_shifts,
            output_zero_point: b.fc1_output.zero_point,
            activation_min: P::MIN,
            activation_max: P::MAX,
        };
        let mut out = vec![P::ZERO; b.fc1.out_features];
        let mut gelu = vec![P::ZERO; b.fc1.out_features];
        let rows = input_rows::<P>(
            b.fc1.in_features,
            b.fc1.input.zero_point,
            random_rows,
            &mut rng,
        );
        for (r, input) in rows.iter().enumerate() {
            let fc = b.fc1.fc();
            let what = || format!("block {i} fc1");
            fc.forward_activated(&requant, None, P::layer_input(input), &mut out)
                .with_context(what)?;
            fc.forward_activated(&requant, Some(&b.gelu), P::layer_input(input), &mut gelu)
                .with_context(what)?;
            let want: Vec<(P, P)> = wide_accumulators(&b.fc1, input)
                .iter()
                .enumerate()
                .map(|(o, &acc)| {
                    let q = P::wide_requantize(
                        acc,
                        b.fc1_multipliers[o],
                        b.fc1_shifts[o],
                        b.fc1_output.zero_point,
                        P::MIN,
                        P::MAX,
                    );
                    (q, P::wide_lookup(&b.gelu, q))
                })
                .collect();
            let got: Vec<(P, P)> = out.iter().copied().zip(gelu.iter().copied()).collect();
            check.record(got == want, || {
                format!(
                    "block {i} fc1 requantize/GELU row {r}: first differing channel {:?}",
                    got.iter().zip(&want).position(|(a, b)| a != b)
                )
            });
        }
    }
    Ok(check)
}
