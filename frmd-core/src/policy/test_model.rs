//! Test-only model: a small random f32 student MLP, calibrated and quantized with the `quant`
//! helpers (as the exporter does), with ProDMP tables, step constants and normalization, so the
//! policy and blob tests can run the f32 and int8 paths side by side.

extern crate std;

use std::{vec, vec::Vec};

use super::*;
use crate::blob::MlpBlobParts;
use crate::kernels::Activation;
use crate::model::fixture::{quantize_layer, FloatLayer, MlpRanges, QuantMlp};
use crate::model::linear::{F32Linear, Int8Linear, RequantizedLinear};
use crate::model::mlp::{F32Mlp, F32Scratch, InputPrecision, Int8Mlp};
use crate::prodmp::{BakedProDmp, ProDmpConfig};
use crate::rng::Rng;
use crate::sigma::SigmaConfig;

pub const M: usize = 2;
pub const O: usize = 3;
pub const K: usize = 2;
pub const N: usize = 6;
pub const NUM_BASIS: usize = 3;
pub const P: usize = NUM_BASIS + 1;
/// Input width of the standard layout: M*O + 2K + N*K.
pub const IN: usize = M * O + 2 * K + N * K;
pub const I: usize = 32;
pub const WIDTH: usize = 40;
pub const DT: f32 = 0.05;

pub type F32Policy<'a> = Policy<'a, F32MlpNetwork<'a, WIDTH>, M, O, K, N, P, I>;
pub type Int8Policy<'a> = Policy<'a, Int8MlpNetwork<'a, WIDTH>, M, O, K, N, P, I>;

/// The test model's sizes.
pub const DIMS: PolicyDims = PolicyDims {
    history: M,
    obs_dim: O,
    action_dim: K,
    horizon: N,
    params_per_dof: P,
};

pub struct TestModel {
    pub hidden: Vec<FloatLayer>,
    pub output: FloatLayer,
    /// Per-step first-layer bias variants (f32), `hidden[0].out_features` each.
    pub bias_variants: Vec<f32>,
    pub quant: QuantMlp,
    pub int8_bias_variants: Vec<i32>,
    pub decoder: BakedProDmp<N, P>,
    pub steps: Vec<StepConstants>,
    /// Observation min and max.
    pub obs_range: ([f32; O], [f32; O]),
    /// Action min and max.
    pub action_range: ([f32; K], [f32; K]),
    pub layout: InputLayout,
}

impl TestModel {
    /// A random model with `sigmas.len()` steps (first step at `sigmas[0]`).
    pub fn new(seed: u64, sigmas: &[f64]) -> Self {
        let mut rng = Rng::new(seed);
        let hidden = vec![
            FloatLayer::random(&mut rng, IN, 40, 1.2, Activation::Silu),
            FloatLayer::random(&mut rng, 40, 32, 1.2, Activation::Mish),
        ];
        let output = FloatLayer::random(&mut rng, 32, K * P, 1.2, Activation::Identity);
        let first_out = hidden[0].out_features;
        let mut bias_variants = Vec::new();
        for _ in sigmas {
            bias_variants.extend(hidden[0].bias.iter().map(|b| b + 0.3 * rng.gaussian()));
        }
        let steps: Vec<StepConstants> = sigmas
            .iter()
            .enumerate()
            .map(|(i, s)| {
                StepConstants::consistency(&SigmaConfig::default(), *s, i as u32).unwrap()
            })
            .collect();
        // Calibration over random inputs shaped like the policy's (trajectory part ~ c_in x).
        let mut ranges = MlpRanges::new(hidden.len());
        let mut scratch = F32Scratch::<WIDTH>::new();
        let mut out = [0.0_f32; K * P];
        for sample in 0..400 {
            let variant = sample % sigmas.len();
            let mut first = hidden[0].view();
            first.bias = &bias_variants[variant * first_out..(variant + 1) * first_out];
            let views = [first, hidden[1].view()];
            let net = F32Mlp {
                hidden: &views,
                output: output.view(),
            };
            let x: Vec<f32> = (0..IN)
                .map(|j| {
                    if j < IN - N * K {
                        2.0 * rng.uniform() - 1.0
                    } else {
                        (1.2 * rng.gaussian()).clamp(-3.5, 3.5)
                    }
                })
                .collect();
            net.forward_observed(&x, &mut out, &mut scratch, |probe, values| {
                ranges.observe(probe, values)
            })
            .unwrap();
        }
        let quant = ranges.quantize(&hidden, &output);
        let int8_bias_variants = bias_variants
            .chunks(first_out)
            .flat_map(|variant| quantize_layer(&hidden[0], variant, quant.input, None).bias)
            .collect();
        let decoder =
            BakedProDmp::from_config(&ProDmpConfig::policy(K, NUM_BASIS, N, f64::from(DT)))
                .unwrap();
        Self {
            hidden,
            output,
            bias_variants,
            quant,
            int8_bias_variants,
            decoder,
            steps,
            obs_range: ([-1.0, 0.0, 2.0], [1.0, 4.0, 2.0]),
            action_range: ([-0.5, 0.1], [0.5, 0.3]),
            layout: InputLayout::standard(DT),
        }
    }

    pub fn obs_norm(&self) -> RangeNormalizer<'_> {
        RangeNormalizer::new(&self.obs_range.0, &self.obs_range.1)
    }

    pub fn action_norm(&self) -> RangeNormalizer<'_> {
        RangeNormalizer::new(&self.action_range.0, &self.action_range.1)
    }

    pub fn config(&self) -> PolicyConfig<'_> {
        PolicyConfig {
            history: M,
            obs_norm: self.obs_norm(),
            action_norm: self.action_norm(),
            sampler: Sampler {
                steps: StepTable::new(&self.steps),
                decoder: ProDmpTables::from_baked(&self.decoder),
                layout: self.layout,
                control_dt: DT,
            },
        }
    }

    pub fn f32_network(&self) -> F32MlpNetwork<'_, WIDTH> {
        let views: Vec<F32Linear<'_>> = self.hidden.iter().map(FloatLayer::view).collect();
        F32MlpNetwork::new(&views, self.output.view(), &self.bias_variants).unwrap()
    }

    pub fn int8_layers(&self) -> Vec<RequantizedLinear<'_>> {
        self.quant.hidden_layers()
    }

    pub fn int8_output(&self) -> Int8Linear<'_> {
        self.quant.output_layer()
    }

    pub fn int8_network(&self) -> Int8MlpNetwork<'_, WIDTH> {
        Int8MlpNetwork::new(
            self.quant.input,
            InputPrecision::Int8,
            &self.int8_layers(),
            self.int8_output(),
            &self.int8_bias_variants,
        )
        .unwrap()
    }

    pub fn f32_policy(&self) -> F32Policy<'_> {
        Policy::new(self.config(), self.f32_network()).unwrap()
    }

    pub fn int8_policy(&self) -> Int8Policy<'_> {
        Policy::new(self.config(), self.int8_network()).unwrap()
    }

    /// Blob parts borrowing this model, with its hidden layers in `hidden` (from
    /// [`Self::int8_layers`]).
    pub fn blob_parts<'p>(&'p self, hidden: &'p [RequantizedLinear<'p>]) -> MlpBlobParts<'p> {
        MlpBlobParts {
            config: self.config(),
            mlp: Int8Mlp {
                input: self.quant.input,
                hidden,
                output: self.int8_output(),
            },
            input_precision: InputPrecision::Int8,
            noise_variants: &self.int8_bias_variants,
        }
    }
}
