//! Check (d) of docs/design.md section 6 for an exported transformer: every int8 linear layer of the
//! model (`traj_in`, `cond_in`, each block's `qkv`, `proj`, `fc1`, `fc2`, and `head`) run by
//! frmd-core's [`frmd_core::kernels::FullyConnected`] against an independent wide-integer model
//! with the exported weights: i64 dot products plus the int32 bias; for `fc1` also the Q31
//! requantization (the i128 model `frmd_core::quant::reference::requantize`) and the GELU table
//! lookup. Inputs: random int8 rows and edge rows (all -128, all 127, all at the layer's input
//! zero point, alternating -128 / 127).
//!
//! The f32 parts of the transformer (LayerNorm, attention, residual) are not integer kernels and
//! are covered by check (a)/(b) instead.

use super::quantize::{QuantizedLinear, QuantizedTransformer};
use crate::reference::KernelCheck;
use anyhow::Context;
use frmd_core::kernels::FcRequant;
use frmd_core::quant::reference;
use frmd_core::rng::Rng;

fn wide_accumulators(layer: &QuantizedLinear, input: &[i8]) -> Vec<i64> {
    layer
        .weights
        .chunks_exact(layer.in_features)
        .zip(&layer.bias)
        .map(|(row, bias)| {
            i64::from(*bias)
                + row
                    .iter()
                    .zip(input)
                    .map(|(w, x)| i64::from(*w) * i64::from(*x))
                    .sum::<i64>()
        })
        .collect()
}

fn input_rows(
    in_features: usize,
    zero_point: i32,
    random_rows: usize,
    rng: &mut Rng,
) -> Vec<Vec<i8>> {
    let zero = zero_point.clamp(-128, 127) as i8;
    let mut rows = vec![
        vec![i8::MIN; in_features],
        vec![i8::MAX; in_features],
        vec![zero; in_features],
    ];
    rows.push(
        (0..in_features)
            .map(|i| if i % 2 == 0 { i8::MIN } else { i8::MAX })
            .collect(),
    );
    for _ in 0..random_rows {
        rows.push(
            (0..in_features)
                .map(|_| rng.next_u32().to_le_bytes()[0] as i8)
                .collect(),
        );
    }
    rows
}

/// Runs the check with `random_rows` random input rows per layer (plus 4 edge rows).
pub fn check_layers(
    model: &QuantizedTransformer,
    random_rows: usize,
    seed: u64,
) -> anyhow::Result<KernelCheck> {
    let mut check = KernelCheck::new("int8 transformer layer mismatches vs wide model (every int8 linear layer, fc1 requantization + GELU table)");
    let mut rng = Rng::new(seed);
    let mut layers: Vec<(String, &QuantizedLinear)> = vec![
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
        let mut acc = vec![0i32; layer.out_features];
        for (r, input) in input_rows(
            layer.in_features,
            layer.input.zero_point,
            random_rows,
            &mut rng,
        )
        .iter()
        .enumerate()
        {
            fc.forward_accumulators(input, &mut acc)
                .with_context(|| name.clone())?;
            let want = wide_accumulators(layer, input);
            let got: Vec<i64> = acc.iter().map(|&a| i64::from(a)).collect();
            check.record(got == want, || {
                format!(
                    "{name} row {r}: first differing accumulator {:?}",
                    got.iter().zip(&want).position(|(a, b)| a != b)
                )
            });
        }
    }
    // fc1: requantized int8 outputs and the GELU table.
    for (i, b) in model.blocks.iter().enumerate() {
        let requant = FcRequant {
            multipliers: &b.fc1_multipliers,
            shifts: &b.fc1_shifts,
            output_zero_point: b.fc1_output.zero_point,
            activation_min: i8::MIN,
            activation_max: i8::MAX,
        };
        let mut out = vec![0i8; b.fc1.out_features];
        for (r, input) in input_rows(
            b.fc1.in_features,
            b.fc1.input.zero_point,
            random_rows,
            &mut rng,
        )
        .iter()
        .enumerate()
        {
            b.fc1
                .fc()
                .forward(&requant, input, &mut out)
                .with_context(|| format!("block {i} fc1"))?;
            let mut gelu = out.clone();
            b.gelu.apply_in_place(&mut gelu);
            let want: Vec<(i8, i8)> = wide_accumulators(&b.fc1, input)
                .iter()
                .enumerate()
                .map(|(o, &acc)| {
                    let q = reference::requantize(
                        acc as i32,
                        b.fc1_multipliers[o],
                        b.fc1_shifts[o],
                        b.fc1_output.zero_point,
                        i8::MIN,
                        i8::MAX,
                    );
                    (q, b.gelu.table[(i32::from(q) + 128) as usize])
                })
                .collect();
            let got: Vec<(i8, i8)> = out.iter().copied().zip(gelu).collect();
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
