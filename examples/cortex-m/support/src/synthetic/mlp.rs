//! A deterministic synthetic int8 MLP with the firmware policy's shape (used by `build.rs`, which
//! bakes it into the `mlp` image, and by the host test, which rebuilds it in memory).
//!
//! Float weights are drawn
//! from `frmd_core::rng::Rng` and quantized with `frmd_core::quant` the way the exporter does
//! (symmetric per-channel weights, asymmetric per-tensor activations, int32 bias with the input
//! zero point folded, Q31 requantization, SiLU as a 256-entry LUT). Only the instruction count,
//! memory and host/firmware bit-equality matter here, not what the network computes.

use frmd_core::kernels::{silu, FcRequant, FullyConnected, Lut8};
use frmd_core::model::linear::{Int8Linear, RequantizedLinear};
use frmd_core::model::mlp::Int8Mlp;
use frmd_core::quant::{
    fold_input_zero_point, quantize_bias, quantize_weights_per_channel, requantization_multiplier,
    QuantParams,
};
use frmd_core::rng::Rng;

pub use crate::shape::{MLP_HIDDEN as HIDDEN, MLP_INPUT as INPUT, MLP_OUTPUT as OUTPUT};
/// Seed of the weight stream.
pub const WEIGHT_SEED: u64 = 0x4652_4D44_4D4C_5031;

/// Real range assumed for the inputs, pre-activations and SiLU outputs.
pub const INPUT_RANGE: (f32, f32) = (-1.0, 1.0);
pub const PRE_ACTIVATION_RANGE: (f32, f32) = (-4.0, 4.0);
pub const ACTIVATION_RANGE: (f32, f32) = (-0.3, 4.0);

/// One fully connected layer in int8 form.
pub struct LayerData {
    pub in_features: usize,
    pub out_features: usize,
    /// `[out, in]` row-major.
    pub weights: Vec<i8>,
    /// Input zero point folded in.
    pub bias: Vec<i32>,
    /// Hidden layers: Q31 requantization and the activation LUT. Output layer: empty.
    pub multipliers: Vec<i32>,
    pub shifts: Vec<i32>,
    pub output_zero_point: i32,
    pub lut: Option<Lut8>,
    /// Output layer only: `input_scale * weight_scale[o]`.
    pub output_scales: Vec<f32>,
}

impl LayerData {
    /// The weights and bias as a frmd-core fully connected layer.
    pub fn fully_connected(&self) -> FullyConnected<'_> {
        FullyConnected::new(
            self.in_features,
            self.out_features,
            &self.weights,
            &self.bias,
        )
    }

    /// A dequantized layer (`output` was `None`) as a frmd-core view.
    pub fn int8_linear(&self) -> Int8Linear<'_> {
        Int8Linear {
            fc: self.fully_connected(),
            output_scales: &self.output_scales,
        }
    }

    /// A requantized layer (`output` was `Some`) as a frmd-core view.
    pub fn requantized(&self) -> RequantizedLinear<'_> {
        RequantizedLinear {
            fc: self.fully_connected(),
            requant: FcRequant {
                multipliers: &self.multipliers,
                shifts: &self.shifts,
                output_zero_point: self.output_zero_point,
                activation_min: i8::MIN,
                activation_max: i8::MAX,
            },
            activation: self.lut.as_ref().map(|lut| &lut.table),
        }
    }
}

/// The whole network.
pub struct ModelData {
    pub input: QuantParams,
    pub hidden: Vec<LayerData>,
    pub output: LayerData,
}

fn uniform_weights(rng: &mut Rng, count: usize, limit: f32) -> Vec<f32> {
    (0..count)
        .map(|_| (2.0 * rng.uniform() - 1.0) * limit)
        .collect()
}

pub fn params(range: (f32, f32)) -> QuantParams {
    QuantParams::from_range(range.0, range.1).expect("valid synthetic range")
}

/// Quantizes one layer whose input has `input` params; `output` is `Some((pre, post))` for hidden
/// layers (requantize to `pre`, `activation` LUT to `post`) and `None` for a layer whose int32
/// accumulators are dequantized to f32 (the MLP's output layer, the transformer's linear layers).
pub fn layer(
    rng: &mut Rng,
    in_features: usize,
    out_features: usize,
    input: QuantParams,
    output: Option<(QuantParams, QuantParams)>,
    activation: fn(f32) -> f32,
) -> LayerData {
    // Weights with variance 1/in_features keep pre-activations near unit scale.
    let limit = (3.0 / in_features as f32).sqrt();
    let float_weights = uniform_weights(rng, in_features * out_features, limit);
    let float_bias = uniform_weights(rng, out_features, 0.1);
    let mut weights = vec![0_i8; in_features * out_features];
    let mut weight_scales = vec![0.0_f32; out_features];
    quantize_weights_per_channel(
        &float_weights,
        in_features,
        &mut weights,
        &mut weight_scales,
    )
    .expect("quantize synthetic weights");
    let bias = weights
        .chunks_exact(in_features)
        .zip(float_bias.iter().zip(&weight_scales))
        .map(|(row, (b, scale))| {
            let bias_q = quantize_bias(*b, input.scale, *scale).expect("quantize synthetic bias");
            fold_input_zero_point(bias_q, row, input.zero_point).expect("fold zero point")
        })
        .collect();
    let mut data = LayerData {
        in_features,
        out_features,
        weights,
        bias,
        multipliers: Vec::new(),
        shifts: Vec::new(),
        output_zero_point: 0,
        lut: None,
        output_scales: Vec::new(),
    };
    match output {
        Some((pre, post)) => {
            for scale in &weight_scales {
                let (multiplier, shift) = requantization_multiplier(input.scale, *scale, pre.scale)
                    .expect("synthetic requantization multiplier");
                data.multipliers.push(multiplier);
                data.shifts.push(shift);
            }
            data.output_zero_point = pre.zero_point;
            data.lut = Some(Lut8::build(activation, pre, post).expect("activation LUT"));
        }
        None => {
            data.output_scales = weight_scales.iter().map(|s| input.scale * s).collect();
        }
    }
    data
}

/// Generates the model (deterministic: the same bytes on every host).
pub fn generate() -> ModelData {
    generate_with(INPUT, WEIGHT_SEED, INPUT_RANGE)
}

/// The same architecture with `input_width` inputs whose real range is `input_range`, from `seed`.
pub fn generate_with(input_width: usize, seed: u64, input_range: (f32, f32)) -> ModelData {
    let mut rng = Rng::new(seed);
    let input = params(input_range);
    let pre = params(PRE_ACTIVATION_RANGE);
    let post = params(ACTIVATION_RANGE);
    let mut hidden = Vec::new();
    let mut width = input_width;
    let mut layer_input = input;
    for out in HIDDEN {
        hidden.push(layer(
            &mut rng,
            width,
            out,
            layer_input,
            Some((pre, post)),
            silu,
        ));
        width = out;
        layer_input = post;
    }
    let output = layer(&mut rng, width, OUTPUT, layer_input, None, silu);
    ModelData {
        input,
        hidden,
        output,
    }
}

impl ModelData {
    /// The hidden layers as frmd-core views over this data.
    pub fn hidden_layers(&self) -> Vec<RequantizedLinear<'_>> {
        self.hidden.iter().map(LayerData::requantized).collect()
    }

    /// The network over `hidden` (from [`Self::hidden_layers`]).
    pub fn mlp<'a>(&'a self, hidden: &'a [RequantizedLinear<'a>]) -> Int8Mlp<'a> {
        Int8Mlp {
            input: self.input,
            hidden,
            output: self.output.int8_linear(),
        }
    }

    /// All int8 weights, layer by layer (hidden, then output): the firmware's weight blob.
    pub fn weight_bytes(&self) -> Vec<u8> {
        self.hidden
            .iter()
            .chain([&self.output])
            .flat_map(|layer| layer.weights.iter().map(|w| *w as u8))
            .collect()
    }

    /// Rust source of everything but the weights (which the firmware includes as bytes).
    pub fn rust_source(&self) -> String {
        let (ints, floats) = (super::rust_ints, super::rust_floats);
        let mut code =
            String::from("// Generated by build.rs from synthetic_mlp::generate(); do not edit.\n");
        code += &format!(
            "pub const INPUT_SCALE: f32 = f32::from_bits(0x{:08x});\npub const INPUT_ZERO_POINT: i32 = {};\n",
            self.input.scale.to_bits(),
            self.input.zero_point
        );
        let mut offset = 0;
        for (index, layer) in self.hidden.iter().enumerate() {
            let lut = layer.lut.as_ref().expect("hidden layers have a LUT");
            let table: Vec<String> = lut.table.iter().map(|v| v.to_string()).collect();
            code += &format!(
                "pub static HIDDEN_{index}: HiddenLayer = HiddenLayer {{ in_features: {}, out_features: {}, \
                 weight_offset: {offset}, bias: &[{}], multipliers: &[{}], shifts: &[{}], \
                 output_zero_point: {}, lut: Lut8::from_table([{}]) }};\n",
                layer.in_features,
                layer.out_features,
                ints(&layer.bias),
                ints(&layer.multipliers),
                ints(&layer.shifts),
                layer.output_zero_point,
                table.join(", "),
            );
            offset += layer.weights.len();
        }
        code += &format!(
            "pub static OUTPUT: OutputLayer = OutputLayer {{ in_features: {}, out_features: {}, \
             weight_offset: {offset}, bias: &[{}], scales: &[{}] }};\n",
            self.output.in_features,
            self.output.out_features,
            ints(&self.output.bias),
            floats(&self.output.output_scales),
        );
        code += &format!(
            "pub const WEIGHT_BYTES: usize = {};\n",
            offset + self.output.weights.len()
        );
        code
    }
}
