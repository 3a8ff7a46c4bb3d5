//! A deterministic random [`QuantizedMlp`] with valid parameters (not a trained model: the
//! export tests check that both output forms carry it exactly, the host tests that any shape
//! runs).

use frmd_core::kernels::{silu, Lut8};
use frmd_core::policy::{InputLayout, StepConstants};
use frmd_core::prodmp::ProDmpConfig;
use frmd_core::quant::{quantize_multiplier, QuantParams};
use frmd_core::rng::Rng;
use frmd_core::sigma::SigmaConfig;
use frmd_export::fold::ProDmpTablesOwned;
use frmd_export::mlp::{QuantizedLayer, QuantizedMlp, QuantizedOutput};

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

/// Sizes of a random policy.
pub struct Dims {
    pub m: usize,
    pub o: usize,
    pub k: usize,
    pub n: usize,
    pub p: usize,
    /// Hidden widths; every hidden layer but the last gets the SiLU LUT.
    pub hidden: Vec<usize>,
}

impl Dims {
    /// History `m`, observation `o`, DoFs `k`, horizon `n`, parameters per DoF `p`, and the
    /// hidden widths.
    pub fn new((m, o, k, n, p): (usize, usize, usize, usize, usize), hidden: Vec<usize>) -> Self {
        Dims {
            m,
            o,
            k,
            n,
            p,
            hidden,
        }
    }
}

/// Two hidden layers (SiLU LUT on the first, none on the second), `steps` sampling steps.
pub fn sample_policy(seed: u64, steps: usize) -> QuantizedMlp {
    let dims = Dims::new((M, O, K, N, P), vec![24, 20]);
    let mut policy = random_policy(seed, steps, &dims);
    policy.obs_min = vec![-1.0, 0.0, 0.5, -3.0];
    policy.obs_max = vec![1.0, 2.0, 0.5, 3.0];
    policy.action_min = vec![-0.4, -0.4, 0.0];
    policy.action_max = vec![0.4, 0.4, 0.3];
    policy
}

/// A random policy of the given sizes (observations in [-1, 1], actions in [-0.5, 0.5]).
pub fn random_policy(seed: u64, steps: usize, dims: &Dims) -> QuantizedMlp {
    let Dims { m, o, k, n, p, .. } = *dims;
    let mut rng = Rng::new(seed);
    let layout = InputLayout::standard(DT);
    let input_width = layout.width(m, o, k, n).unwrap();
    let mut hidden = Vec::new();
    let mut width = input_width;
    for (i, next) in dims.hidden.iter().enumerate() {
        let lut = (i + 1 < dims.hidden.len()).then_some(0);
        hidden.push(layer(&mut rng, width, *next, lut));
        width = *next;
    }
    let first = dims.hidden[0];
    let first_layer_biases = (0..steps * first)
        .map(|_| (rng.next_u32() % 4001) as i32 - 2000)
        .collect();
    let output = QuantizedOutput {
        in_features: width,
        out_features: k * p,
        weights: (0..width * k * p)
            .map(|_| ((rng.next_u32() % 255) as i32 - 127) as i8)
            .collect(),
        bias: (0..k * p)
            .map(|_| (rng.next_u32() % 501) as i32 - 250)
            .collect(),
        scales: (0..k * p).map(|_| 1e-4 * (1.0 + rng.uniform())).collect(),
    };
    let pre = QuantParams::new(0.05, 3).unwrap();
    let post = QuantParams::new(0.04, -100).unwrap();
    let lut = Lut8::build(silu, pre, post).unwrap();
    let sigmas = [80.0, 1.5, 0.4, 0.1];
    let cfg = ProDmpConfig::policy(k, p - 1, n, f64::from(DT));
    let prodmp = ProDmpTablesOwned::from_config(&cfg, n).unwrap();
    QuantizedMlp {
        history: m,
        obs_dim: o,
        action_dim: k,
        horizon: n,
        params_per_dof: p,
        control_dt: DT,
        layout,
        input: QuantParams::new(0.02, -5).unwrap(),
        input_precision: frmd_core::model::mlp::InputPrecision::Int8,
        obs_min: vec![-1.0; o],
        obs_max: vec![1.0; o],
        action_min: vec![-0.5; k],
        action_max: vec![0.5; k],
        prodmp,
        steps: (0..steps)
            .map(|i| {
                StepConstants::consistency(&SigmaConfig::default(), sigmas[i], i as u32).unwrap()
            })
            .collect(),
        first_layer_biases,
        luts: vec![lut.table],
        hidden,
        output,
    }
}
