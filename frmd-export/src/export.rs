//! The one entry point: [`export`] (or [`export_checkpoint`] for a checkpoint already read) takes
//! a student checkpoint through the exporter of its backbone and checks the blob with frmd-core's
//! loader; the [`ExportedStudent`] it returns offers the blob, the baked module, the memory report
//! and the checks of the bit-accuracy harness for every backbone alike.
use std::fmt;
use std::path::{Path, PathBuf};

use anyhow::Context;
use frmd_core::policy::{Network, PolicyDims};
use frmd_formats::calibration::{self, CalibrationSet};
use frmd_formats::checkpoint::{
    BackboneConfig, Checkpoint, CheckpointMeta, Normalization, CALIBRATION_FILE,
};

use crate::backbone::{Activations, ExportOptions, ExportedNetwork};
use crate::fold::check_student;
use crate::host::HostScratch;
use crate::memory::MemoryFigures;
use crate::mlp::{MlpExport, MlpExports};
use crate::reference::KernelCheck;
use crate::rounding::WeightRounding;
use crate::transformer::{TransformerExport, TransformerExports};

/// A student checkpoint exported by the exporter of its backbone, its blob checked.
#[derive(Clone, Debug)]
pub struct ExportedStudent {
    meta: CheckpointMeta,
    options: ExportOptions,
    calibration: CalibrationSet,
    network: Backbone,
    blob: Vec<u8>,
}

/// The exporter's result for each backbone.
#[derive(Clone, Debug)]
enum Backbone {
    Mlp(MlpExports),
    Transformer(TransformerExports),
}

impl Backbone {
    fn get(&self) -> &dyn ExportedNetwork {
        match self {
            Backbone::Mlp(mlp) => mlp.get(),
            Backbone::Transformer(transformer) => transformer.get(),
        }
    }
}

/// Reads the student checkpoint in `dir` once and exports it: see [`export_checkpoint`].
pub fn export(
    dir: &Path,
    options: &ExportOptions,
    calibration: Option<CalibrationSet>,
) -> anyhow::Result<ExportedStudent> {
    export_checkpoint(Checkpoint::read(dir)?, options, calibration)
}

/// Exports `checkpoint` with the exporter of its backbone: folds it for `options.steps` sampling
/// steps, calibrates on `calibration` (or the checkpoint's own `calibration.safetensors` when
/// `None`), quantizes, encodes the blob and loads it back with frmd-core's loader (the
/// firmware's) into a host policy: an export the runtime would refuse is an error here, not a
/// file.
pub fn export_checkpoint(
    checkpoint: Checkpoint,
    options: &ExportOptions,
    calibration: Option<CalibrationSet>,
) -> anyhow::Result<ExportedStudent> {
    let dir = checkpoint.dir.display().to_string();
    let meta = &checkpoint.meta;
    check_student(meta).with_context(|| format!("cannot export {dir}"))?;
    let calibration = match calibration {
        Some(set) => set,
        None => calibration::read(
            &checkpoint.dir.join(CALIBRATION_FILE),
            meta.model.cond_dim(),
        )
        .with_context(|| format!("{dir}: no calibration rows given and its {CALIBRATION_FILE} is unusable (calibrate on the training demonstrations, `frmd export --data`)"))?,
    };
    let norm = meta
        .normalization
        .clone()
        .with_context(|| format!("{dir}: checkpoint has no normalization"))?;
    let activations = Activations::resolve(options.activations, &meta.model.backbone);
    let rounding = WeightRounding::resolve(options.weight_rounding, &meta.model.backbone);
    let options = &ExportOptions {
        weight_rounding: Some(rounding),
        ..*options
    };
    let network = match meta.model.backbone {
        BackboneConfig::Mlp { .. } => {
            crate::mlp::export(&checkpoint, options, activations, &calibration, &norm)
                .map(Backbone::Mlp)
        }
        BackboneConfig::Transformer { .. } => {
            crate::transformer::export(&checkpoint, options, activations, &calibration)
                .map(Backbone::Transformer)
        }
    }
    .with_context(|| format!("cannot export {dir}"))?;
    let blob = network
        .get()
        .blob(&norm)
        .with_context(|| format!("{dir}: encoding the blob"))?;
    crate::host::check_blob(&blob).with_context(|| {
        format!("{dir}: the exported blob does not load with the runtime's loader")
    })?;
    Ok(ExportedStudent {
        meta: checkpoint.meta,
        options: *options,
        calibration,
        network,
        blob,
    })
}

impl ExportedStudent {
    /// The checkpoint's `frmd.json`.
    pub fn meta(&self) -> &CheckpointMeta {
        &self.meta
    }

    /// The settings it was exported with.
    pub fn options(&self) -> &ExportOptions {
        &self.options
    }

    /// How its weights were rounded (the options' or the backbone's default).
    pub fn weight_rounding(&self) -> WeightRounding {
        self.options
            .weight_rounding
            .unwrap_or_else(|| WeightRounding::recipe(&self.meta.model.backbone))
    }

    /// The precision of its hidden activations (the options' or the backbone's default).
    pub fn activations(&self) -> Activations {
        match &self.network {
            Backbone::Mlp(MlpExports::Int16(_))
            | Backbone::Transformer(TransformerExports::Int16(_)) => Activations::Int16,
            _ => Activations::Int8,
        }
    }

    /// The rows it was calibrated on.
    pub fn calibration(&self) -> &CalibrationSet {
        &self.calibration
    }

    /// The checkpoint's normalization (an exported student always has one).
    pub fn normalization(&self) -> Option<&Normalization> {
        self.meta.normalization.as_ref()
    }

    /// The self-describing blob (`policy.blob`), checked with frmd-core's loader.
    pub fn blob(&self) -> &[u8] {
        &self.blob
    }

    /// The policy's sizes.
    pub fn dims(&self) -> PolicyDims {
        self.network.get().dims()
    }

    /// Sampling steps baked into the step table.
    pub fn steps(&self) -> usize {
        self.network.get().steps()
    }

    /// RAM and flash figures of the baked form.
    pub fn memory(&self) -> MemoryFigures {
        self.network.get().memory()
    }

    /// Writes the baked module (see [`crate::bake`]) and the blob into `dir`; returns the files
    /// written.
    pub fn write_module(&self, dir: &Path) -> anyhow::Result<Vec<PathBuf>> {
        self.network.get().write_module(&self.blob, dir)
    }

    /// The folded student's sampler on frmd-core's f32 path (check (a) of docs/design.md
    /// section 6): the chunk positions (normalized, `[n][k]`) for condition `cond` and
    /// standard-normal `noise` (`steps * n * k` values), reporting each step's model input to
    /// `on_input(step, input)`.
    pub fn sample_f32(
        &self,
        cond: &[f32],
        noise: &[f32],
        mut on_input: impl FnMut(usize, &[f32]),
    ) -> anyhow::Result<Vec<f32>> {
        self.network.get().sample_f32(cond, noise, &mut on_input)
    }

    /// Check (d): the int8 kernels on the exported weights against a wide-integer model (an
    /// MLP's whole network on `inputs`, step-0 model inputs, plus edge inputs; a transformer's
    /// every linear layer on random and edge rows). The check's name says which.
    pub fn check_kernels(&self, inputs: &[Vec<f32>]) -> anyhow::Result<KernelCheck> {
        self.network.get().check_kernels(inputs)
    }

    /// Calls `run` with frmd-core's f32 network of the folded student, the int8 network's twin
    /// (a transformer runs in `scratch`): the runtime's policy over it isolates quantization from
    /// everything else.
    pub fn with_f32_network<R>(
        &self,
        scratch: &mut HostScratch,
        run: impl FnOnce(&mut dyn Network) -> anyhow::Result<R>,
    ) -> anyhow::Result<R> {
        let mut run = Some(run);
        let mut result = None;
        self.network
            .get()
            .with_f32_network(scratch, &mut |network| {
                if let Some(run) = run.take() {
                    result = Some(run(network)?);
                }
                Ok(())
            })?;
        result.context("the f32 network was not built")
    }

    /// The MLP exporter's result with int8 activations, for tools that look inside an MLP (none
    /// for a transformer or int16 activations).
    pub fn mlp(&self) -> Option<&MlpExport> {
        match &self.network {
            Backbone::Mlp(MlpExports::Int8(mlp)) => Some(mlp),
            _ => None,
        }
    }

    /// The MLP exporter's result with int16 activations (none otherwise).
    pub fn mlp16(&self) -> Option<&MlpExport<i16>> {
        match &self.network {
            Backbone::Mlp(MlpExports::Int16(mlp)) => Some(mlp),
            _ => None,
        }
    }

    /// The transformer exporter's result with int8 activations (none for an MLP or int16
    /// activations).
    pub fn transformer(&self) -> Option<&TransformerExport> {
        match &self.network {
            Backbone::Transformer(TransformerExports::Int8(transformer)) => Some(transformer),
            _ => None,
        }
    }

    /// The transformer exporter's result with int16 activations (none otherwise).
    pub fn transformer16(&self) -> Option<&TransformerExport<i16>> {
        match &self.network {
            Backbone::Transformer(TransformerExports::Int16(transformer)) => Some(transformer),
            _ => None,
        }
    }
}

/// The summary `frmd export` prints: shape, steps and calibration, backbone details, memory.
impl fmt::Display for ExportedStudent {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        let network = self.network.get();
        let d = network.dims();
        writeln!(
            f,
            "policy: {:?}, m {} O {} K {} n {} P {}, {} step(s), calibration {} on {} rows",
            self.meta.model.backbone,
            d.history,
            d.obs_dim,
            d.action_dim,
            d.horizon,
            d.params_per_dof,
            network.steps(),
            self.options.ranges,
            network.calibration_rows()
        )?;
        network.details(f)?;
        write!(f, "{} (blob {} B)", network.memory(), self.blob.len())
    }
}
