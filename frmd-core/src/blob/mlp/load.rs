//! The parse side of MLP blobs: [`LoadedMlp`].

use heapless::Vec;

use super::MlpSection;
use super::{
    HiddenLayerDesc, MlpDescriptor, INPUT_INT16, INPUT_INT8, INPUT_TWO_PLANE, LUT_LEN, MLP_MAGIC,
};
use crate::blob::container::{self, Data};
use crate::blob::policy_tables::{self, PolicyTables};
use crate::blob::BlobError;
use crate::kernels::{FcRequant, FullyConnected, LutTable};
use crate::model::linear::{Int8Linear, RequantizedLinear};
use crate::model::mlp::{InputPrecision, Int8Mlp};
use crate::policy::{
    InputLayout, Int8MlpNetwork, Policy, PolicyConfig, PolicyDims, PolicyError, StepConstants,
    MAX_HIDDEN_LAYERS,
};
use crate::quant::{QuantParams, SHIFT_MAX, SHIFT_MIN};

/// A validated MLP blob, borrowed: weights, biases, requantization parameters, tables, scales,
/// normalization and decoder tables stay in the blob (`'a`); the steps are copied. Its
/// [`Self::config`] and [`Self::network`] borrow only the blob, so the policy built from them may
/// outlive the `LoadedMlp`.
///
/// A firmware keeps the blob in flash, 16-aligned, checks it once at boot and runs the policy
/// over it (here: a small sample policy, 2 x 3 observations, 2 DoF, horizon 6):
///
/// ```
/// use frmd_core::blob::{BlobError, LoadedMlp};
/// use frmd_core::policy::{AlignedBytes, Noise, PolicyDims};
/// use frmd_core::rng::Rng;
///
/// macro_rules! sample {
///     () => {
///         include_bytes!(concat!(env!("CARGO_MANIFEST_DIR"), "/tests/data/sample_policy.blob"))
///     };
/// }
/// static BLOB: AlignedBytes<{ sample!().len() }> = AlignedBytes(*sample!());
///
/// // Magic, version, CRC-32, descriptor, every section's bounds, alignment, length and values.
/// let loaded = LoadedMlp::load(&BLOB.0)?;
/// // The sizes this firmware was built for.
/// let expected = PolicyDims { history: 2, obs_dim: 3, action_dim: 2, horizon: 6, params_per_dof: 4 };
/// loaded.check_dims(&expected)?;
/// // Capacities M, O, K, N, P, the model input I and the scratch width of the widest layer.
/// let mut policy = loaded.policy::<2, 3, 2, 6, 4, 32, 40>()?;
/// policy.reset(&[0.0, 0.1])?; // the robot's current position
/// policy.observe(&[0.2, -0.1, 0.4])?; // every control tick
/// policy.act(Noise::Rng(&mut Rng::new(7)))?; // when a new chunk is needed
/// while let Some(action) = policy.next_action() {
///     assert!(action.iter().all(|a| a.is_finite())); // command it
/// }
///
/// // A damaged blob is refused with a named error, never a panic.
/// let mut damaged = BLOB.0;
/// damaged[40] ^= 1;
/// assert!(matches!(LoadedMlp::load(&damaged), Err(BlobError::CrcMismatch { .. })));
/// # Ok::<(), Box<dyn core::error::Error>>(())
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
        let tables = policy_tables::read(data, &d.header, &d.tables)?;
        let input = QuantParams::new(d.input_scale, d.input_zero_point)
            .map_err(|_| BlobError::InputQuantization)?;
        let input_precision = match (d.input_precision, d.hidden.is_empty()) {
            (INPUT_INT8, _) => InputPrecision::Int8,
            (INPUT_TWO_PLANE, false) => InputPrecision::TwoPlane,
            (INPUT_INT16, false) => InputPrecision::Int16,
            _ => return Err(BlobError::InputQuantization),
        };
        d.header
            .layout
            .validate()
            .map_err(|_| BlobError::InputLayout)?;
        let input_width = d
            .header
            .layout
            .width_of(&tables.dims)
            .ok_or(BlobError::InputLayout)?;
        let lut_bytes = data.cast::<i8>(d.luts, MlpSection::Luts.into())?;
        if !lut_bytes.len().is_multiple_of(LUT_LEN) || lut_bytes.len() / LUT_LEN > MAX_HIDDEN_LAYERS
        {
            return Err(BlobError::SectionLength(MlpSection::Luts.into()));
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
        let noise_variants =
            data.cast::<i32>(d.first_layer_biases, MlpSection::FirstLayerBiases.into())?;
        let variants = noise_variants
            .len()
            .checked_div(first_width)
            .filter(|_| noise_variants.len().is_multiple_of(first_width))
            .ok_or(BlobError::SectionLength(
                MlpSection::FirstLayerBiases.into(),
            ))?;
        policy_tables::check_variants(&tables.steps, variants)?;
        Ok(Self {
            tables,
            layout: d.header.layout,
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
        MlpSection::HiddenWeights(layer).into(),
    )?;
    let bias = data.exact::<i32>(
        desc.bias,
        Some(outputs),
        MlpSection::HiddenBias(layer).into(),
    )?;
    let multipliers = data.exact::<i32>(
        desc.multipliers,
        Some(outputs),
        MlpSection::HiddenMultipliers(layer).into(),
    )?;
    let shifts = data.exact::<i32>(
        desc.shifts,
        Some(outputs),
        MlpSection::HiddenShifts(layer).into(),
    )?;
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
        MlpSection::OutputWeights.into(),
    )?;
    let bias = data.exact::<i32>(out.bias, Some(outputs), MlpSection::OutputBias.into())?;
    let output_scales = data.finite(out.scales, Some(outputs), MlpSection::OutputScales.into())?;
    Ok(Int8Linear {
        fc: FullyConnected::new(inputs, outputs, weights, bias),
        output_scales,
    })
}
