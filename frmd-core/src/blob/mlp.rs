//! MLP blobs (magic [`MLP_MAGIC`], `b"FRMD"`): the [`MlpDescriptor`], its emit side
//! ([`encode_mlp`] from borrowed [`MlpBlobParts`]) and its parse side ([`LoadedMlp`]).
//!
//! Data area, in order: the policy sections ([`super::policy_tables`]), the first-layer bias
//! variants (i32), the activation tables (i8, [`LUT_LEN`] each, one per hidden layer that has one,
//! in layer order), then per hidden layer weights (i8 `[out, in]`), bias, multipliers and shifts
//! (i32 `[out]`), then the output layer's weights, bias and dequantization scales (f32). The data
//! area ends at a multiple of 16 bytes.

use heapless::Vec;
use serde::{Deserialize, Serialize};

use super::container::{self, Data, Section, SectionId, SectionWriter};
use super::policy_tables::{self, PolicyFields, PolicySections, PolicyTables};
use super::BlobError;
use crate::kernels::{FcRequant, FullyConnected, LutTable};
use crate::model::linear::{Int8Linear, RequantizedLinear};
use crate::model::mlp::{InputPrecision, Int8Mlp};
use crate::policy::{
    InputLayout, Int8MlpNetwork, Policy, PolicyConfig, PolicyDims, PolicyError, StepConstants,
    MAX_HIDDEN_LAYERS,
};
use crate::quant::{QuantParams, SHIFT_MAX, SHIFT_MIN};

/// First four bytes of an MLP blob.
pub const MLP_MAGIC: [u8; 4] = *b"FRMD";
/// [`MlpDescriptor::input_precision`] of int8 input ([`InputPrecision::Int8`]).
pub const INPUT_INT8: u8 = 0;
/// [`MlpDescriptor::input_precision`] of a two-plane input ([`InputPrecision::TwoPlane`]).
pub const INPUT_TWO_PLANE: u8 = 1;
/// [`MlpDescriptor::input_precision`] of the 16-bit input plane ([`InputPrecision::Int16`]).
pub const INPUT_INT16: u8 = 2;
/// Bytes per table in the activation-table section (outputs for input codes -128..=127).
pub const LUT_LEN: usize = 256;

/// One hidden layer: int8 FC, per-channel requantization, optional activation table.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
pub struct HiddenLayerDesc {
    /// Input width.
    pub in_features: u32,
    /// Output width.
    pub out_features: u32,
    /// i8 `[out, in]` row-major.
    pub weights: Section,
    /// i32 `[out]` (input zero point folded). For the first layer these are variant 0's; the
    /// sampler uses the first-layer-bias section instead when it is non-empty.
    pub bias: Section,
    /// i32 `[out]` Q31 multipliers.
    pub multipliers: Section,
    /// i32 `[out]` shifts.
    pub shifts: Section,
    /// Zero point of the requantized output.
    pub output_zero_point: i32,
    /// Lower clamp of the requantized output.
    pub activation_min: i8,
    /// Upper clamp of the requantized output.
    pub activation_max: i8,
    /// Index of the table applied after requantization, if any.
    pub lut: Option<u32>,
}

/// The output layer: int8 FC whose int32 accumulators are dequantized to f32.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
pub struct OutputLayerDesc {
    /// Input width.
    pub in_features: u32,
    /// Output width (`k p`).
    pub out_features: u32,
    /// i8 `[out, in]` row-major.
    pub weights: Section,
    /// i32 `[out]`.
    pub bias: Section,
    /// f32 `[out]` dequantization scales.
    pub scales: Section,
}

/// Everything about an MLP blob that is not bulk data.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct MlpDescriptor {
    /// Observation history length `m`.
    pub history: u32,
    /// Observation dimension `o`.
    pub obs_dim: u32,
    /// Action dimension `k`.
    pub action_dim: u32,
    /// Horizon `n`.
    pub horizon: u32,
    /// ProDMP parameters per DoF `p`.
    pub params_per_dof: u32,
    /// Control period, seconds.
    pub control_dt: f32,
    /// Model input layout.
    pub layout: InputLayout,
    /// Input quantization scale.
    pub input_scale: f32,
    /// Input quantization zero point.
    pub input_zero_point: i32,
    /// How the first layer takes the input ([`INPUT_INT8`], [`INPUT_TWO_PLANE`] or
    /// [`INPUT_INT16`]); a `bool` "two-plane" flag in format version 2.
    pub input_precision: u8,
    /// f32 `[min; o]` then `[max; o]`.
    pub obs_norm: Section,
    /// f32 `[min; k]` then `[max; k]`.
    pub action_norm: Section,
    /// f32 `pos_params [n][p]`, `vel_params [n][p]`, `pos_y0 [n]`, `pos_v0 [n]`, `vel_y0 [n]`,
    /// `vel_v0 [n]`.
    pub prodmp: Section,
    /// u32 `[steps][STEP_WORDS]`.
    pub steps: Section,
    /// i32 first-layer bias variants, `out_features` of the first layer each (may be empty).
    pub first_layer_biases: Section,
    /// i8 `[tables][LUT_LEN]`.
    pub luts: Section,
    /// Hidden layers in order.
    pub hidden: Vec<HiddenLayerDesc, MAX_HIDDEN_LAYERS>,
    /// Output layer.
    pub output: OutputLayerDesc,
}

/// Everything an MLP blob holds, borrowed.
#[derive(Clone, Copy, Debug)]
pub struct MlpBlobParts<'p> {
    /// Normalization, steps, decoder tables, layout, control period.
    pub config: PolicyConfig<'p>,
    /// The int8 network (its first hidden layer's bias is variant 0).
    pub mlp: Int8Mlp<'p>,
    /// How the first layer takes the input (its multipliers must match).
    pub input_precision: InputPrecision,
    /// First-layer bias variants back to back (may be empty).
    pub noise_variants: &'p [i32],
}

fn precision_code(precision: InputPrecision) -> u8 {
    match precision {
        InputPrecision::Int8 => INPUT_INT8,
        InputPrecision::TwoPlane => INPUT_TWO_PLANE,
        InputPrecision::Int16 => INPUT_INT16,
    }
}

fn small(value: usize) -> Result<u32, BlobError> {
    u32::try_from(value).map_err(|_| BlobError::TooLarge)
}

fn expect_len(actual: usize, expected: Option<usize>, id: SectionId) -> Result<(), BlobError> {
    if Some(actual) == expected {
        Ok(())
    } else {
        Err(BlobError::SectionLength(id))
    }
}

/// Lays out the sections of `parts` (every length checked against the stated shapes) and
/// returns the descriptor.
fn emit(parts: &MlpBlobParts<'_>, writer: &mut SectionWriter<'_>) -> Result<MlpDescriptor, BlobError> {
    let PolicySections {
        obs_norm,
        action_norm,
        prodmp,
        steps,
    } = policy_tables::write(writer, &parts.config)?;
    let first_layer_biases = writer.i32s(parts.noise_variants)?;
    let tables = parts.mlp.hidden.iter().filter_map(|layer| layer.activation);
    let luts = writer.i8s(tables.flatten())?;
    let mut hidden = Vec::new();
    let mut next_lut = 0_u32;
    for (index, layer) in parts.mlp.hidden.iter().enumerate() {
        let id = u8::try_from(index).map_err(|_| BlobError::TooLarge)?;
        let (fc, requant) = (&layer.fc, &layer.requant);
        let out = fc.out_features;
        let weight_count = out.checked_mul(fc.in_features);
        expect_len(fc.weights.len(), weight_count, SectionId::HiddenWeights(id))?;
        expect_len(fc.bias.len(), Some(out), SectionId::HiddenBias(id))?;
        expect_len(requant.multipliers.len(), Some(out), SectionId::HiddenMultipliers(id))?;
        expect_len(requant.shifts.len(), Some(out), SectionId::HiddenShifts(id))?;
        let lut = layer.activation.map(|_| {
            next_lut += 1;
            next_lut - 1
        });
        let desc = HiddenLayerDesc {
            in_features: small(fc.in_features)?,
            out_features: small(out)?,
            weights: writer.i8s(fc.weights.iter())?,
            bias: writer.i32s(fc.bias)?,
            multipliers: writer.i32s(requant.multipliers)?,
            shifts: writer.i32s(requant.shifts)?,
            output_zero_point: requant.output_zero_point,
            activation_min: requant.activation_min,
            activation_max: requant.activation_max,
            lut,
        };
        hidden.push(desc).map_err(|_| BlobError::TooLarge)?;
    }
    let (fc, scales) = (&parts.mlp.output.fc, parts.mlp.output.output_scales);
    let out = fc.out_features;
    expect_len(fc.weights.len(), out.checked_mul(fc.in_features), SectionId::OutputWeights)?;
    expect_len(fc.bias.len(), Some(out), SectionId::OutputBias)?;
    expect_len(scales.len(), Some(out), SectionId::OutputScales)?;
    let output = OutputLayerDesc {
        in_features: small(fc.in_features)?,
        out_features: small(out)?,
        weights: writer.i8s(fc.weights.iter())?,
        bias: writer.i32s(fc.bias)?,
        scales: writer.f32s(scales.iter())?,
    };
    writer.pad_end();
    let dims = parts.config.dims();
    Ok(MlpDescriptor {
        history: small(dims.history)?,
        obs_dim: small(dims.obs_dim)?,
        action_dim: small(dims.action_dim)?,
        horizon: small(dims.horizon)?,
        params_per_dof: small(dims.params_per_dof)?,
        control_dt: parts.config.sampler.control_dt,
        layout: parts.config.sampler.layout,
        input_scale: parts.mlp.input.scale,
        input_zero_point: parts.mlp.input.zero_point,
        input_precision: precision_code(parts.input_precision),
        obs_norm,
        action_norm,
        prodmp,
        steps,
        first_layer_biases,
        luts,
        hidden,
        output,
    })
}

/// Exact length of the blob [`encode_mlp`] writes for `parts`.
pub fn mlp_encoded_len(parts: &MlpBlobParts<'_>) -> Result<usize, BlobError> {
    container::encoded_len(|writer| emit(parts, writer))
}

/// Writes the MLP blob of `parts` into the front of `out` and returns its length
/// ([`mlp_encoded_len`]); the rest of `out` is untouched. Every part's length is checked against
/// the stated shapes; value checks (finite floats, shift ranges, ...) are the loader's.
pub fn encode_mlp(parts: &MlpBlobParts<'_>, out: &mut [u8]) -> Result<usize, BlobError> {
    container::encode(MLP_MAGIC, out, |writer| emit(parts, writer))
}

/// A validated MLP blob, borrowed: weights, biases, requantization parameters, tables, scales,
/// normalization and decoder tables stay in the blob (`'a`); the steps are copied. Its
/// [`Self::config`] and [`Self::network`] borrow only the blob, so the policy built from them may
/// outlive the `LoadedMlp`:
///
/// ```text
/// let loaded = LoadedMlp::load(BLOB)?;           // BLOB: 4-aligned &'static [u8]
/// loaded.check_dims(&EXPECTED)?;                 // the sizes the firmware was built for
/// let mut policy = loaded.policy::<2, 10, 3, 12, 21, 64, 256>()?;  // capacities, scratch width
/// policy.reset(&current_position)?;
/// loop {
///     policy.observe(&read_sensors())?;
///     if need_new_chunk { policy.act(Noise::Rng(&mut rng))?; }
///     if let Some(action) = policy.next_action() { command(action); }
/// }
/// ```
#[derive(Clone, Debug)]
pub struct LoadedMlp<'a> {
    tables: PolicyTables<'a>,
    layout: InputLayout,
    input: QuantParams,
    input_precision: InputPrecision,
    hidden: Vec<RequantizedLinear<'a>, MAX_HIDDEN_LAYERS>,
    output: Int8Linear<'a>,
    noise_variants: &'a [i32],
}

impl<'a> LoadedMlp<'a> {
    /// Validates `bytes` (header, CRC, descriptor, sections, shapes, values) and borrows it.
    /// Bytes after the stated total length are ignored (e.g. flash padding). The buffer must start
    /// at a 4-byte aligned address.
    pub fn load(bytes: &'a [u8]) -> Result<Self, BlobError> {
        let (descriptor, data) = container::parse::<MlpDescriptor>(bytes, MLP_MAGIC, true)?;
        Self::view(&descriptor, &data)
    }

    /// [`Self::load`] without recomputing the CRC, for bytes that passed [`Self::load`] before
    /// (a host keeping a blob and viewing it again); every other check runs.
    pub fn reload(bytes: &'a [u8]) -> Result<Self, BlobError> {
        let (descriptor, data) = container::parse::<MlpDescriptor>(bytes, MLP_MAGIC, false)?;
        Self::view(&descriptor, &data)
    }

    fn view(d: &MlpDescriptor, data: &Data<'a>) -> Result<Self, BlobError> {
        let fields = PolicyFields {
            dims: [d.history, d.obs_dim, d.action_dim, d.horizon, d.params_per_dof],
            control_dt: d.control_dt,
            sections: PolicySections {
                obs_norm: d.obs_norm,
                action_norm: d.action_norm,
                prodmp: d.prodmp,
                steps: d.steps,
            },
        };
        let tables = policy_tables::read(data, fields)?;
        let input = QuantParams::new(d.input_scale, d.input_zero_point)
            .map_err(|_| BlobError::InputQuantization)?;
        let input_precision = match (d.input_precision, d.hidden.is_empty()) {
            (INPUT_INT8, _) => InputPrecision::Int8,
            (INPUT_TWO_PLANE, false) => InputPrecision::TwoPlane,
            (INPUT_INT16, false) => InputPrecision::Int16,
            _ => return Err(BlobError::InputQuantization),
        };
        d.layout.validate().map_err(|_| BlobError::InputLayout)?;
        let input_width = d
            .layout
            .width_of(&tables.dims)
            .ok_or(BlobError::InputLayout)?;
        let lut_bytes = data.cast::<i8>(d.luts, SectionId::Luts)?;
        if !lut_bytes.len().is_multiple_of(LUT_LEN) || lut_bytes.len() / LUT_LEN > MAX_HIDDEN_LAYERS
        {
            return Err(BlobError::SectionLength(SectionId::Luts));
        }
        let luts = lut_bytes.chunks_exact(LUT_LEN);
        let mut hidden = Vec::new();
        let mut width = input_width;
        for (index, desc) in d.hidden.iter().enumerate() {
            let layer = read_hidden(data, desc, index, width, luts.clone())?;
            width = layer.fc.out_features;
            hidden.push(layer).map_err(|_| BlobError::TooLarge)?;
        }
        let output = read_output(data, d, width, &tables.dims)?;
        let first_width = hidden
            .first()
            .map_or(output.fc.out_features, |layer| layer.fc.out_features);
        let noise_variants = data.cast::<i32>(d.first_layer_biases, SectionId::FirstLayerBiases)?;
        let variants = noise_variants
            .len()
            .checked_div(first_width)
            .filter(|_| noise_variants.len().is_multiple_of(first_width))
            .ok_or(BlobError::SectionLength(SectionId::FirstLayerBiases))?;
        policy_tables::check_variants(&tables.steps, variants)?;
        Ok(Self {
            tables,
            layout: d.layout,
            input,
            input_precision,
            hidden,
            output,
            noise_variants,
        })
    }

    /// The blob's sizes.
    pub fn dims(&self) -> PolicyDims {
        self.tables.dims
    }

    /// [`BlobError::DimensionMismatch`] unless the blob has the sizes `expected` (e.g. those a
    /// firmware image was built for).
    pub fn check_dims(&self, expected: &PolicyDims) -> Result<(), BlobError> {
        self.tables.check_dims(expected)
    }

    /// The step table.
    pub fn steps(&self) -> &[StepConstants] {
        self.tables.steps.as_slice()
    }

    /// The model input layout.
    pub fn layout(&self) -> &InputLayout {
        &self.layout
    }

    /// The ProDMP decoder tables.
    pub fn decoder(&self) -> crate::policy::ProDmpTables<'a> {
        self.tables.decoder
    }

    /// Control period, seconds.
    pub fn control_dt(&self) -> f32 {
        self.tables.control_dt
    }

    /// How the first layer takes the input.
    pub fn input_precision(&self) -> InputPrecision {
        self.input_precision
    }

    /// The int8 MLP over the blob's weights (its own first-layer bias: variant 0), with its
    /// hidden layers in `hidden` (from [`Self::hidden_layers`]).
    pub fn mlp<'b>(&self, hidden: &'b [RequantizedLinear<'a>]) -> Int8Mlp<'b>
    where
        'a: 'b,
    {
        Int8Mlp {
            input: self.input,
            hidden,
            output: self.output,
        }
    }

    /// The hidden layers.
    pub fn hidden_layers(&self) -> &[RequantizedLinear<'a>] {
        &self.hidden
    }

    /// The first-layer bias variants, back to back.
    pub fn noise_variants(&self) -> &'a [i32] {
        self.noise_variants
    }

    /// The int8 network over the blob's weights, with scratch for layers up to `WIDTH` wide.
    pub fn network<const WIDTH: usize>(&self) -> Result<Int8MlpNetwork<'a, WIDTH>, PolicyError> {
        Int8MlpNetwork::new(
            self.input,
            self.input_precision,
            &self.hidden,
            self.output,
            self.noise_variants,
        )
    }

    /// The policy configuration (normalization, sampler) borrowing the blob.
    pub fn config(&self) -> PolicyConfig<'a> {
        self.tables.config(self.layout)
    }

    /// A ready policy with capacities `M, O, K, N, P`, an input buffer of `I` values and network
    /// scratch of `WIDTH`.
    #[allow(clippy::type_complexity)]
    pub fn policy<
        const M: usize,
        const O: usize,
        const K: usize,
        const N: usize,
        const P: usize,
        const I: usize,
        const WIDTH: usize,
    >(
        &self,
    ) -> Result<Policy<'a, Int8MlpNetwork<'a, WIDTH>, M, O, K, N, P, I>, PolicyError> {
        Policy::new(self.config(), self.network::<WIDTH>()?)
    }
}

fn read_hidden<'a, 'l>(
    data: &Data<'a>,
    desc: &HiddenLayerDesc,
    index: usize,
    width: usize,
    mut luts: impl Iterator<Item = &'a [i8]>,
) -> Result<RequantizedLinear<'a>, BlobError> {
    let layer = index as u8; // at most MAX_HIDDEN_LAYERS (heapless capacity)
    let (inputs, outputs) = (desc.in_features as usize, desc.out_features as usize);
    if inputs != width || outputs == 0 {
        return Err(if index == 0 {
            BlobError::InputLayout
        } else {
            BlobError::LayerWidth { index: layer }
        });
    }
    let weights = data.exact::<i8>(
        desc.weights,
        outputs.checked_mul(inputs),
        SectionId::HiddenWeights(layer),
    )?;
    let bias = data.exact::<i32>(desc.bias, Some(outputs), SectionId::HiddenBias(layer))?;
    let multipliers = data.exact::<i32>(
        desc.multipliers,
        Some(outputs),
        SectionId::HiddenMultipliers(layer),
    )?;
    let shifts = data.exact::<i32>(desc.shifts, Some(outputs), SectionId::HiddenShifts(layer))?;
    if multipliers.iter().any(|m| *m < 0) {
        return Err(BlobError::NegativeMultiplier { layer });
    }
    if shifts.iter().any(|s| !(SHIFT_MIN..=SHIFT_MAX).contains(s)) {
        return Err(BlobError::ShiftOutOfRange { layer });
    }
    if !(-128..=127).contains(&desc.output_zero_point) || desc.activation_min > desc.activation_max
    {
        return Err(BlobError::Requantization { layer });
    }
    let activation: Option<&'a LutTable> = match desc.lut {
        Some(i) => Some(
            luts.nth(i as usize)
                .and_then(|table| table.try_into().ok())
                .ok_or(BlobError::LutIndex { layer })?,
        ),
        None => None,
    };
    Ok(RequantizedLinear {
        fc: FullyConnected::new(inputs, outputs, weights, bias),
        requant: FcRequant {
            multipliers,
            shifts,
            output_zero_point: desc.output_zero_point,
            activation_min: desc.activation_min,
            activation_max: desc.activation_max,
        },
        activation,
    })
}

fn read_output<'a>(
    data: &Data<'a>,
    d: &MlpDescriptor,
    width: usize,
    dims: &PolicyDims,
) -> Result<Int8Linear<'a>, BlobError> {
    let out = &d.output;
    let (inputs, outputs) = (out.in_features as usize, out.out_features as usize);
    if inputs != width || inputs == 0 {
        return Err(if d.hidden.is_empty() {
            BlobError::InputLayout
        } else {
            BlobError::LayerWidth {
                index: d.hidden.len() as u8,
            }
        });
    }
    if Some(outputs) != dims.params_len() {
        return Err(BlobError::OutputWidth);
    }
    let weights = data.exact::<i8>(
        out.weights,
        outputs.checked_mul(inputs),
        SectionId::OutputWeights,
    )?;
    let bias = data.exact::<i32>(out.bias, Some(outputs), SectionId::OutputBias)?;
    let output_scales = data.finite(out.scales, Some(outputs), SectionId::OutputScales)?;
    Ok(Int8Linear {
        fc: FullyConnected::new(inputs, outputs, weights, bias),
        output_scales,
    })
}
