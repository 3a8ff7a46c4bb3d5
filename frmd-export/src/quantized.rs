//! [`QuantizedPolicy`]: the owned, target-independent result of quantization, from which both
//! output forms (blob and baked module) are written.

use frmd_core::blob::{MlpBlobParts, LUT_LEN};
use frmd_core::kernels::{FcRequant, FullyConnected};
use frmd_core::model::linear::{Int8Linear, RequantizedLinear};
use frmd_core::model::mlp::{InputPrecision, Int8Mlp};
use frmd_core::policy::{
    InputLayout, PolicyConfig, ProDmpTables, RangeNormalizer, Sampler, StepConstants, StepTable,
};
use frmd_core::prodmp::BakedProDmp;
use frmd_core::quant::QuantParams;

/// ProDMP decoder tables (row-major `[N][P]` and `[N]`), as [`BakedProDmp`] holds them.
#[derive(Clone, Debug, PartialEq)]
pub struct ProDmpTablesOwned {
    /// `[N][P]` position coefficients of `[w.., g]`.
    pub pos_params: Vec<f32>,
    /// `[N][P]` velocity coefficients (1/s).
    pub vel_params: Vec<f32>,
    /// `[N]` position coefficient of `y0`.
    pub pos_y0: Vec<f32>,
    /// `[N]` position coefficient of `v0` (s).
    pub pos_v0: Vec<f32>,
    /// `[N]` velocity coefficient of `y0` (1/s).
    pub vel_y0: Vec<f32>,
    /// `[N]` velocity coefficient of `v0`.
    pub vel_v0: Vec<f32>,
}

impl ProDmpTablesOwned {
    /// Copies the tables of a baked decoder.
    pub fn from_baked<const N: usize, const P: usize>(baked: &BakedProDmp<N, P>) -> Self {
        Self {
            pos_params: baked.pos_params.as_flattened().to_vec(),
            vel_params: baked.vel_params.as_flattened().to_vec(),
            pos_y0: baked.pos_y0.to_vec(),
            pos_v0: baked.pos_v0.to_vec(),
            vel_y0: baked.vel_y0.to_vec(),
            vel_v0: baked.vel_v0.to_vec(),
        }
    }

    /// The tables as frmd-core's decoder view.
    pub fn view(&self) -> ProDmpTables<'_> {
        ProDmpTables {
            pos_params: &self.pos_params,
            vel_params: &self.vel_params,
            pos_y0: &self.pos_y0,
            pos_v0: &self.pos_v0,
            vel_y0: &self.vel_y0,
            vel_v0: &self.vel_v0,
        }
    }
}

/// One quantized hidden layer (int8 FC, per-channel requantization, optional LUT).
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct QuantizedLayer {
    /// Input width.
    pub in_features: usize,
    /// Output width.
    pub out_features: usize,
    /// `[out, in]` int8 weights, symmetric per output channel.
    pub weights: Vec<i8>,
    /// `[out]` int32 bias, input zero point folded (the first layer: step 0's variant).
    pub bias: Vec<i32>,
    /// `[out]` Q31 multipliers.
    pub multipliers: Vec<i32>,
    /// `[out]` shifts.
    pub shifts: Vec<i32>,
    /// Zero point of the requantized output.
    pub output_zero_point: i32,
    /// Lower output clamp.
    pub activation_min: i8,
    /// Upper output clamp.
    pub activation_max: i8,
    /// Index into [`QuantizedPolicy::luts`] of the activation, if any.
    pub lut: Option<usize>,
}

/// The output layer: int8 FC whose accumulators are dequantized to f32 ProDMP parameters.
#[derive(Clone, Debug, PartialEq)]
pub struct QuantizedOutput {
    /// Input width.
    pub in_features: usize,
    /// Output width (`K * P`).
    pub out_features: usize,
    /// `[out, in]` int8 weights.
    pub weights: Vec<i8>,
    /// `[out]` int32 bias.
    pub bias: Vec<i32>,
    /// `[out]` dequantization scales `input_scale * weight_scale[o]`.
    pub scales: Vec<f32>,
}

/// A calibrated, quantized student with everything the firmware needs besides code.
#[derive(Clone, Debug, PartialEq)]
pub struct QuantizedPolicy {
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
    pub first_layer_biases: Vec<i32>,
    /// Activation LUTs.
    pub luts: Vec<[i8; LUT_LEN]>,
    /// Hidden layers.
    pub hidden: Vec<QuantizedLayer>,
    /// Output layer.
    pub output: QuantizedOutput,
}

/// RAM and flash figures of a policy (bytes).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct MemoryFigures {
    /// Widest layer (input, hidden or output): the `WIDTH` of the scratch buffers.
    pub scratch_width: usize,
    /// Forward-pass scratch: two int8 activations and one int32 accumulator row of `WIDTH`.
    pub scratch_bytes: usize,
    /// Sampler working memory and policy state (history, chunk buffers, input vector), f32.
    pub state_bytes: usize,
    /// Weight file: int8 weights, int32 biases (incl. bias variants), padding.
    pub weights_bytes: usize,
    /// Constant tables: multipliers, shifts, LUTs, output scales, ProDMP, normalization, steps.
    pub table_bytes: usize,
}

impl MemoryFigures {
    /// Total read-only bytes (weights plus tables).
    pub fn flash_bytes(&self) -> usize {
        self.weights_bytes + self.table_bytes
    }
}

impl QuantizedPolicy {
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
    pub fn hidden_layers(&self) -> Vec<RequantizedLinear<'_>> {
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
    pub fn output_layer(&self) -> Int8Linear<'_> {
        let o = &self.output;
        Int8Linear {
            fc: FullyConnected::new(o.in_features, o.out_features, &o.weights, &o.bias),
            output_scales: &o.scales,
        }
    }

    /// Borrowed view for [`frmd_core::blob::encode_mlp`], given to `f`.
    pub fn with_parts<R>(&self, f: impl FnOnce(&MlpBlobParts<'_>) -> R) -> R {
        let hidden = self.hidden_layers();
        let parts = MlpBlobParts {
            config: self.config(),
            mlp: Int8Mlp {
                input: self.input,
                hidden: &hidden,
                output: self.output_layer(),
            },
            input_precision: self.input_precision,
            noise_variants: &self.first_layer_biases,
        };
        f(&parts)
    }

    /// RAM/flash figures of the baked form (estimates of the tables the generated module holds;
    /// the exact RAM of the policy object is `size_of::<BakedPolicy>()` in the generated module).
    pub fn memory(&self) -> MemoryFigures {
        let width = self.scratch_width();
        let (m, o, k, n, p) = (
            self.history,
            self.obs_dim,
            self.action_dim,
            self.horizon,
            self.params_per_dof,
        );
        let input = self.input_width().unwrap_or(0);
        // history ring + ordered copy, 2 x noisy/noise, 3 trajectories (decoded, normalized,
        // chunk) of positions and velocities, input vector, params, prev action and rate.
        let floats = 2 * m * o + 2 * n * k + 6 * n * k + input + k * p + 2 * k;
        let weights_bytes = crate::bake::weight_file_layout(self).1;
        let channels: usize = self.hidden.iter().map(|l| l.out_features).sum();
        let table_bytes = 8 * channels
            + LUT_LEN * self.luts.len()
            + 4 * self.output.out_features
            + 4 * n * (2 * p + 4)
            + 8 * (o + k)
            + 24 * self.steps.len();
        MemoryFigures {
            scratch_width: width,
            scratch_bytes: 6 * width,
            state_bytes: 4 * floats,
            weights_bytes,
            table_bytes,
        }
    }
}
