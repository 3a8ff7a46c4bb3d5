//! A deterministic random [`QuantizedPolicy`] with valid parameters (not a trained model: the
//! export tests check that both output forms carry it exactly).
#![allow(dead_code)] // each test crate uses a different subset

use frmd_core::kernels::{silu, Lut8};
use frmd_core::policy::{InputLayout, StepConstants};
use frmd_core::prodmp::{BakedProDmp, ProDmpConfig};
use frmd_core::quant::{quantize_multiplier, QuantParams};
use frmd_core::rng::Rng;
use frmd_export::{ProDmpTablesOwned, QuantizedLayer, QuantizedOutput, QuantizedPolicy};

pub const M: usize = 2;
pub const O: usize = 4;
pub const K: usize = 3;
pub const N: usize = 8;
pub const P: usize = 5;
pub const DT: f32 = 0.05;
/// Seed and step count of the committed golden module in `tests/baked/`.
pub const GOLDEN_SEED: u64 = 11;
pub const GOLDEN_STEPS: usize = 3;

fn layer(rng: &mut Rng, inputs: usize, outputs: usize, lut: Option<usize>) -> QuantizedLayer {
    let mut multipliers = Vec::new();
    let mut shifts = Vec::new();
    for _ in 0..outputs {
        let (m, s) = quantize_multiplier(f64::from(2e-3 + 2e-3 * rng.uniform())).unwrap();
        multipliers.push(m);
        shifts.push(s);
    }
    QuantizedLayer {
        in_features: inputs,
        out_features: outputs,
        weights: (0..inputs * outputs)
            .map(|_| ((rng.next_u32() % 255) as i32 - 127) as i8)
            .collect(),
        bias: (0..outputs)
            .map(|_| (rng.next_u32() % 2001) as i32 - 1000)
            .collect(),
        multipliers,
        shifts,
        output_zero_point: (rng.next_u32() % 21) as i32 - 10,
        activation_min: -128,
        activation_max: 127,
        lut,
    }
}

fn step(sigma: f64, first: bool, index: u32) -> StepConstants {
    let (sigma_min, sigma_data) = (0.002_f64, 0.5_f64);
    let norm = (sigma * sigma + sigma_data * sigma_data).sqrt();
    let shifted = sigma - sigma_min;
    StepConstants {
        sigma: sigma as f32,
        renoise_std: if first {
            0.0
        } else {
            (sigma * sigma - sigma_min * sigma_min).sqrt() as f32
        },
        c_in: (1.0 / norm) as f32,
        c_skip: (sigma_data * sigma_data / (shifted * shifted + sigma_data * sigma_data)) as f32,
        c_out: (shifted * sigma_data / norm) as f32,
        first_layer_bias_index: index,
    }
}

/// Two hidden layers (SiLU LUT on the first, none on the second), `steps` sampling steps.
pub fn sample_policy(seed: u64, steps: usize) -> QuantizedPolicy {
    let mut rng = Rng::new(seed);
    let layout = InputLayout::standard(DT);
    let input_width = layout.width(M, O, K, N).unwrap();
    let hidden = vec![
        layer(&mut rng, input_width, 24, Some(0)),
        layer(&mut rng, 24, 20, None),
    ];
    let first_layer_biases = (0..steps * 24)
        .map(|_| (rng.next_u32() % 4001) as i32 - 2000)
        .collect();
    let output = QuantizedOutput {
        in_features: 20,
        out_features: K * P,
        weights: (0..20 * K * P)
            .map(|_| ((rng.next_u32() % 255) as i32 - 127) as i8)
            .collect(),
        bias: (0..K * P)
            .map(|_| (rng.next_u32() % 501) as i32 - 250)
            .collect(),
        scales: (0..K * P).map(|_| 1e-4 * (1.0 + rng.uniform())).collect(),
    };
    let pre = QuantParams::new(0.05, 3).unwrap();
    let post = QuantParams::new(0.04, -100).unwrap();
    let lut = Lut8::build(silu, pre, post).unwrap();
    let sigmas = [80.0, 1.5, 0.4, 0.1];
    let decoder =
        BakedProDmp::<N, P>::from_config(&ProDmpConfig::policy(K, P - 1, N, f64::from(DT)))
            .unwrap();
    QuantizedPolicy {
        history: M,
        obs_dim: O,
        action_dim: K,
        horizon: N,
        params_per_dof: P,
        control_dt: DT,
        layout,
        input: QuantParams::new(0.02, -5).unwrap(),
        obs_min: vec![-1.0, 0.0, 0.5, -3.0],
        obs_max: vec![1.0, 2.0, 0.5, 3.0],
        action_min: vec![-0.4, -0.4, 0.0],
        action_max: vec![0.4, 0.4, 0.3],
        prodmp: ProDmpTablesOwned::from_baked(&decoder),
        steps: (0..steps)
            .map(|i| step(sigmas[i], i == 0, i as u32))
            .collect(),
        first_layer_biases,
        luts: vec![lut.table],
        hidden,
        output,
    }
}
