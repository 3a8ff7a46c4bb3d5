//! Blob writer: borrowed parts in, bytes out (no allocation; the exporter sizes a `Vec` with
//! [`encoded_len`]). The writer checks every part's length against the stated shapes, so it never
//! writes a blob whose sections disagree with its descriptor; value checks (finite floats, shift
//! ranges, ...) are the loader's, which the exporter's tests run on every written blob.

use heapless::Vec;

use super::crc32::crc32;
use super::format::{
    align_up, Descriptor, HiddenLayerDesc, OutputLayerDesc, Section, SectionId, FORMAT_VERSION,
    HEADER_LEN, INPUT_INT16, INPUT_INT8, INPUT_TWO_PLANE, LUT_LEN, MAGIC, SECTION_ALIGN,
    STEP_WORDS,
};
use super::BlobError;
use crate::model::mlp::InputPrecision;
use crate::policy::{InputLayout, StepConstants};
use crate::quant::QuantParams;

/// ProDMP decoder tables, row-major (`[N][P]` and `[N]`), as in
/// [`crate::prodmp::BakedProDmp`].
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ProDmpTables<'p> {
    /// `[N][P]` position coefficients.
    pub pos_params: &'p [f32],
    /// `[N][P]` velocity coefficients.
    pub vel_params: &'p [f32],
    /// `[N]` position coefficient of `y0`.
    pub pos_y0: &'p [f32],
    /// `[N]` position coefficient of `v0`.
    pub pos_v0: &'p [f32],
    /// `[N]` velocity coefficient of `y0`.
    pub vel_y0: &'p [f32],
    /// `[N]` velocity coefficient of `v0`.
    pub vel_v0: &'p [f32],
}

/// One hidden layer to write.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct HiddenLayerParts<'p> {
    /// Input width.
    pub in_features: usize,
    /// Output width.
    pub out_features: usize,
    /// `[out, in]` int8 weights.
    pub weights: &'p [i8],
    /// `[out]` int32 bias (input zero point folded).
    pub bias: &'p [i32],
    /// `[out]` Q31 multipliers.
    pub multipliers: &'p [i32],
    /// `[out]` shifts.
    pub shifts: &'p [i32],
    /// Output zero point.
    pub output_zero_point: i32,
    /// Lower output clamp.
    pub activation_min: i8,
    /// Upper output clamp.
    pub activation_max: i8,
    /// LUT index, if any.
    pub lut: Option<usize>,
}

/// The output layer to write.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct OutputLayerParts<'p> {
    /// Input width.
    pub in_features: usize,
    /// Output width (`K * P`).
    pub out_features: usize,
    /// `[out, in]` int8 weights.
    pub weights: &'p [i8],
    /// `[out]` int32 bias.
    pub bias: &'p [i32],
    /// `[out]` dequantization scales.
    pub scales: &'p [f32],
}

/// Everything a blob holds, borrowed.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct BlobParts<'p> {
    /// History length `M`.
    pub history: usize,
    /// Observation dimension `O`.
    pub obs_dim: usize,
    /// Action dimension `K`.
    pub action_dim: usize,
    /// Horizon `N`.
    pub horizon: usize,
    /// ProDMP parameters per DoF `P`.
    pub params_per_dof: usize,
    /// Control period, seconds.
    pub control_dt: f32,
    /// Model input layout.
    pub layout: InputLayout,
    /// Quantization of the f32 input vector.
    pub input: QuantParams,
    /// How the first layer quantizes the input (its multipliers must match).
    pub input_precision: InputPrecision,
    /// `[O]` observation minimum.
    pub obs_min: &'p [f32],
    /// `[O]` observation maximum.
    pub obs_max: &'p [f32],
    /// `[K]` action minimum.
    pub action_min: &'p [f32],
    /// `[K]` action maximum.
    pub action_max: &'p [f32],
    /// ProDMP tables.
    pub prodmp: ProDmpTables<'p>,
    /// Step constants (1..=4).
    pub steps: &'p [StepConstants],
    /// First-layer bias variants back to back (may be empty).
    pub first_layer_biases: &'p [i32],
    /// Activation LUTs.
    pub luts: &'p [[i8; LUT_LEN]],
    /// Hidden layers.
    pub hidden: &'p [HiddenLayerParts<'p>],
    /// Output layer.
    pub output: OutputLayerParts<'p>,
}

/// Assigns aligned, consecutive data-area ranges.
struct Planner {
    cursor: usize,
}

impl Planner {
    fn place(&mut self, count: usize, size: usize) -> Result<Section, BlobError> {
        let len = count.checked_mul(size).ok_or(BlobError::TooLarge)?;
        let offset = self.cursor;
        let end = offset.checked_add(len).ok_or(BlobError::TooLarge)?;
        self.cursor = align_up(end, SECTION_ALIGN).ok_or(BlobError::TooLarge)?;
        Ok(Section {
            offset: u32::try_from(offset).map_err(|_| BlobError::TooLarge)?,
            len: u32::try_from(len).map_err(|_| BlobError::TooLarge)?,
        })
    }
}

fn expect_len(actual: usize, expected: Option<usize>, id: SectionId) -> Result<(), BlobError> {
    if Some(actual) == expected {
        Ok(())
    } else {
        Err(BlobError::SectionLength(id))
    }
}

fn small(value: usize) -> Result<u32, BlobError> {
    u32::try_from(value).map_err(|_| BlobError::TooLarge)
}

/// Checks part lengths and builds the descriptor; returns it with the data-area length.
fn plan(parts: &BlobParts<'_>) -> Result<(Descriptor, usize), BlobError> {
    let (o, k, n, p) = (
        parts.obs_dim,
        parts.action_dim,
        parts.horizon,
        parts.params_per_dof,
    );
    expect_len(parts.obs_min.len(), Some(o), SectionId::ObsNorm)?;
    expect_len(parts.obs_max.len(), Some(o), SectionId::ObsNorm)?;
    expect_len(parts.action_min.len(), Some(k), SectionId::ActionNorm)?;
    expect_len(parts.action_max.len(), Some(k), SectionId::ActionNorm)?;
    let tables = &parts.prodmp;
    expect_len(tables.pos_params.len(), n.checked_mul(p), SectionId::ProDmp)?;
    expect_len(tables.vel_params.len(), n.checked_mul(p), SectionId::ProDmp)?;
    for column in [tables.pos_y0, tables.pos_v0, tables.vel_y0, tables.vel_v0] {
        expect_len(column.len(), Some(n), SectionId::ProDmp)?;
    }
    let mut planner = Planner { cursor: 0 };
    let obs_norm = planner.place(2 * o, 4)?;
    let action_norm = planner.place(2 * k, 4)?;
    let prodmp_count = n
        .checked_mul(p)
        .and_then(|np| np.checked_mul(2))
        .and_then(|v| v.checked_add(4 * n))
        .ok_or(BlobError::TooLarge)?;
    let prodmp = planner.place(prodmp_count, 4)?;
    let steps = planner.place(parts.steps.len(), 4 * STEP_WORDS)?;
    let first_layer_biases = planner.place(parts.first_layer_biases.len(), 4)?;
    let luts = planner.place(parts.luts.len(), LUT_LEN)?;
    let mut hidden = Vec::new();
    for (index, layer) in parts.hidden.iter().enumerate() {
        let id = u8::try_from(index).map_err(|_| BlobError::TooLarge)?;
        let out = layer.out_features;
        let weight_count = out.checked_mul(layer.in_features);
        expect_len(
            layer.weights.len(),
            weight_count,
            SectionId::HiddenWeights(id),
        )?;
        expect_len(layer.bias.len(), Some(out), SectionId::HiddenBias(id))?;
        expect_len(
            layer.multipliers.len(),
            Some(out),
            SectionId::HiddenMultipliers(id),
        )?;
        expect_len(layer.shifts.len(), Some(out), SectionId::HiddenShifts(id))?;
        let desc = HiddenLayerDesc {
            in_features: small(layer.in_features)?,
            out_features: small(out)?,
            weights: planner.place(layer.weights.len(), 1)?,
            bias: planner.place(out, 4)?,
            multipliers: planner.place(out, 4)?,
            shifts: planner.place(out, 4)?,
            output_zero_point: layer.output_zero_point,
            activation_min: layer.activation_min,
            activation_max: layer.activation_max,
            lut: layer.lut.map(small).transpose()?,
        };
        hidden.push(desc).map_err(|_| BlobError::TooLarge)?;
    }
    let out_layer = &parts.output;
    let out = out_layer.out_features;
    let weight_count = out.checked_mul(out_layer.in_features);
    expect_len(
        out_layer.weights.len(),
        weight_count,
        SectionId::OutputWeights,
    )?;
    expect_len(out_layer.bias.len(), Some(out), SectionId::OutputBias)?;
    expect_len(out_layer.scales.len(), Some(out), SectionId::OutputScales)?;
    let output = OutputLayerDesc {
        in_features: small(out_layer.in_features)?,
        out_features: small(out)?,
        weights: planner.place(out_layer.weights.len(), 1)?,
        bias: planner.place(out, 4)?,
        scales: planner.place(out, 4)?,
    };
    let descriptor = Descriptor {
        history: small(parts.history)?,
        obs_dim: small(o)?,
        action_dim: small(k)?,
        horizon: small(n)?,
        params_per_dof: small(p)?,
        control_dt: parts.control_dt,
        layout: parts.layout,
        input_scale: parts.input.scale,
        input_zero_point: parts.input.zero_point,
        input_precision: match parts.input_precision {
            InputPrecision::Int8 => INPUT_INT8,
            InputPrecision::TwoPlane => INPUT_TWO_PLANE,
            InputPrecision::Int16 => INPUT_INT16,
        },
        obs_norm,
        action_norm,
        prodmp,
        steps,
        first_layer_biases,
        luts,
        hidden,
        output,
    };
    Ok((descriptor, planner.cursor))
}

/// Byte offset of the data area for a descriptor of `descriptor_len` bytes.
pub(crate) fn data_start(descriptor_len: usize) -> Option<usize> {
    align_up(HEADER_LEN.checked_add(descriptor_len)?, SECTION_ALIGN)
}

fn descriptor_len(descriptor: &Descriptor) -> Result<usize, BlobError> {
    postcard::serialize_with_flavor(descriptor, postcard::ser_flavors::Size::default())
        .map_err(|_| BlobError::Encode)
}

/// Exact length of the blob [`encode`] writes for `parts`.
pub fn encoded_len(parts: &BlobParts<'_>) -> Result<usize, BlobError> {
    let (descriptor, data_len) = plan(parts)?;
    data_start(descriptor_len(&descriptor)?)
        .and_then(|start| start.checked_add(data_len))
        .ok_or(BlobError::TooLarge)
}

/// Writes the little-endian bytes of `values` at `section` of the data area.
fn put<const B: usize, T: Copy>(
    data: &mut [u8],
    section: Section,
    values: impl IntoIterator<Item = T>,
    to_bytes: impl Fn(T) -> [u8; B],
) -> Result<(), BlobError> {
    let start = section.offset as usize;
    let end = start
        .checked_add(section.len as usize)
        .ok_or(BlobError::TooLarge)?;
    let target = data.get_mut(start..end).ok_or(BlobError::BufferTooSmall)?;
    for (chunk, value) in target.chunks_exact_mut(B).zip(values) {
        chunk.copy_from_slice(&to_bytes(value));
    }
    Ok(())
}

fn step_words(step: &StepConstants) -> [u32; STEP_WORDS] {
    [
        step.sigma.to_bits(),
        step.renoise_std.to_bits(),
        step.c_in.to_bits(),
        step.c_skip.to_bits(),
        step.c_out.to_bits(),
        step.first_layer_bias_index,
    ]
}

/// Writes the blob for `parts` into the front of `out` and returns its length
/// ([`encoded_len`]); the rest of `out` is untouched.
pub fn encode(parts: &BlobParts<'_>, out: &mut [u8]) -> Result<usize, BlobError> {
    let (d, data_len) = plan(parts)?;
    let desc_len = descriptor_len(&d)?;
    let start = data_start(desc_len).ok_or(BlobError::TooLarge)?;
    let total = start.checked_add(data_len).ok_or(BlobError::TooLarge)?;
    let blob = out.get_mut(..total).ok_or(BlobError::BufferTooSmall)?;
    blob.fill(0);
    let desc_area = blob
        .get_mut(HEADER_LEN..HEADER_LEN + desc_len)
        .ok_or(BlobError::BufferTooSmall)?;
    postcard::to_slice(&d, desc_area).map_err(|_| BlobError::Encode)?;
    let data = blob.get_mut(start..).ok_or(BlobError::BufferTooSmall)?;
    let f32_bytes = |v: f32| v.to_le_bytes();
    let i32_bytes = |v: i32| v.to_le_bytes();
    let i8_bytes = |v: i8| v.to_le_bytes();
    let obs = parts.obs_min.iter().chain(parts.obs_max).copied();
    put(data, d.obs_norm, obs, f32_bytes)?;
    let action = parts.action_min.iter().chain(parts.action_max).copied();
    put(data, d.action_norm, action, f32_bytes)?;
    let t = &parts.prodmp;
    let tables = t
        .pos_params
        .iter()
        .chain(t.vel_params)
        .chain(t.pos_y0)
        .chain(t.pos_v0)
        .chain(t.vel_y0)
        .chain(t.vel_v0)
        .copied();
    put(data, d.prodmp, tables, f32_bytes)?;
    let words = parts.steps.iter().flat_map(step_words);
    put(data, d.steps, words, |w: u32| w.to_le_bytes())?;
    let biases = parts.first_layer_biases.iter().copied();
    put(data, d.first_layer_biases, biases, i32_bytes)?;
    put(data, d.luts, parts.luts.iter().flatten().copied(), i8_bytes)?;
    for (layer, desc) in parts.hidden.iter().zip(&d.hidden) {
        put(data, desc.weights, layer.weights.iter().copied(), i8_bytes)?;
        put(data, desc.bias, layer.bias.iter().copied(), i32_bytes)?;
        put(
            data,
            desc.multipliers,
            layer.multipliers.iter().copied(),
            i32_bytes,
        )?;
        put(data, desc.shifts, layer.shifts.iter().copied(), i32_bytes)?;
    }
    let o = &parts.output;
    put(data, d.output.weights, o.weights.iter().copied(), i8_bytes)?;
    put(data, d.output.bias, o.bias.iter().copied(), i32_bytes)?;
    put(data, d.output.scales, o.scales.iter().copied(), f32_bytes)?;
    seal(blob, MAGIC, desc_len)?;
    Ok(total)
}

/// Fills the header of `blob` (the whole blob, descriptor and data already in place): `magic`,
/// [`FORMAT_VERSION`], reserved 0, total length `blob.len()`, the payload CRC-32 and the
/// descriptor length.
pub(crate) fn seal(blob: &mut [u8], magic: [u8; 4], desc_len: usize) -> Result<(), BlobError> {
    let crc = crc32(blob.get(HEADER_LEN..).ok_or(BlobError::BufferTooSmall)?);
    let total_u32 = u32::try_from(blob.len()).map_err(|_| BlobError::TooLarge)?;
    let desc_u32 = u32::try_from(desc_len).map_err(|_| BlobError::TooLarge)?;
    let header = blob
        .get_mut(..HEADER_LEN)
        .ok_or(BlobError::BufferTooSmall)?;
    let mut fields = [0_u8; HEADER_LEN];
    for (slot, byte) in fields.iter_mut().zip(
        magic
            .iter()
            .chain(&FORMAT_VERSION.to_le_bytes())
            .chain(&0_u16.to_le_bytes())
            .chain(&total_u32.to_le_bytes())
            .chain(&crc.to_le_bytes())
            .chain(&desc_u32.to_le_bytes()),
    ) {
        *slot = *byte;
    }
    header.copy_from_slice(&fields);
    Ok(())
}
