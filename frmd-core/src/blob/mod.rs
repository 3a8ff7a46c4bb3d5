//! Self-describing policy blobs (docs/design.md s.5): update a policy without rebuilding firmware.
//!
//! One container ([`container`]: header, CRC, postcard descriptor, aligned sections) holds one
//! format per backbone, each with its emit and parse side in one module: [`mlp`] (magic
//! `b"FRMD"`, [`encode_mlp`], [`LoadedMlp`]) and [`transformer`] (magic `b"FRMT"`,
//! [`encode_transformer`], [`LoadedTransformer`]); both carry the same policy sections
//! (normalization, ProDMP tables, steps). Encoding writes borrowed frmd-core views into a caller
//! buffer (the exporter sizes a `Vec` with the `*_encoded_len` functions). Loading validates a
//! blob in place and is zero-copy for everything but the step table; the loaded configuration
//! and MLP network borrow only the blob, so a policy may outlive the loader. Sizes come from the
//! descriptor at run time; `check_dims` compares them with the sizes a firmware image was built
//! for. Every check failure is a named [`BlobError`]; nothing panics on any input.

#[cfg(any(test, feature = "alloc"))]
mod aligned;
pub mod container;
pub mod crc32;
mod loaded;
pub mod mlp;
mod policy_tables;
pub mod transformer;

#[cfg(test)]
mod tests;

#[cfg(any(test, feature = "alloc"))]
pub use aligned::AlignedBlob;
pub use container::{Section, FORMAT_VERSION, HEADER_LEN, MIN_FORMAT_VERSION, SECTION_ALIGN};
pub use loaded::{BlobNetwork, LoadedBlob};
pub use mlp::{
    activation_bits, encode_mlp, mlp_encoded_len, HiddenLayerDesc, LoadedMlp, LoadedMlp16,
    LoadedQuantMlp, MlpActivations, MlpBlobParts, MlpDescriptor, MlpSection, OutputLayerDesc,
    INPUT_INT16, INPUT_INT8, INPUT_TWO_PLANE, LUT_LEN, MLP_MAGIC,
};
pub use policy_tables::{PolicyHeader, PolicySection, PolicySections, STEP_WORDS};
pub use transformer::{
    encode_transformer, transformer_activation_bits, transformer_encoded_len,
    LoadedQuantTransformer, LoadedTransformer, LoadedTransformer16, TransformerActivations,
    TransformerBlobParts, TransformerDescriptor, TransformerSection, TRANSFORMER_ACTIVATIONS_SINCE,
    TRANSFORMER_MAGIC,
};

use crate::model::transformer::TransformerError;
use crate::policy::PolicyError;

/// Names a section in errors: the format that defines it, with that format's own tag.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum SectionId {
    /// A section every policy blob carries (normalization, decoder tables, steps).
    Policy(PolicySection),
    /// A section of an MLP blob.
    Mlp(MlpSection),
    /// A section of a transformer blob.
    Transformer(TransformerSection),
}

impl From<PolicySection> for SectionId {
    fn from(section: PolicySection) -> Self {
        Self::Policy(section)
    }
}

impl From<MlpSection> for SectionId {
    fn from(section: MlpSection) -> Self {
        Self::Mlp(section)
    }
}

impl From<TransformerSection> for SectionId {
    fn from(section: TransformerSection) -> Self {
        Self::Transformer(section)
    }
}

/// Which size of a blob is zero or differs from the expected one.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum Dimension {
    /// History length `M`.
    History,
    /// Observation dimension `O`.
    ObsDim,
    /// Action dimension `K`.
    ActionDim,
    /// Horizon `N`.
    Horizon,
    /// ProDMP parameters per DoF `P`.
    ParamsPerDof,
}

/// Why a blob was rejected (or could not be written). Small and `Copy`; each variant names the
/// problem and, where it applies, the section or layer.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum BlobError {
    /// The buffer is shorter than the header or than the total length the header states.
    Truncated,
    /// The first four bytes are not the format's magic ([`MLP_MAGIC`], [`TRANSFORMER_MAGIC`]).
    BadMagic,
    /// The format version is outside [`MIN_FORMAT_VERSION`]`..=`[`FORMAT_VERSION`].
    UnsupportedVersion {
        /// Version found in the header.
        found: u16,
    },
    /// The reserved header field is not zero.
    ReservedField,
    /// The stated total length is smaller than the header, or the descriptor does not fit in it.
    InvalidLength,
    /// The payload CRC-32 differs from the header's.
    CrcMismatch {
        /// CRC stored in the header.
        stored: u32,
        /// CRC computed over the payload.
        computed: u32,
    },
    /// The descriptor is not a valid postcard encoding (or has trailing bytes).
    Descriptor,
    /// A blob size differs from the expected one (`check_dims`).
    DimensionMismatch(Dimension),
    /// A blob size is zero.
    ZeroDimension(Dimension),
    /// A section lies (partly) outside the blob.
    SectionBounds(SectionId),
    /// A section's address is not aligned for its element type (the blob must start 4-aligned),
    /// or its offset is not a multiple of [`SECTION_ALIGN`].
    SectionMisaligned(SectionId),
    /// A section's length does not match the shapes in the descriptor.
    SectionLength(SectionId),
    /// A float section contains NaN or infinity.
    NonFinite(SectionId),
    /// A normalization range has `min > max`.
    Normalization,
    /// The input layout is invalid or its width differs from the first layer's input width.
    InputLayout,
    /// The input quantization scale or zero point is invalid.
    InputQuantization,
    /// The step table is invalid (count, values, or a bias variant index out of range).
    Steps,
    /// The control period is not finite and positive.
    ControlPeriod,
    /// Layer `index` (the output layer is `hidden.len()`) does not take the previous width, or a
    /// width is 0.
    LayerWidth {
        /// Offending layer.
        index: u8,
    },
    /// The output layer does not produce `k p` values.
    OutputWidth,
    /// A multiplier is negative in hidden layer `layer`.
    NegativeMultiplier {
        /// Offending layer.
        layer: u8,
    },
    /// A shift is outside `SHIFT_MIN..=SHIFT_MAX` in hidden layer `layer`.
    ShiftOutOfRange {
        /// Offending layer.
        layer: u8,
    },
    /// Output zero point outside `[-128, 127]` or `activation_min > activation_max` in hidden
    /// layer `layer`.
    Requantization {
        /// Offending layer.
        layer: u8,
    },
    /// Hidden layer `layer` refers to an activation table the blob does not have.
    LutIndex {
        /// Offending layer.
        layer: u8,
    },
    /// The blob's activations have `found` bits, not those of the loader it was given (an MLP
    /// blob with int16 activations needs `LoadedMlp::<i16>`, or [`LoadedBlob`] for either).
    ActivationBits {
        /// Bits per activation code the blob states.
        found: u8,
    },
    /// Layer `layer` (the output layer is `hidden.len()`) of an int16-activation blob has a
    /// -128 weight or a bias beyond `quant::BIAS16_MAX`, where its int64 accumulation would not
    /// be exact.
    ExactRange {
        /// Offending layer.
        layer: u8,
    },
    /// The loader runs on a big-endian target (the blob is little endian, read in place).
    BigEndianTarget,
    /// Writing: the output buffer is too small.
    BufferTooSmall,
    /// Writing: the descriptor could not be encoded, or the model has a part the format cannot
    /// hold (an f32 transformer input layer, a feed-forward without its GELU table).
    Encode,
    /// Writing: more layers or blocks than the format holds, or a size beyond u32.
    TooLarge,
    /// Building the network or policy from a loaded blob failed.
    Policy(PolicyError),
    /// A transformer blob's backbone does not validate (shape, or a part's sizes or
    /// quantization parameters, named by part).
    Transformer(TransformerError),
}

impl core::fmt::Display for BlobError {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        match self {
            Self::Truncated => f.write_str("blob is truncated"),
            Self::BadMagic => {
                f.write_str("blob magic is not the expected one (FRMD: MLP, FRMT: transformer)")
            }
            Self::UnsupportedVersion { found } => {
                write!(
                    f,
                    "blob format version {found} is not {MIN_FORMAT_VERSION}..={FORMAT_VERSION}"
                )
            }
            Self::ReservedField => f.write_str("reserved header field is not zero"),
            Self::InvalidLength => f.write_str("blob total or descriptor length is inconsistent"),
            Self::CrcMismatch { stored, computed } => {
                write!(
                    f,
                    "payload CRC {computed:#010x} differs from header {stored:#010x}"
                )
            }
            Self::Descriptor => f.write_str("descriptor is not valid postcard"),
            Self::DimensionMismatch(d) => {
                write!(f, "blob dimension {d:?} differs from the expected one")
            }
            Self::ZeroDimension(d) => write!(f, "blob dimension {d:?} is zero"),
            Self::SectionBounds(s) => write!(f, "section {s:?} lies outside the blob"),
            Self::SectionMisaligned(s) => write!(f, "section {s:?} is misaligned"),
            Self::SectionLength(s) => write!(f, "section {s:?} has the wrong length"),
            Self::NonFinite(s) => write!(f, "section {s:?} contains NaN or infinity"),
            Self::Normalization => f.write_str("normalization range has min > max"),
            Self::InputLayout => f.write_str("input layout invalid or width mismatch"),
            Self::InputQuantization => f.write_str(
                "input quantization parameters invalid (or two-plane without a hidden layer)",
            ),
            Self::Steps => f.write_str("step table invalid"),
            Self::ControlPeriod => f.write_str("control period is not finite and positive"),
            Self::LayerWidth { index } => write!(f, "layer {index} width mismatch"),
            Self::OutputWidth => f.write_str("output layer width is not k * p"),
            Self::NegativeMultiplier { layer } => {
                write!(f, "layer {layer} has a negative multiplier")
            }
            Self::ShiftOutOfRange { layer } => write!(f, "layer {layer} has a shift out of range"),
            Self::Requantization { layer } => {
                write!(f, "layer {layer} has an invalid zero point or clamp range")
            }
            Self::LutIndex { layer } => write!(f, "layer {layer} refers to a missing LUT"),
            Self::ActivationBits { found } => {
                write!(f, "blob has {found}-bit activations, not the loader's")
            }
            Self::ExactRange { layer } => write!(
                f,
                "layer {layer} has a -128 weight or a bias beyond 2^46 (int16 activations)"
            ),
            Self::BigEndianTarget => {
                f.write_str("blobs are read in place on little-endian targets only")
            }
            Self::BufferTooSmall => f.write_str("output buffer too small for the blob"),
            Self::Encode => f.write_str("descriptor encoding failed"),
            Self::TooLarge => f.write_str("blob too large (layers or sizes)"),
            Self::Policy(_) => f.write_str("the blob's policy does not validate"),
            Self::Transformer(_) => f.write_str("the blob's transformer does not validate"),
        }
    }
}

impl core::error::Error for BlobError {
    fn source(&self) -> Option<&(dyn core::error::Error + 'static)> {
        match self {
            Self::Policy(error) => Some(error),
            Self::Transformer(error) => Some(error),
            _ => None,
        }
    }
}

impl From<PolicyError> for BlobError {
    fn from(error: PolicyError) -> Self {
        Self::Policy(error)
    }
}
