//! The synthetic int8 MLP as baked by build.rs: weights in a byte blob (`include_bytes!`), biases,
//! requantization and LUTs as generated statics. Firmware only.

use frmd_core::kernels::{FcRequant, FullyConnected, Lut8};
use frmd_core::model::linear::{Int8Linear, RequantizedLinear};
use frmd_core::model::mlp::Int8Mlp;
use frmd_core::policy::AlignedBytes;
use frmd_core::quant::QuantParams;
use frmd_firmware_support::shape::{MLP_HIDDEN, MLP_OUTPUT};

/// A generated hidden layer; weights are `weight_offset..` in [`WEIGHTS`].
pub struct HiddenLayer {
    pub in_features: usize,
    pub out_features: usize,
    pub weight_offset: usize,
    pub bias: &'static [i32],
    pub multipliers: &'static [i32],
    pub shifts: &'static [i32],
    pub output_zero_point: i32,
    pub lut: Lut8,
}

/// The generated output layer (accumulators dequantized with `scales`).
pub struct OutputLayer {
    pub in_features: usize,
    pub out_features: usize,
    pub weight_offset: usize,
    pub bias: &'static [i32],
    pub scales: &'static [f32],
}

mod generated {
    use super::{HiddenLayer, Lut8, OutputLayer};
    include!(concat!(env!("OUT_DIR"), "/synthetic_mlp.rs"));
}

/// All int8 weights, layer by layer.
/// (16-byte aligned, as the DSP kernels' word loads need for their fast path.)
static WEIGHTS: AlignedBytes<{ generated::WEIGHT_BYTES }> = AlignedBytes(*include_bytes!(concat!(
    env!("OUT_DIR"),
    "/synthetic_mlp.bin"
)));

fn weights(offset: usize, in_features: usize, out_features: usize) -> Option<&'static [i8]> {
    let bytes = WEIGHTS
        .0
        .get(offset..offset.checked_add(in_features * out_features)?)?;
    Some(bytemuck::cast_slice(bytes))
}

fn hidden_layer(layer: &'static HiddenLayer) -> Option<RequantizedLinear<'static>> {
    Some(RequantizedLinear {
        fc: FullyConnected::new(
            layer.in_features,
            layer.out_features,
            weights(layer.weight_offset, layer.in_features, layer.out_features)?,
            layer.bias,
        ),
        requant: FcRequant {
            multipliers: layer.multipliers,
            shifts: layer.shifts,
            output_zero_point: layer.output_zero_point,
            activation_min: i8::MIN,
            activation_max: i8::MAX,
        },
        activation: Some(&layer.lut.table),
    })
}

/// The hidden layers, or `None` if the generated offsets do not fit the weight blob.
pub fn hidden_layers() -> Option<[RequantizedLinear<'static>; MLP_HIDDEN.len()]> {
    Some([
        hidden_layer(&generated::HIDDEN_0)?,
        hidden_layer(&generated::HIDDEN_1)?,
        hidden_layer(&generated::HIDDEN_2)?,
    ])
}

/// The network over `hidden` (from [`hidden_layers`]).
pub fn mlp<'a>(hidden: &'a [RequantizedLinear<'static>]) -> Option<Int8Mlp<'a>> {
    let output = &generated::OUTPUT;
    if output.out_features != MLP_OUTPUT {
        return None;
    }
    Some(Int8Mlp {
        input: QuantParams {
            scale: generated::INPUT_SCALE,
            zero_point: generated::INPUT_ZERO_POINT,
        },
        hidden,
        output: Int8Linear {
            fc: FullyConnected::new(
                output.in_features,
                output.out_features,
                weights(
                    output.weight_offset,
                    output.in_features,
                    output.out_features,
                )?,
                output.bias,
            ),
            output_scales: output.scales,
        },
    })
}
