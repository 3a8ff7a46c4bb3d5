//! [`QuantizedMlp`]: the owned, target-independent result of quantizing an MLP student, from
//! which both output forms (blob and baked module) are written; int8 weights with int8
//! activations (the default type parameter) or int16 activations (`QuantizedMlp<i16>`: int64
//! biases, interpolated int16 tables).

use crate::fold::ProDmpTablesOwned;
use crate::memory::{policy_table_bytes, state_bytes, MemoryFigures};
use frmd_core::blob::{encode_mlp, mlp_encoded_len, BlobError, MlpBlobParts};
use frmd_core::kernels::{FcRequant, FullyConnected, Precision};
use frmd_core::model::linear::{Int8Linear, RequantizedLinear};
use frmd_core::model::mlp::{InputPrecision, MlpPrecision, QuantMlp};
use frmd_core::policy::{
    InputLayout, PolicyConfig, PolicyDims, RangeNormalizer, Sampler, StepConstants, StepTable,
};
use frmd_core::quant::QuantParams;

/// One quantized hidden layer (int8-weight FC, per-channel requantization to `P` codes, optional
/// table).
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct QuantizedLayer<P: Precision = i8> {
    /// Input width.
    pub in_features: usize,
    /// Output width.
    pub out_features: usize,
    /// `[out, in]` int8 weights, symmetric per output channel.
    pub weights: Vec<i8>,
    /// `[out]` bias (int32, int64 with int16 activations), input zero point folded (the first
    /// layer: step 0's variant).
    pub bias: Vec<P::Acc>,
    /// `[out]` Q31 multipliers.
    pub multipliers: Vec<i32>,
    /// `[out]` shifts.
    pub shifts: Vec<i32>,
    /// Zero point of the requantized output.
    pub output_zero_point: i32,
    /// Lower output clamp.
    pub activation_min: P,
    /// Upper output clamp.
    pub activation_max: P,
    /// Index into [`QuantizedMlp::luts`] of the activation, if any.
    pub lut: Option<usize>,
}

/// The output layer: int8-weight FC whose accumulators (`A`: int32, or int64 with int16
/// activations) are dequantized to f32 ProDMP parameters.
#[derive(Clone, Debug, PartialEq)]
pub struct QuantizedOutput<A = i32> {
    /// Input width.
    pub in_features: usize,
    /// Output width (`K * P`).
    pub out_features: usize,
    /// `[out, in]` int8 weights.
    pub weights: Vec<i8>,
    /// `[out]` bias.
    pub bias: Vec<A>,
    /// `[out]` dequantization scales `input_scale * weight_scale[o]`.
    pub scales: Vec<f32>,
}

/// Alignment of every array in the weight file.
const ALIGN: usize = 16;

/// One array of the weight file: byte offset and element count.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct WeightEntry {
    /// Byte offset in the weight file (multiple of 16).
    pub offset: usize,
    /// Number of elements.
    pub count: usize,
}

/// A calibrated, quantized student with everything the firmware needs besides code; `P` is the
/// activation precision.
#[derive(Clone, Debug, PartialEq)]
pub struct QuantizedMlp<P: Precision = i8> {
    /// History length `M`.
    pub history: usize,
    /// Observation dimension `O`.
    pub obs_dim: usize,
    /// Action dimension `K`.
    pub action_dim: usize,
    /// Horizon `N`.
    pub horizon: usize,
    /// ProDMP parameters per DoF `P = num_basis + 1`.
    pub params_per_dof: usize,
    /// Control period, seconds.
    pub control_dt: f32,
    /// Model input layout.
    pub layout: InputLayout,
    /// Quantization of the f32 input vector.
    pub input: QuantParams,
    /// How the first layer quantizes the input; with [`InputPrecision::TwoPlane`] the first
    /// layer's multipliers, with [`InputPrecision::Int16`] also its biases, are for the input
    /// scale `input.scale / 2^FINE_INPUT_BITS`.
    pub input_precision: InputPrecision,
    /// `[O]` observation minimum (raw units).
    pub obs_min: Vec<f32>,
    /// `[O]` observation maximum.
    pub obs_max: Vec<f32>,
    /// `[K]` action minimum.
    pub action_min: Vec<f32>,
    /// `[K]` action maximum.
    pub action_max: Vec<f32>,
    /// ProDMP decoder tables.
    pub prodmp: ProDmpTablesOwned,
    /// Step constants, 1..=4.
    pub steps: Vec<StepConstants>,
    /// First-layer bias variants (noise embedding per step folded in), back to back.
    pub first_layer_biases: Vec<P::Acc>,
    /// Activation tables.
    pub luts: Vec<P::Table>,
    /// Hidden layers.
    pub hidden: Vec<QuantizedLayer<P>>,
    /// Output layer.
    pub output: QuantizedOutput<P::Acc>,
}

impl<P: MlpPrecision + Into<i16>> QuantizedMlp<P> {
    /// Where each array goes: per hidden layer (weights i8, bias), then the first-layer bias
    /// variants, the output weights (i8) and bias (biases int32, or int64 with int16
    /// activations). Returns the entries in that order and the file length.
    pub fn weight_file_layout(&self) -> (Vec<WeightEntry>, usize) {
        let mut entries = Vec::new();
        let mut cursor = 0;
        let mut place = |count: usize, size: usize| {
            let entry = WeightEntry {
                offset: cursor,
                count,
            };
            cursor = (cursor + count * size).div_ceil(ALIGN) * ALIGN;
            entries.push(entry);
        };
        let bias_size = core::mem::size_of::<P::Acc>();
        for layer in &self.hidden {
            place(layer.weights.len(), 1);
            place(layer.bias.len(), bias_size);
        }
        place(self.first_layer_biases.len(), bias_size);
        place(self.output.weights.len(), 1);
        place(self.output.bias.len(), bias_size);
        (entries, cursor)
    }

    /// Width of the model input vector per the layout.
    pub fn input_width(&self) -> Option<usize> {
        self.layout
            .width(self.history, self.obs_dim, self.action_dim, self.horizon)
    }

    /// Widest layer.
    pub fn scratch_width(&self) -> usize {
        self.hidden
            .iter()
            .flat_map(|l| [l.in_features, l.out_features])
            .chain([self.output.in_features, self.output.out_features])
            .max()
            .unwrap_or(0)
    }

    /// The policy configuration (normalization, steps, decoder, layout) as frmd-core's view.
    pub fn config(&self) -> PolicyConfig<'_> {
        PolicyConfig {
            history: self.history,
            obs_norm: RangeNormalizer::new(&self.obs_min, &self.obs_max),
            action_norm: RangeNormalizer::new(&self.action_min, &self.action_max),
            sampler: Sampler {
                steps: StepTable::new(&self.steps),
                decoder: self.prodmp.view(),
                layout: self.layout,
                control_dt: self.control_dt,
            },
        }
    }

    /// The hidden layers as frmd-core views (tables from [`Self::luts`]; a layer naming a missing
    /// table gets none).
    pub fn hidden_layers(&self) -> Vec<RequantizedLinear<'_, P>> {
        self.hidden
            .iter()
            .map(|l| RequantizedLinear {
                fc: FullyConnected::new(l.in_features, l.out_features, &l.weights, &l.bias),
                requant: FcRequant {
                    multipliers: &l.multipliers,
                    shifts: &l.shifts,
                    output_zero_point: l.output_zero_point,
                    activation_min: l.activation_min,
                    activation_max: l.activation_max,
                },
                activation: l.lut.and_then(|i| self.luts.get(i)),
            })
            .collect()
    }

    /// The output layer as a frmd-core view.
    pub fn output_layer(&self) -> Int8Linear<'_, P::Acc> {
        let o = &self.output;
        Int8Linear {
            fc: FullyConnected::new(o.in_features, o.out_features, &o.weights, &o.bias),
            output_scales: &o.scales,
        }
    }

    /// Borrowed view for [`frmd_core::blob::encode_mlp`], given to `f`.
    pub fn with_parts<R>(&self, f: impl FnOnce(&MlpBlobParts<'_, P>) -> R) -> R {
        let hidden = self.hidden_layers();
        let parts = MlpBlobParts {
            config: self.config(),
            mlp: QuantMlp {
                input: self.input,
                hidden: &hidden,
                output: self.output_layer(),
            },
            input_precision: self.input_precision,
            noise_variants: &self.first_layer_biases,
        };
        f(&parts)
    }

    /// The policy's sizes.
    pub fn dims(&self) -> PolicyDims {
        PolicyDims {
            history: self.history,
            obs_dim: self.obs_dim,
            action_dim: self.action_dim,
            horizon: self.horizon,
            params_per_dof: self.params_per_dof,
        }
    }

    /// The self-describing blob (format in [`frmd_core::blob::mlp`]); a named error if a part's
    /// length disagrees with the stated shapes.
    pub fn blob(&self) -> Result<Vec<u8>, BlobError> {
        self.with_parts(|parts| {
            let mut out = vec![0_u8; mlp_encoded_len(parts)?];
            let written = encode_mlp(parts, &mut out)?;
            out.truncate(written);
            Ok(out)
        })
    }

    /// RAM/flash figures of the baked form (estimates of the tables the generated module holds;
    /// the exact RAM of the policy object is `size_of::<BakedPolicy>()` in the generated module).
    pub fn memory(&self) -> MemoryFigures {
        let width = self.scratch_width();
        let dims = self.dims();
        let channels: usize = self.hidden.iter().map(|l| l.out_features).sum();
        let code = core::mem::size_of::<P>();
        MemoryFigures {
            scratch_width: width,
            // Two activation buffers and the accumulators.
            scratch_bytes: (2 * code + core::mem::size_of::<P::Acc>()) * width,
            state_bytes: state_bytes(&dims, self.input_width().unwrap_or(0)),
            weights_bytes: self.weight_file_layout().1,
            table_bytes: 8 * channels
                + code * P::TABLE_LEN * self.luts.len()
                + 4 * self.output.out_features
                + policy_table_bytes(&dims, self.steps.len()),
        }
    }
}
