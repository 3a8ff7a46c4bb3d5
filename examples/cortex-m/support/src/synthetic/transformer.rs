//! A deterministic synthetic transformer-lite ([`TRANSFORMER_SHAPE`]) in int8 form (used by
//! `build.rs`, which bakes it into the transformer firmware, and by the host test, which rebuilds
//! it in memory and must reproduce the firmware's digest).
//!
//! Linear layers come from the same generator as the synthetic MLP
//! ([`super::mlp::layer`]: uniform weights of variance `1 / in_features`, symmetric
//! per-channel int8, int32 bias with the input zero point folded); `fc1` is requantized to int8
//! and mapped through a GELU (`x sigmoid(1.702 x)`) table, every other layer is dequantized to
//! f32. LayerNorm gains are `1 + u`, shifts and positions small uniform values. Only cost, memory
//! and host/firmware bit-equality matter, not what the network computes.

use super::mlp::{layer, params, LayerData};
use crate::shape::{TRANSFORMER_LINEARS, TRANSFORMER_NORMS, TRANSFORMER_SHAPE};
use frmd_core::kernels::gelu_sigmoid;
use frmd_core::model::linear::QuantizedLinear;
use frmd_core::model::transformer::{
    Int8Block, Int8FeedForward, Int8Transformer, LayerNormWeights, TokenLinear,
};
use frmd_core::quant::QuantParams;
use frmd_core::rng::Rng;

/// Seed of the weight stream.
pub const TRANSFORMER_SEED: u64 = 0x4652_4D44_5452_4631;

/// Real ranges assumed at the quantization points.
const TRAJECTORY_RANGE: (f32, f32) = (-4.0, 4.0);
const CONDITION_RANGE: (f32, f32) = (-2.0, 2.0);
const NORM_RANGE: (f32, f32) = (-4.0, 4.0);
const ATTENTION_RANGE: (f32, f32) = (-2.0, 2.0);
const FC1_RANGE: (f32, f32) = (-4.0, 4.0);
const GELU_RANGE: (f32, f32) = (-0.2, 4.0);

/// One linear layer and the quantization of its input.
pub struct LinearData {
    pub input: QuantParams,
    pub layer: LayerData,
}

/// LayerNorm gain and shift.
pub struct NormData {
    pub gamma: Vec<f32>,
    pub beta: Vec<f32>,
}

/// The whole backbone. `linears` and `norms` are in the order of
/// [`TRANSFORMER_LINEARS`] / [`TRANSFORMER_NORMS`].
pub struct TransformerData {
    pub linears: Vec<LinearData>,
    pub norms: Vec<NormData>,
    pub noise_token: Vec<f32>,
    pub positions: Vec<f32>,
}

fn uniform(rng: &mut Rng, count: usize, low: f32, high: f32) -> Vec<f32> {
    (0..count)
        .map(|_| low + (high - low) * rng.uniform())
        .collect()
}

fn norm(rng: &mut Rng, width: usize) -> NormData {
    NormData {
        gamma: uniform(rng, width, 0.8, 1.2),
        beta: uniform(rng, width, -0.1, 0.1),
    }
}

fn linear(rng: &mut Rng, in_features: usize, out_features: usize, range: (f32, f32)) -> LinearData {
    let input = params(range);
    LinearData {
        input,
        layer: layer(rng, in_features, out_features, input, None, gelu_sigmoid),
    }
}

/// Generates the backbone (deterministic: the same bytes on every host).
pub fn generate() -> TransformerData {
    let shape = TRANSFORMER_SHAPE;
    let width = shape.width;
    let mut rng = Rng::new(TRANSFORMER_SEED);
    let mut linears = vec![
        linear(&mut rng, shape.action_dim, width, TRAJECTORY_RANGE),
        linear(&mut rng, shape.cond_dim, width, CONDITION_RANGE),
    ];
    let mut norms = Vec::new();
    for _ in 0..shape.layers {
        norms.push(norm(&mut rng, width));
        linears.push(linear(&mut rng, width, 3 * width, NORM_RANGE));
        linears.push(linear(&mut rng, width, width, ATTENTION_RANGE));
        norms.push(norm(&mut rng, width));
        let (input, pre, post) = (params(NORM_RANGE), params(FC1_RANGE), params(GELU_RANGE));
        let fc1 = layer(
            &mut rng,
            width,
            shape.hidden(),
            input,
            Some((pre, post)),
            gelu_sigmoid,
        );
        linears.push(LinearData { input, layer: fc1 });
        let fc2 = layer(&mut rng, shape.hidden(), width, post, None, gelu_sigmoid);
        linears.push(LinearData {
            input: post,
            layer: fc2,
        });
    }
    norms.push(norm(&mut rng, width));
    linears.push(linear(
        &mut rng,
        shape.token_values(),
        shape.output,
        NORM_RANGE,
    ));
    assert_eq!(linears.len(), TRANSFORMER_LINEARS);
    assert_eq!(norms.len(), TRANSFORMER_NORMS);
    let noise_token = uniform(&mut rng, width, -0.5, 0.5);
    let positions = uniform(&mut rng, shape.token_values(), -0.1, 0.1);
    TransformerData {
        linears,
        norms,
        noise_token,
        positions,
    }
}

fn quantized(linear: &LinearData) -> QuantizedLinear<'_> {
    QuantizedLinear {
        input: linear.input,
        linear: linear.layer.int8_linear(),
    }
}

fn layer_norm(norm: &NormData) -> LayerNormWeights<'_> {
    LayerNormWeights {
        gamma: &norm.gamma,
        beta: &norm.beta,
    }
}

impl TransformerData {
    /// The blocks as frmd-core views over this data.
    pub fn blocks(&self) -> Vec<Int8Block<'_>> {
        (0..TRANSFORMER_SHAPE.layers)
            .map(|l| {
                let [qkv, proj, fc1, fc2] = [0, 1, 2, 3].map(|i| &self.linears[2 + 4 * l + i]);
                Int8Block {
                    norm1: layer_norm(&self.norms[2 * l]),
                    qkv: quantized(qkv),
                    proj: quantized(proj),
                    norm2: layer_norm(&self.norms[2 * l + 1]),
                    feed_forward: Int8FeedForward {
                        input: fc1.input,
                        fc1: fc1.layer.requantized(),
                        fc2: quantized(fc2),
                    },
                }
            })
            .collect()
    }

    /// The backbone over `blocks` (from [`Self::blocks`]).
    pub fn model<'a>(&'a self, blocks: &'a [Int8Block<'a>]) -> Int8Transformer<'a> {
        Int8Transformer {
            shape: TRANSFORMER_SHAPE,
            traj_in: TokenLinear::Quantized(quantized(&self.linears[0])),
            cond_in: TokenLinear::Quantized(quantized(&self.linears[1])),
            noise_token: &self.noise_token,
            positions: &self.positions,
            blocks,
            final_norm: layer_norm(&self.norms[TRANSFORMER_NORMS - 1]),
            head: quantized(&self.linears[TRANSFORMER_LINEARS - 1]),
        }
    }

    /// All int8 weights, in `linears` order: the firmware's weight blob.
    pub fn weight_bytes(&self) -> Vec<u8> {
        self.linears
            .iter()
            .flat_map(|l| l.layer.weights.iter().map(|w| *w as u8))
            .collect()
    }

    /// Rust source of everything but the weights (`LINEARS`, `NORMS`, `NOISE_TOKEN`,
    /// `POSITIONS`, `WEIGHT_BYTES`; types from the firmware's src/baked_transformer.rs).
    pub fn rust_source(&self) -> String {
        let (ints, floats) = (super::rust_ints, super::rust_floats);
        let mut code = String::from(
            "// Generated by build.rs from synthetic_transformer::generate(); do not edit.\n",
        );
        code += &format!("pub static LINEARS: [Linear; {}] = [\n", self.linears.len());
        let mut offset = 0;
        for linear in &self.linears {
            let l = &linear.layer;
            let lut = match &l.lut {
                Some(lut) => format!(
                    "Some(Lut8::from_table([{}]))",
                    lut.table
                        .iter()
                        .map(|v| v.to_string())
                        .collect::<Vec<_>>()
                        .join(", ")
                ),
                None => "None".into(),
            };
            code += &format!(
                "    Linear {{ input: QuantParams {{ scale: f32::from_bits(0x{:08x}), zero_point: {} }}, \
                 in_features: {}, out_features: {}, weight_offset: {offset}, bias: &[{}], scales: &[{}], \
                 multipliers: &[{}], shifts: &[{}], output_zero_point: {}, lut: {lut} }},\n",
                linear.input.scale.to_bits(),
                linear.input.zero_point,
                l.in_features,
                l.out_features,
                ints(&l.bias),
                floats(&l.output_scales),
                ints(&l.multipliers),
                ints(&l.shifts),
                l.output_zero_point,
            );
            offset += l.weights.len();
        }
        code += "];\n";
        code += &format!("pub static NORMS: [Norm; {}] = [\n", self.norms.len());
        for norm in &self.norms {
            code += &format!(
                "    Norm {{ gamma: &[{}], beta: &[{}] }},\n",
                floats(&norm.gamma),
                floats(&norm.beta)
            );
        }
        code += "];\n";
        code += &format!(
            "pub static NOISE_TOKEN: [f32; {}] = [{}];\n",
            self.noise_token.len(),
            floats(&self.noise_token)
        );
        code += &format!(
            "pub static POSITIONS: [f32; {}] = [{}];\n",
            self.positions.len(),
            floats(&self.positions)
        );
        code += &format!("pub const WEIGHT_BYTES: usize = {offset};\n");
        code
    }
}
