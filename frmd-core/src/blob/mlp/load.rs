//! The parse side of MLP blobs: [`LoadedMlp`].

use heapless::Vec;

use super::MlpSection;
use super::{
    HiddenLayerDesc, MlpActivations, MlpDescriptor, ACTIVATIONS_SINCE, INPUT_INT16, INPUT_INT8,
    INPUT_TWO_PLANE, MLP_MAGIC,
};
use crate::blob::container::{self, Data};
use crate::blob::policy_tables::{self, PolicyTables};
use crate::blob::BlobError;
use crate::kernels::{Accumulator, FcRequant, FullyConnected};
use crate::model::linear::{Int8Linear, RequantizedLinear};
use crate::model::mlp::{InputPrecision, MlpPrecision, QuantMlp};
use crate::policy::{
    InputLayout, Policy, PolicyConfig, PolicyDims, PolicyError, QuantMlpNetwork, StepConstants,
    MAX_HIDDEN_LAYERS,
};
use crate::quant::QuantParams;

/// A validated MLP blob, borrowed: weights, biases, requantization parameters, tables, scales,
/// normalization and decoder tables stay in the blob (`'a`); the steps are copied. Its
/// [`Self::config`] and [`Self::network`] borrow only the blob, so the policy built from them may
/// outlive the `LoadedQuantMlp`. `A` is the activation precision the loader takes: int8
/// ([`LoadedMlp`]) or int16 ([`LoadedMlp16`]); a blob of the other precision is refused with
/// [`BlobError::ActivationBits`] ([`crate::blob::LoadedBlob`] takes either).
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
pub struct LoadedQuantMlp<'a, A: MlpPrecision> {
    tables: PolicyTables<'a>,
    layout: InputLayout,
    input: QuantParams,
    input_precision: InputPrecision,
    hidden: Vec<RequantizedLinear<'a, A>, MAX_HIDDEN_LAYERS>,
    output: Int8Linear<'a, A::Acc>,
    noise_variants: &'a [A::Acc],
}

/// The loader of int8-activation MLP blobs.
pub type LoadedMlp<'a> = LoadedQuantMlp<'a, i8>;
/// The loader of int16-activation MLP blobs (the blob must start 8-byte aligned: its biases are
/// i64, read in place).
pub type LoadedMlp16<'a> = LoadedQuantMlp<'a, i16>;

/// Bits per activation of an MLP blob: its trailer's, or 8 for a blob older than format 4.
pub fn activation_bits(bytes: &[u8]) -> Result<u8, BlobError> {
    let (_, trailer, _) = container::parse_versioned::<MlpDescriptor, MlpActivations>(
        bytes,
        MLP_MAGIC,
        false,
        ACTIVATIONS_SINCE,
    )?;
    Ok(trailer.map_or(8, |t| t.bits))
}

impl<'a, A: MlpPrecision + TryFrom<i16>> LoadedQuantMlp<'a, A> {
    /// Validates `bytes` (header, CRC, descriptor, sections, shapes, values) and borrows it.
    /// Bytes after the stated total length are ignored (e.g. flash padding). The buffer must start
    /// at a 4-byte aligned address.
    pub fn load(bytes: &'a [u8]) -> Result<Self, BlobError> {
        Self::parse(bytes, true)
    }

    /// [`Self::load`] without recomputing the CRC, for bytes that passed [`Self::load`] before
    /// (a host keeping a blob and viewing it again); every other check runs.
    pub fn reload(bytes: &'a [u8]) -> Result<Self, BlobError> {
        Self::parse(bytes, false)
    }

    fn parse(bytes: &'a [u8], check_crc: bool) -> Result<Self, BlobError> {
        let (descriptor, trailer, data) = container::parse_versioned::<
            MlpDescriptor,
            MlpActivations,
        >(bytes, MLP_MAGIC, check_crc, ACTIVATIONS_SINCE)?;
        let bits = trailer.as_ref().map_or(8, |t| t.bits);
        if bits != A::BITS {
            return Err(BlobError::ActivationBits { found: bits });
        }
        Self::view(&descriptor, trailer.as_ref(), &data)
    }

    fn view(
        d: &MlpDescriptor,
        trailer: Option<&MlpActivations>,
        data: &Data<'a>,
    ) -> Result<Self, BlobError> {
        let tables = policy_tables::read(data, &d.header, &d.tables)?;
        let input = QuantParams::new(d.input_scale, d.input_zero_point)
            .map_err(|_| BlobError::InputQuantization)?;
        let input_precision = match (d.input_precision, d.hidden.is_empty()) {
            (INPUT_INT8, _) => InputPrecision::Int8,
            (INPUT_TWO_PLANE, false) => InputPrecision::TwoPlane,
            (INPUT_INT16, false) => InputPrecision::Int16,
            _ => return Err(BlobError::InputQuantization),
        };
        if !A::accepts(input_precision) {
            return Err(BlobError::InputQuantization);
        }
        // From format 4 the trailer holds the clamps; the layer fields must be their int8
        // saturations (one value per clamp, however it is read).
        if let Some(t) = trailer {
            let agree = t.clamps.len() == d.hidden.len()
                && t.clamps.iter().zip(&d.hidden).all(|(clamp, desc)| {
                    clamp.map(super::saturate_i8) == [desc.activation_min, desc.activation_max]
                });
            if !agree {
                return Err(BlobError::Descriptor);
            }
        }
        d.header
            .layout
            .validate()
            .map_err(|_| BlobError::InputLayout)?;
        let input_width = d
            .header
            .layout
            .width_of(&tables.dims)
            .ok_or(BlobError::InputLayout)?;
        let lut_entries = data.cast::<A>(d.luts, MlpSection::Luts.into())?;
        let table_len = A::TABLE_LEN;
        if !lut_entries.len().is_multiple_of(table_len)
            || lut_entries.len() / table_len > MAX_HIDDEN_LAYERS
        {
            return Err(BlobError::SectionLength(MlpSection::Luts.into()));
        }
        let luts = lut_entries.chunks_exact(table_len);
        let mut hidden = Vec::new();
        let mut width = input_width;
        for (index, desc) in d.hidden.iter().enumerate() {
            let clamp = match trailer {
                Some(t) => t.clamps.get(index).copied().unwrap_or_default(),
                None => [desc.activation_min, desc.activation_max].map(i16::from),
            };
            let layer = read_hidden(data, desc, clamp, index, width, luts.clone())?;
            width = layer.fc.out_features;
            hidden.push(layer).map_err(|_| BlobError::TooLarge)?;
        }
        let output = read_output(data, d, width, &tables.dims)?;
        let first_width = hidden
            .first()
            .map_or(output.fc.out_features, |layer| layer.fc.out_features);
        let noise_variants =
            data.cast::<A::Acc>(d.first_layer_biases, MlpSection::FirstLayerBiases.into())?;
        if noise_variants.iter().any(|b| !b.bias_valid()) {
            return Err(BlobError::ExactRange { layer: 0 });
        }
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

    /// The quantized MLP over the blob's weights (its own first-layer bias: variant 0), with its
    /// hidden layers in `hidden` (from [`Self::hidden_layers`]).
    pub fn mlp<'b>(&self, hidden: &'b [RequantizedLinear<'a, A>]) -> QuantMlp<'b, A>
    where
        'a: 'b,
    {
        QuantMlp {
            input: self.input,
            hidden,
            output: self.output,
        }
    }

    /// The hidden layers.
    pub fn hidden_layers(&self) -> &[RequantizedLinear<'a, A>] {
        &self.hidden
    }

    /// The first-layer bias variants, back to back.
    pub fn noise_variants(&self) -> &'a [A::Acc] {
        self.noise_variants
    }

    /// The network over the blob's weights, with scratch for layers up to `WIDTH` wide.
    pub fn network<const WIDTH: usize>(
        &self,
    ) -> Result<QuantMlpNetwork<'a, A, WIDTH>, PolicyError> {
        QuantMlpNetwork::new(
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
    ) -> Result<Policy<'a, QuantMlpNetwork<'a, A, WIDTH>, M, O, K, N, P, I>, PolicyError> {
        Policy::new(self.config(), self.network::<WIDTH>()?)
    }
}

fn read_hidden<'a, P: MlpPrecision + TryFrom<i16>>(
    data: &Data<'a>,
    desc: &HiddenLayerDesc,
    clamp: [i16; 2],
    index: usize,
    width: usize,
    mut luts: impl Iterator<Item = &'a [P]>,
) -> Result<RequantizedLinear<'a, P>, BlobError> {
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
    let bias = data.exact::<P::Acc>(
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
    if shifts
        .iter()
        .any(|s| !(P::SHIFT_MIN..=P::SHIFT_MAX).contains(s))
    {
        return Err(BlobError::ShiftOutOfRange { layer });
    }
    let [min, max] = clamp.map(|c| P::try_from(c).ok());
    let (Some(activation_min), Some(activation_max)) = (min, max) else {
        return Err(BlobError::Requantization { layer });
    };
    if !P::zero_point_valid(desc.output_zero_point) || activation_min > activation_max {
        return Err(BlobError::Requantization { layer });
    }
    let activation = match desc.lut {
        Some(i) => Some(
            luts.nth(i as usize)
                .and_then(P::table)
                .ok_or(BlobError::LutIndex { layer })?,
        ),
        None => None,
    };
    let fc = FullyConnected::new(inputs, outputs, weights, bias);
    fc.validate_exact()
        .map_err(|_| BlobError::ExactRange { layer })?;
    Ok(RequantizedLinear {
        fc,
        requant: FcRequant {
            multipliers,
            shifts,
            output_zero_point: desc.output_zero_point,
            activation_min,
            activation_max,
        },
        activation,
    })
}

fn read_output<'a, A: Accumulator>(
    data: &Data<'a>,
    d: &MlpDescriptor,
    width: usize,
    dims: &PolicyDims,
) -> Result<Int8Linear<'a, A>, BlobError> {
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
    let bias = data.exact::<A>(out.bias, Some(outputs), MlpSection::OutputBias.into())?;
    let output_scales = data.finite(out.scales, Some(outputs), MlpSection::OutputScales.into())?;
    let fc = FullyConnected::new(inputs, outputs, weights, bias);
    fc.validate_exact().map_err(|_| BlobError::ExactRange {
        layer: d.hidden.len() as u8,
    })?;
    Ok(Int8Linear { fc, output_scales })
}
