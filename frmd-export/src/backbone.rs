//! What the entry point ([`crate::export`]) and each backbone's exporter ([`crate::mlp`],
//! [`crate::transformer`]) share: the options every exporter takes and the operations on its
//! result, so that nothing above this crate chooses between backbones.
use std::fmt;
use std::path::{Path, PathBuf};

use frmd_core::blob::BlobError;
use frmd_core::model::mlp::InputPrecision;
use frmd_core::policy::{Network, PolicyDims};
use frmd_formats::checkpoint::{BackboneConfig, Normalization};

use crate::calibrate::RangeMethod;
use crate::host::HostScratch;
use crate::memory::MemoryFigures;
use crate::reference::KernelCheck;
use crate::rounding::WeightRounding;

/// Export settings.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ExportOptions {
    /// Sampling steps baked into the step table (1..=4).
    pub steps: usize,
    /// How activation ranges are chosen from the calibration values.
    pub ranges: RangeMethod,
    /// MLP: balance the input segments' ranges with
    /// [`FoldedMlp::with_input_gains`](crate::mlp::FoldedMlp::with_input_gains).
    pub balance_inputs: bool,
    /// MLP: how the first layer takes the input: one 16-bit plane
    /// (`frmd_core::model::mlp::InputPrecision::Int16`, the default: about 16-bit input precision
    /// in one pass), two int8 planes (`TwoPlane`: the same precision in two passes) or one int8
    /// plane (`Int8`). A transformer quantizes each input layer with its own scale.
    pub input_precision: InputPrecision,
    /// MLP, with a 16-bit or two-plane input: the calibrated input range is widened by this
    /// factor (>= 1), so observations beyond the training range (closed-loop states the
    /// demonstrations never visited) reach the network instead of saturating; the fine grid keeps
    /// the resolution (`range / 2^16`). Ignored for plain int8 input.
    pub input_headroom: f32,
    /// The precision of the hidden activations (int8 weights either way); `None`: the best
    /// measured one the backbone has ([`Activations::recipe`]).
    pub activations: Option<Activations>,
    /// With int16 activations (either backbone): every calibrated activation range is widened by
    /// this factor (>= 1) before it becomes a symmetric int16 scale, so closed-loop activations
    /// beyond the calibration states are not clipped. Ignored for int8 activations.
    pub activation_headroom: f32,
    /// How weights are rounded to their int8 codes; `None`: the backbone's default
    /// ([`WeightRounding::recipe`]: GPTQ for the MLP, nearest for transformer-lite, which has
    /// no other).
    pub weight_rounding: Option<WeightRounding>,
}

/// The precision of a network's hidden activations.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Activations {
    /// TFLite's int8 scheme: asymmetric int8 codes, int32 biases, 256-entry tables.
    Int8,
    /// TFLite's 16x8 scheme: symmetric int16 codes, int64 biases, interpolated int16 tables;
    /// the first layer takes the 16-bit input.
    Int16,
}

impl Activations {
    /// The default of a backbone: int16 for the MLP (the int8 export lost up to 17 points of
    /// closed-loop success to its float student, the int16 one within 0.2 on the same episodes,
    /// at 1.03x the Cortex-M4 instructions: docs/design.md section 7), int8 for transformer-lite
    /// (its int16 path is built and exact, but its closed-loop success has not been measured
    /// against int8 yet).
    pub fn recipe(backbone: &BackboneConfig) -> Self {
        match backbone {
            BackboneConfig::Mlp { .. } => Activations::Int16,
            BackboneConfig::Transformer { .. } => Activations::Int8,
        }
    }

    /// `requested`, or the backbone's default ([`Self::recipe`]).
    pub fn resolve(requested: Option<Self>, backbone: &BackboneConfig) -> Self {
        requested.unwrap_or_else(|| Self::recipe(backbone))
    }
}

impl std::str::FromStr for Activations {
    type Err = anyhow::Error;
    fn from_str(text: &str) -> anyhow::Result<Self> {
        match text {
            "int8" => Ok(Activations::Int8),
            "int16" => Ok(Activations::Int16),
            _ => anyhow::bail!("activations `{text}`: expected int8 or int16"),
        }
    }
}

impl fmt::Display for Activations {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(match self {
            Activations::Int8 => "int8",
            Activations::Int16 => "int16",
        })
    }
}

/// Default [`ExportOptions::activation_headroom`]: simulated 16-bit activations of the avoid
/// student scored the same with ranges x1.25, x2 and x3 and lost 10.9 points at x1
/// (docs/experiments.md, "Int8 student").
pub const DEFAULT_ACTIVATION_HEADROOM: f32 = 1.5;

/// Default [`ExportOptions::input_headroom`]: the weaker built-in task policies reach normalized
/// observations of 3-16 in closed loop (training range +-1).
pub const DEFAULT_INPUT_HEADROOM: f32 = 8.0;

impl Default for ExportOptions {
    fn default() -> Self {
        ExportOptions {
            steps: 1,
            ranges: RangeMethod::MinMax,
            balance_inputs: true,
            input_precision: InputPrecision::Int16,
            input_headroom: DEFAULT_INPUT_HEADROOM,
            activations: None,
            activation_headroom: DEFAULT_ACTIVATION_HEADROOM,
            weight_rounding: None,
        }
    }
}

/// A backbone's calibrated, quantized student and what can be done with it.
pub(crate) trait ExportedNetwork {
    /// The policy's sizes.
    fn dims(&self) -> PolicyDims;
    /// Sampling steps in the step table.
    fn steps(&self) -> usize;
    /// Calibration rows the ranges came from.
    fn calibration_rows(&self) -> usize;
    /// The self-describing blob with normalization `norm`.
    fn blob(&self, norm: &Normalization) -> Result<Vec<u8>, BlobError>;
    /// Writes the baked module and `blob` into `dir`; returns the files written.
    fn write_module(&self, blob: &[u8], dir: &Path) -> anyhow::Result<Vec<PathBuf>>;
    /// RAM and flash figures of the baked form.
    fn memory(&self) -> MemoryFigures;
    /// Lines of the export summary beyond the shape and the memory, if any.
    fn details(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result;
    /// The folded student's f32 sampler on frmd-core's f32 path, reporting each step's model
    /// input to `on_input`.
    fn sample_f32(
        &self,
        cond: &[f32],
        noise: &[f32],
        on_input: &mut dyn FnMut(usize, &[f32]),
    ) -> anyhow::Result<Vec<f32>>;
    /// Check (d): the int8 kernels on the exported weights against a wide-integer model,
    /// with `inputs` (step-0 model inputs) where the backbone's check takes inputs.
    fn check_kernels(&self, inputs: &[Vec<f32>]) -> anyhow::Result<KernelCheck>;
    /// Calls `run` with frmd-core's f32 network of the folded student (the int8 network's twin),
    /// running a transformer in `scratch`.
    fn with_f32_network(
        &self,
        scratch: &mut HostScratch,
        run: &mut dyn FnMut(&mut dyn Network) -> anyhow::Result<()>,
    ) -> anyhow::Result<()>;
}
