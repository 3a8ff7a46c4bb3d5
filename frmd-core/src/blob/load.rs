//! Blob loader: full validation, then a [`LoadedPolicy`] that borrows the blob.

use bytemuck::PodCastError;

use super::crc32::crc32;
use super::format::{
    Descriptor, Section, SectionId, FORMAT_VERSION, HEADER_LEN, INPUT_INT16, INPUT_INT8,
    INPUT_TWO_PLANE, LUT_LEN, MAGIC, MIN_FORMAT_VERSION, SECTION_ALIGN,
    STEP_WORDS,
};
use super::writer::data_start;
use super::{BlobError, Dimension};
use crate::kernels::{FcRequant, FullyConnected, Lut8};
use crate::model::mlp::{InputPrecision, Int8Layer};
use crate::policy::{
    validate_steps, InputLayout, Int8Network, Policy, PolicyConfig, PolicyError, RangeNormalizer,
    Sampler, StepConstants, MAX_HIDDEN_LAYERS, MAX_STEPS,
};
use crate::prodmp::BakedProDmp;
use crate::quant::{QuantParams, SHIFT_MAX, SHIFT_MIN};

/// One hidden layer borrowed from the blob (its LUT by index into [`LoadedPolicy`]'s copies).
#[derive(Clone, Copy, Debug)]
struct HiddenLayer<'a> {
    fc: FullyConnected<'a>,
    requant: FcRequant<'a>,
    lut: Option<usize>,
}

const EMPTY_LAYER: HiddenLayer<'static> = HiddenLayer {
    fc: FullyConnected::new(0, 0, &[], &[]),
    requant: FcRequant {
        multipliers: &[],
        shifts: &[],
        output_zero_point: 0,
        activation_min: i8::MIN,
        activation_max: i8::MAX,
    },
    lut: None,
};

/// A validated blob: `M` history, `O` observation dim, `K` action dim, `N` horizon, `P` ProDMP
/// parameters per DoF (all checked against the descriptor).
///
/// Weights, biases, multipliers, shifts and output scales stay in the blob (`'a`); the small
/// tables are copied: normalization (`8 (O + K)` bytes), ProDMP tables (`4 N (2 P + 4)`), steps and
/// up to [`MAX_HIDDEN_LAYERS`] LUTs of 256 bytes.
///
/// The policy built by [`Self::policy`] borrows the `LoadedPolicy`, so keep the `LoadedPolicy`
/// where it outlives the control loop (a `static` cell, or a local of a never-returning `main`):
///
/// ```text
/// let loaded = LoadedPolicy::<2, 10, 3, 12, 21>::load(BLOB)?;   // BLOB: 4-aligned &'static [u8]
/// let mut policy = loaded.policy::<64, 256>()?;                  // input capacity, scratch width
/// policy.reset(&current_position)?;
/// loop {
///     policy.observe(&read_sensors())?;
///     if need_new_chunk { policy.act(Noise::Rng(&mut rng))?; }
///     if let Some(action) = policy.next_action() { command(action); }
/// }
/// ```
#[derive(Clone, Debug)]
pub struct LoadedPolicy<
    'a,
    const M: usize,
    const O: usize,
    const K: usize,
    const N: usize,
    const P: usize,
> {
    shared: SharedTables<O, K, N, P>,
    layout: InputLayout,
    control_dt: f32,
    input: QuantParams,
    input_precision: InputPrecision,
    luts: [Lut8; MAX_HIDDEN_LAYERS],
    hidden: [HiddenLayer<'a>; MAX_HIDDEN_LAYERS],
    num_hidden: usize,
    output: FullyConnected<'a>,
    output_scales: &'a [f32],
    first_layer_biases: &'a [i32],
}

/// The data area and a checked view of one section as `T` elements.
pub(crate) struct Data<'a> {
    pub(crate) bytes: &'a [u8],
}

impl<'a> Data<'a> {
    pub(crate) fn cast<T: bytemuck::Pod>(
        &self,
        section: Section,
        id: SectionId,
    ) -> Result<&'a [T], BlobError> {
        let start = section.offset as usize;
        if !start.is_multiple_of(SECTION_ALIGN) {
            return Err(BlobError::SectionMisaligned(id));
        }
        let end = start
            .checked_add(section.len as usize)
            .ok_or(BlobError::SectionBounds(id))?;
        let raw = self
            .bytes
            .get(start..end)
            .ok_or(BlobError::SectionBounds(id))?;
        bytemuck::try_cast_slice(raw).map_err(|e| match e {
            PodCastError::TargetAlignmentGreaterAndInputNotAligned
            | PodCastError::AlignmentMismatch => BlobError::SectionMisaligned(id),
            PodCastError::OutputSliceWouldHaveSlop | PodCastError::SizeMismatch => {
                BlobError::SectionLength(id)
            }
        })
    }

    /// Section of exactly `count` elements.
    pub(crate) fn exact<T: bytemuck::Pod>(
        &self,
        section: Section,
        count: Option<usize>,
        id: SectionId,
    ) -> Result<&'a [T], BlobError> {
        let values = self.cast::<T>(section, id)?;
        if Some(values.len()) == count {
            Ok(values)
        } else {
            Err(BlobError::SectionLength(id))
        }
    }

    /// f32 section of exactly `count` finite values.
    pub(crate) fn finite(
        &self,
        section: Section,
        count: Option<usize>,
        id: SectionId,
    ) -> Result<&'a [f32], BlobError> {
        let values = self.exact::<f32>(section, count, id)?;
        if values.iter().all(|v| v.is_finite()) {
            Ok(values)
        } else {
            Err(BlobError::NonFinite(id))
        }
    }
}

fn read_u16(bytes: &[u8], at: usize) -> Result<u16, BlobError> {
    let raw = bytes.get(at..at + 2).ok_or(BlobError::Truncated)?;
    let mut word = [0_u8; 2];
    word.copy_from_slice(raw);
    Ok(u16::from_le_bytes(word))
}

fn read_u32(bytes: &[u8], at: usize) -> Result<u32, BlobError> {
    let raw = bytes.get(at..at + 4).ok_or(BlobError::Truncated)?;
    let mut word = [0_u8; 4];
    word.copy_from_slice(raw);
    Ok(u32::from_le_bytes(word))
}

pub(crate) fn check_dim(found: u32, expected: usize, which: Dimension) -> Result<(), BlobError> {
    if found as usize == expected {
        Ok(())
    } else {
        Err(BlobError::DimensionMismatch(which))
    }
}

/// Copies `values` into a fixed array (lengths checked by the caller).
pub(crate) fn to_array<const D: usize>(values: &[f32]) -> [f32; D] {
    let mut array = [0.0; D];
    for (slot, value) in array.iter_mut().zip(values) {
        *slot = *value;
    }
    array
}

/// Checks the header and CRC; returns the descriptor bytes and the data area.
pub(crate) fn split(bytes: &[u8], magic: [u8; 4]) -> Result<(&[u8], &[u8]), BlobError> {
    if cfg!(target_endian = "big") {
        return Err(BlobError::BigEndianTarget);
    }
    let header = bytes.get(..HEADER_LEN).ok_or(BlobError::Truncated)?;
    if header.get(..4) != Some(&magic[..]) {
        return Err(BlobError::BadMagic);
    }
    let version = read_u16(header, 4)?;
    if !(MIN_FORMAT_VERSION..=FORMAT_VERSION).contains(&version) {
        return Err(BlobError::UnsupportedVersion { found: version });
    }
    if read_u16(header, 6)? != 0 {
        return Err(BlobError::ReservedField);
    }
    let total = read_u32(header, 8)? as usize;
    let stored = read_u32(header, 12)?;
    let desc_len = read_u32(header, 16)? as usize;
    if total < HEADER_LEN {
        return Err(BlobError::InvalidLength);
    }
    let blob = bytes.get(..total).ok_or(BlobError::Truncated)?;
    let payload = blob.get(HEADER_LEN..).ok_or(BlobError::InvalidLength)?;
    let start = data_start(desc_len).ok_or(BlobError::InvalidLength)?;
    if start > total {
        return Err(BlobError::InvalidLength);
    }
    let computed = crc32(payload);
    if computed != stored {
        return Err(BlobError::CrcMismatch { stored, computed });
    }
    let descriptor = payload.get(..desc_len).ok_or(BlobError::InvalidLength)?;
    let data = blob.get(start..).ok_or(BlobError::InvalidLength)?;
    Ok((descriptor, data))
}

/// Descriptor fields shared by every policy blob kind (MLP and transformer), copied out of the
/// kind's own descriptor so one routine validates them.
#[derive(Clone, Copy, Debug)]
pub(crate) struct SharedFields {
    pub(crate) history: u32,
    pub(crate) obs_dim: u32,
    pub(crate) action_dim: u32,
    pub(crate) horizon: u32,
    pub(crate) params_per_dof: u32,
    /// Control period in seconds (must be finite and positive).
    pub(crate) control_dt: f32,
    pub(crate) obs_norm: Section,
    pub(crate) action_norm: Section,
    pub(crate) prodmp: Section,
    pub(crate) steps: Section,
}

/// [`SharedFields`] copied out of a descriptor value (MLP or transformer; both name the fields
/// alike).
macro_rules! shared_fields {
    ($descriptor:expr) => {
        SharedFields {
            history: $descriptor.history,
            obs_dim: $descriptor.obs_dim,
            action_dim: $descriptor.action_dim,
            horizon: $descriptor.horizon,
            params_per_dof: $descriptor.params_per_dof,
            control_dt: $descriptor.control_dt,
            obs_norm: $descriptor.obs_norm,
            action_norm: $descriptor.action_norm,
            prodmp: $descriptor.prodmp,
            steps: $descriptor.steps,
        }
    };
}
pub(crate) use shared_fields;

/// The validated, copied tables every policy blob kind carries (embedded by [`LoadedPolicy`] and
/// `LoadedTransformer`).
#[derive(Clone, Debug)]
pub(crate) struct SharedTables<const O: usize, const K: usize, const N: usize, const P: usize> {
    pub(crate) obs_norm: RangeNormalizer<O>,
    pub(crate) action_norm: RangeNormalizer<K>,
    pub(crate) decoder: BakedProDmp<N, P>,
    pub(crate) steps: [StepConstants; MAX_STEPS],
    pub(crate) num_steps: usize,
}

impl<const O: usize, const K: usize, const N: usize, const P: usize> SharedTables<O, K, N, P> {
    /// The active steps.
    pub(crate) fn steps(&self) -> &[StepConstants] {
        self.steps.get(..self.num_steps).unwrap_or(&[])
    }

    /// The policy configuration over these tables with the blob's `layout` and `control_dt`.
    pub(crate) fn config(
        &self,
        layout: InputLayout,
        control_dt: f32,
    ) -> PolicyConfig<'_, O, K, N, P> {
        PolicyConfig {
            obs_norm: self.obs_norm,
            action_norm: self.action_norm,
            sampler: Sampler {
                steps: self.steps(),
                decoder: &self.decoder,
                layout,
                control_dt,
            },
        }
    }
}

/// Checks the header and CRC (see [`split`]) and decodes the descriptor, which must fill the
/// descriptor bytes exactly; returns it with the data region.
pub(crate) fn parse_descriptor<'a, D: serde::Deserialize<'a>>(
    bytes: &'a [u8],
    magic: [u8; 4],
) -> Result<(D, Data<'a>), BlobError> {
    let (descriptor_bytes, data_bytes) = split(bytes, magic)?;
    let (descriptor, rest) =
        postcard::take_from_bytes::<D>(descriptor_bytes).map_err(|_| BlobError::Descriptor)?;
    if !rest.is_empty() {
        return Err(BlobError::Descriptor);
    }
    Ok((descriptor, Data { bytes: data_bytes }))
}

impl<'a, const M: usize, const O: usize, const K: usize, const N: usize, const P: usize>
    LoadedPolicy<'a, M, O, K, N, P>
{
    /// Validates `bytes` (header, CRC, descriptor, sections, shapes, values) and borrows it.
    /// Bytes after the stated total length are ignored (e.g. flash padding). The buffer must start
    /// at a 4-byte aligned address.
    pub fn load(bytes: &'a [u8]) -> Result<Self, BlobError> {
        let (d, data) = parse_descriptor::<Descriptor>(bytes, MAGIC)?;
        let shared = Self::read_shared(&data, shared_fields!(d))?;
        let input = QuantParams::new(d.input_scale, d.input_zero_point)
            .map_err(|_| BlobError::InputQuantization)?;
        let input_precision = match (d.input_precision, d.hidden.is_empty()) {
            (INPUT_INT8, _) => InputPrecision::Int8,
            (INPUT_TWO_PLANE, false) => InputPrecision::TwoPlane,
            (INPUT_INT16, false) => InputPrecision::Int16,
            _ => return Err(BlobError::InputQuantization),
        };
        d.layout.validate().map_err(|_| BlobError::InputLayout)?;
        let input_width = d.layout.width(M, O, K, N).ok_or(BlobError::InputLayout)?;

        let lut_bytes = data.cast::<i8>(d.luts, SectionId::Luts)?;
        if !lut_bytes.len().is_multiple_of(LUT_LEN) || lut_bytes.len() / LUT_LEN > MAX_HIDDEN_LAYERS
        {
            return Err(BlobError::SectionLength(SectionId::Luts));
        }
        let mut luts = [Lut8::from_table([0; LUT_LEN]); MAX_HIDDEN_LAYERS];
        for (lut, table) in luts.iter_mut().zip(lut_bytes.chunks_exact(LUT_LEN)) {
            for (slot, value) in lut.table.iter_mut().zip(table) {
                *slot = *value;
            }
        }
        let num_luts = lut_bytes.len() / LUT_LEN;

        let mut hidden = [EMPTY_LAYER; MAX_HIDDEN_LAYERS];
        let mut width = input_width;
        for (index, (desc, slot)) in d.hidden.iter().zip(hidden.iter_mut()).enumerate() {
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
            let shifts =
                data.exact::<i32>(desc.shifts, Some(outputs), SectionId::HiddenShifts(layer))?;
            if multipliers.iter().any(|m| *m < 0) {
                return Err(BlobError::NegativeMultiplier { layer });
            }
            if shifts.iter().any(|s| !(SHIFT_MIN..=SHIFT_MAX).contains(s)) {
                return Err(BlobError::ShiftOutOfRange { layer });
            }
            if !(-128..=127).contains(&desc.output_zero_point)
                || desc.activation_min > desc.activation_max
            {
                return Err(BlobError::Requantization { layer });
            }
            let lut = match desc.lut {
                Some(i) if (i as usize) < num_luts => Some(i as usize),
                Some(_) => return Err(BlobError::LutIndex { layer }),
                None => None,
            };
            *slot = HiddenLayer {
                fc: FullyConnected::new(inputs, outputs, weights, bias),
                requant: FcRequant {
                    multipliers,
                    shifts,
                    output_zero_point: desc.output_zero_point,
                    activation_min: desc.activation_min,
                    activation_max: desc.activation_max,
                },
                lut,
            };
            width = outputs;
        }
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
        if Some(outputs) != K.checked_mul(P) {
            return Err(BlobError::OutputWidth);
        }
        let weights = data.exact::<i8>(
            out.weights,
            outputs.checked_mul(inputs),
            SectionId::OutputWeights,
        )?;
        let bias = data.exact::<i32>(out.bias, Some(outputs), SectionId::OutputBias)?;
        let output_scales = data.finite(out.scales, Some(outputs), SectionId::OutputScales)?;

        let first_width = d
            .hidden
            .first()
            .map_or(outputs, |layer| layer.out_features as usize);
        let first_layer_biases =
            data.cast::<i32>(d.first_layer_biases, SectionId::FirstLayerBiases)?;
        let variants = first_layer_biases
            .len()
            .checked_div(first_width)
            .filter(|_| first_layer_biases.len().is_multiple_of(first_width))
            .ok_or(BlobError::SectionLength(SectionId::FirstLayerBiases))?
            .max(1);
        if shared
            .steps()
            .iter()
            .any(|s| s.first_layer_bias_index as usize >= variants)
        {
            return Err(BlobError::Steps);
        }

        Ok(Self {
            shared,
            layout: d.layout,
            control_dt: d.control_dt,
            input,
            input_precision,
            luts,
            hidden,
            num_hidden: d.hidden.len(),
            output: FullyConnected::new(inputs, outputs, weights, bias),
            output_scales,
            first_layer_biases,
        })
    }

    /// Validates the dimensions, control period, normalization ranges, ProDMP tables and steps
    /// named by `fields` (in that order, so the first failing check names the error) and copies
    /// the tables.
    pub(crate) fn read_shared(
        data: &Data<'a>,
        fields: SharedFields,
    ) -> Result<SharedTables<O, K, N, P>, BlobError> {
        check_dim(fields.history, M, Dimension::History)?;
        check_dim(fields.obs_dim, O, Dimension::ObsDim)?;
        check_dim(fields.action_dim, K, Dimension::ActionDim)?;
        check_dim(fields.horizon, N, Dimension::Horizon)?;
        check_dim(fields.params_per_dof, P, Dimension::ParamsPerDof)?;
        if !(fields.control_dt.is_finite() && fields.control_dt > 0.0) {
            return Err(BlobError::ControlPeriod);
        }
        let obs = data.finite(fields.obs_norm, O.checked_mul(2), SectionId::ObsNorm)?;
        let (obs_min, obs_max) = obs
            .split_at_checked(O)
            .ok_or(BlobError::SectionLength(SectionId::ObsNorm))?;
        let obs_norm = RangeNormalizer::new(to_array(obs_min), to_array(obs_max));
        let action = data.finite(fields.action_norm, K.checked_mul(2), SectionId::ActionNorm)?;
        let (action_min, action_max) = action
            .split_at_checked(K)
            .ok_or(BlobError::SectionLength(SectionId::ActionNorm))?;
        let action_norm = RangeNormalizer::new(to_array(action_min), to_array(action_max));
        if obs_norm.validate().is_err() || action_norm.validate().is_err() {
            return Err(BlobError::Normalization);
        }
        let decoder = Self::read_decoder(data, fields.prodmp)?;
        let (steps, num_steps) = Self::read_steps(data, fields.steps)?;
        Ok(SharedTables {
            obs_norm,
            action_norm,
            decoder,
            steps,
            num_steps,
        })
    }

    pub(crate) fn read_decoder(
        data: &Data<'a>,
        section: Section,
    ) -> Result<BakedProDmp<N, P>, BlobError> {
        let table_len = N.checked_mul(P);
        let count = table_len
            .and_then(|np| np.checked_mul(2))
            .and_then(|v| v.checked_add(N.checked_mul(4)?));
        let values = data.finite(section, count, SectionId::ProDmp)?;
        let mut decoder = BakedProDmp {
            pos_params: [[0.0; P]; N],
            vel_params: [[0.0; P]; N],
            pos_y0: [0.0; N],
            pos_v0: [0.0; N],
            vel_y0: [0.0; N],
            vel_v0: [0.0; N],
        };
        let targets = decoder
            .pos_params
            .iter_mut()
            .flatten()
            .chain(decoder.vel_params.iter_mut().flatten())
            .chain(decoder.pos_y0.iter_mut())
            .chain(decoder.pos_v0.iter_mut())
            .chain(decoder.vel_y0.iter_mut())
            .chain(decoder.vel_v0.iter_mut());
        for (slot, value) in targets.zip(values) {
            *slot = *value;
        }
        Ok(decoder)
    }

    pub(crate) fn read_steps(
        data: &Data<'a>,
        section: Section,
    ) -> Result<([StepConstants; MAX_STEPS], usize), BlobError> {
        let words = data.cast::<u32>(section, SectionId::Steps)?;
        if !words.len().is_multiple_of(STEP_WORDS) {
            return Err(BlobError::SectionLength(SectionId::Steps));
        }
        let count = words.len() / STEP_WORDS;
        if count == 0 || count > MAX_STEPS {
            return Err(BlobError::Steps);
        }
        let mut steps = [StepConstants {
            sigma: 0.0,
            renoise_std: 0.0,
            c_in: 0.0,
            c_skip: 0.0,
            c_out: 0.0,
            first_layer_bias_index: 0,
        }; MAX_STEPS];
        for (step, chunk) in steps.iter_mut().zip(words.chunks_exact(STEP_WORDS)) {
            if let [sigma, renoise, c_in, c_skip, c_out, index] = chunk {
                *step = StepConstants {
                    sigma: f32::from_bits(*sigma),
                    renoise_std: f32::from_bits(*renoise),
                    c_in: f32::from_bits(*c_in),
                    c_skip: f32::from_bits(*c_skip),
                    c_out: f32::from_bits(*c_out),
                    first_layer_bias_index: *index,
                };
            }
        }
        validate_steps(steps.get(..count).unwrap_or(&[])).map_err(|_| BlobError::Steps)?;
        Ok((steps, count))
    }

    /// The step table.
    pub fn steps(&self) -> &[StepConstants] {
        self.shared.steps()
    }

    /// The model input layout.
    pub fn layout(&self) -> &InputLayout {
        &self.layout
    }

    /// The baked ProDMP decoder.
    pub fn decoder(&self) -> &BakedProDmp<N, P> {
        &self.shared.decoder
    }

    /// Control period, seconds.
    pub fn control_dt(&self) -> f32 {
        self.control_dt
    }

    /// The int8 network over the blob's weights, with scratch for layers up to `WIDTH` wide.
    pub fn network<const WIDTH: usize>(&self) -> Result<Int8Network<'_, WIDTH>, PolicyError> {
        let mut layers = [crate::policy::EMPTY_INT8_LAYER; MAX_HIDDEN_LAYERS];
        for (slot, layer) in layers.iter_mut().zip(&self.hidden).take(self.num_hidden) {
            *slot = Int8Layer {
                fc: layer.fc,
                requant: layer.requant,
                activation: layer.lut.and_then(|i| self.luts.get(i)),
            };
        }
        Int8Network::from_parts_with_input(
            self.input,
            self.input_precision,
            layers.get(..self.num_hidden).unwrap_or(&[]),
            self.output,
            self.output_scales,
            self.first_layer_biases,
        )
    }

    /// The policy configuration (normalization, sampler) borrowing this blob.
    pub fn config(&self) -> PolicyConfig<'_, O, K, N, P> {
        self.shared.config(self.layout, self.control_dt)
    }

    /// A ready policy: int8 network with `WIDTH` scratch, input buffer of `I` values.
    #[allow(clippy::type_complexity)]
    pub fn policy<const I: usize, const WIDTH: usize>(
        &self,
    ) -> Result<Policy<'_, Int8Network<'_, WIDTH>, M, O, K, N, P, I>, PolicyError> {
        Policy::new(self.config(), self.network::<WIDTH>()?)
    }
}
