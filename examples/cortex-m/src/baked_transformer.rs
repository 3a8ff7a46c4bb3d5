//! The synthetic transformer-lite as baked by build.rs (`frmd_firmware_support::synthetic::transformer`): int8
//! weights in a byte blob (`include_bytes!`), everything else as generated statics. Firmware only.

use frmd_core::kernels::{FcRequant, FullyConnected, Lut8};
use frmd_core::model::linear::{Int8Linear, QuantizedLinear, RequantizedLinear};
use frmd_core::model::transformer::{
    Int8Block, Int8FeedForward, Int8Transformer, LayerNormWeights, TokenLinear,
};
use frmd_core::policy::AlignedBytes;
use frmd_core::quant::QuantParams;
use frmd_firmware_support::shape::{TRANSFORMER_LINEARS, TRANSFORMER_NORMS, TRANSFORMER_SHAPE};

/// A generated linear layer; weights are `weight_offset..` in [`WEIGHTS`]. `scales` for layers
/// dequantized to f32; `multipliers`, `shifts`, `output_zero_point` and `lut` for `fc1`.
pub struct Linear {
    pub input: QuantParams,
    pub in_features: usize,
    pub out_features: usize,
    pub weight_offset: usize,
    pub bias: &'static [i32],
    pub scales: &'static [f32],
    pub multipliers: &'static [i32],
    pub shifts: &'static [i32],
    pub output_zero_point: i32,
    pub lut: Option<Lut8>,
}

/// A generated LayerNorm.
pub struct Norm {
    pub gamma: &'static [f32],
    pub beta: &'static [f32],
}

mod generated {
    use super::{Linear, Lut8, Norm, QuantParams};
    include!(concat!(env!("OUT_DIR"), "/synthetic_transformer.rs"));
}

/// All int8 weights, layer by layer.
/// (16-byte aligned, as the DSP kernels' word loads need for their fast path.)
static WEIGHTS: AlignedBytes<{ generated::WEIGHT_BYTES }> = AlignedBytes(*include_bytes!(concat!(
    env!("OUT_DIR"),
    "/synthetic_transformer.bin"
)));

fn linear_at(index: usize) -> Option<&'static Linear> {
    generated::LINEARS.get(index)
}

fn fully_connected(layer: &'static Linear) -> Option<FullyConnected<'static>> {
    let count = layer.in_features.checked_mul(layer.out_features)?;
    let bytes = WEIGHTS
        .0
        .get(layer.weight_offset..layer.weight_offset.checked_add(count)?)?;
    Some(FullyConnected::new(
        layer.in_features,
        layer.out_features,
        bytemuck::cast_slice(bytes),
        layer.bias,
    ))
}

fn quantized(index: usize) -> Option<QuantizedLinear<'static>> {
    let layer = linear_at(index)?;
    Some(QuantizedLinear {
        input: layer.input,
        linear: Int8Linear {
            fc: fully_connected(layer)?,
            output_scales: layer.scales,
        },
    })
}

fn layer_norm(index: usize) -> Option<LayerNormWeights<'static>> {
    let norm = generated::NORMS.get(index)?;
    Some(LayerNormWeights {
        gamma: norm.gamma,
        beta: norm.beta,
    })
}

fn block(layer: usize) -> Option<Int8Block<'static>> {
    let base = 2 + 4 * layer;
    let fc1 = linear_at(base + 2)?;
    Some(Int8Block {
        norm1: layer_norm(2 * layer)?,
        qkv: quantized(base)?,
        proj: quantized(base + 1)?,
        norm2: layer_norm(2 * layer + 1)?,
        feed_forward: Int8FeedForward {
            input: fc1.input,
            fc1: RequantizedLinear {
                fc: fully_connected(fc1)?,
                requant: FcRequant {
                    multipliers: fc1.multipliers,
                    shifts: fc1.shifts,
                    output_zero_point: fc1.output_zero_point,
                    activation_min: i8::MIN,
                    activation_max: i8::MAX,
                },
                activation: Some(&fc1.lut.as_ref()?.table),
            },
            fc2: quantized(base + 3)?,
        },
    })
}

/// Number of blocks.
pub const LAYERS: usize = TRANSFORMER_SHAPE.layers;

/// The blocks over the baked data; `None` if a generated part is missing or out of the blob.
pub fn blocks() -> Option<[Int8Block<'static>; LAYERS]> {
    let mut blocks = [block(0)?; LAYERS];
    for (layer, slot) in blocks.iter_mut().enumerate() {
        *slot = block(layer)?;
    }
    Some(blocks)
}

/// The backbone over `blocks` (from [`blocks`]).
pub fn model<'a>(blocks: &'a [Int8Block<'static>]) -> Option<Int8Transformer<'a>> {
    Some(Int8Transformer {
        shape: TRANSFORMER_SHAPE,
        traj_in: TokenLinear::Quantized(quantized(0)?),
        cond_in: TokenLinear::Quantized(quantized(1)?),
        noise_token: &generated::NOISE_TOKEN,
        positions: &generated::POSITIONS,
        blocks,
        final_norm: layer_norm(TRANSFORMER_NORMS - 1)?,
        head: quantized(TRANSFORMER_LINEARS - 1)?,
    })
}
