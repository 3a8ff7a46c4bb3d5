//! Exporting a student checkpoint directory (what `frmd export` does): the settings recorded in
//! `export.json` ([`ExportConfig`], whose `Default` is the recipe), the calibration rows they
//! name, the exporter the checkpoint's backbone picks (MLP students: the const-baked module;
//! transformer-lite students: the `FRMT` blob plus a generated module that embeds it), and the
//! files written beside each other (module, `policy.blob`, `export.json`).
use crate::checkpoint::CALIBRATION_FILE;
use crate::data::windows::CALIBRATION_ROWS;
use crate::data::Dataset;
use crate::limits::{self, OptionError};
use anyhow::{bail, Context};
use frmd_core::model::mlp::InputPrecision;
use frmd_export::artifact::write_atomic;
use frmd_export::calibrate::{CalibrationSet, RangeMethod};
use frmd_export::checkpoint::{BackboneConfig, CheckpointMeta, Role};
use frmd_export::export::{
    export_checkpoint, export_transformer_checkpoint, ExportOptions, Exported, ExportedTransformer,
};
use serde::{Deserialize, Serialize};
use std::path::{Path, PathBuf};

/// Blob written beside a baked module (what `--baked DIR` loads).
pub const BAKED_BLOB_FILE: &str = "policy.blob";
/// Export settings written beside a baked module.
pub const EXPORT_INFO_FILE: &str = "export.json";

/// Export settings, as `export.json` records them (enough to reproduce the export). Fields
/// missing from an older `export.json` take their default.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(default)]
pub struct ExportConfig {
    /// Student checkpoint directory.
    pub checkpoint: String,
    /// Sampling steps baked into the step table (1..4).
    pub steps: usize,
    /// Activation ranges: `minmax` | `percentile:P`.
    pub calibration: String,
    /// Demonstrations to calibrate on instead of the checkpoint's `calibration.safetensors`.
    pub calibration_data: Option<String>,
    /// Input range balancing (`frmd_export::fold::FoldedMlp::with_input_gains`).
    pub balance_inputs: bool,
    /// 16-bit input precision: the 16-bit input plane
    /// (`frmd_core::model::mlp::InputPrecision::Int16`; before blob format 3, two int8 planes).
    pub two_plane_input: bool,
    /// Input range widening with the 16-bit input (>= 1).
    pub input_headroom: f32,
}

impl Default for ExportConfig {
    /// The exporter's defaults (`frmd_export::export::ExportOptions::default`: one step, min-max
    /// calibration, balanced inputs, the 16-bit input with its headroom), calibrated on the
    /// checkpoint's own rows; no checkpoint named.
    fn default() -> Self {
        let options = ExportOptions::default();
        ExportConfig {
            checkpoint: String::new(),
            steps: options.steps,
            calibration: options.ranges.to_string(),
            calibration_data: None,
            balance_inputs: options.balance_inputs,
            two_plane_input: options.input_precision == InputPrecision::Int16,
            input_headroom: options.input_headroom,
        }
    }
}

impl ExportConfig {
    /// The default export of the checkpoint in `dir`.
    pub fn for_checkpoint(dir: &Path) -> Self {
        ExportConfig {
            checkpoint: dir.display().to_string(),
            ..ExportConfig::default()
        }
    }

    /// The settings alone, before any work.
    pub fn validate(&self) -> Result<(), OptionError> {
        limits::count("steps", self.steps, 1, 4)?;
        if !(self.input_headroom.is_finite() && self.input_headroom >= 1.0) {
            return Err(limits::range(
                "input-headroom",
                self.input_headroom,
                "a finite factor >= 1",
            ));
        }
        self.calibration.parse::<RangeMethod>().map_err(|e| {
            limits::range(
                "calibration",
                &self.calibration,
                format!("minmax or percentile:P ({e})"),
            )
        })?;
        Ok(())
    }

    fn options(&self) -> anyhow::Result<ExportOptions> {
        let ranges: RangeMethod = self.calibration.parse()?;
        let input_precision = if self.two_plane_input {
            InputPrecision::Int16
        } else {
            InputPrecision::Int8
        };
        Ok(ExportOptions {
            steps: self.steps,
            ranges,
            balance_inputs: self.balance_inputs,
            input_precision,
            input_headroom: self.input_headroom,
        })
    }
}

/// Calibration rows from a dataset file, checked against the checkpoint's normalization.
pub fn calibration_from_data(path: &Path, ckpt: &Path) -> anyhow::Result<CalibrationSet> {
    let meta = CheckpointMeta::read(ckpt)?;
    let dataset = Dataset::load(path)?;
    let (windows, norm) = dataset.windows(meta.model.history, meta.model.horizon)?;
    if Some(&norm) != meta.normalization.as_ref() {
        bail!(
            "{}: its normalization differs from the checkpoint's (not the training data?)",
            path.display()
        );
    }
    Ok(windows.calibration_rows(CALIBRATION_ROWS, 0x5eed))
}

/// Stores the calibration rows of `data` as the checkpoint's `calibration.safetensors`.
pub fn save_calibration(data: &Path, ckpt: &Path) -> anyhow::Result<()> {
    let set = calibration_from_data(data, ckpt)?;
    frmd_export::calibration_file::write(&ckpt.join(CALIBRATION_FILE), &set)
}

/// The calibration rows `cfg` names: its data file, else `None` (the checkpoint's own file),
/// failing with advice when neither exists.
fn calibration_set(cfg: &ExportConfig) -> anyhow::Result<Option<CalibrationSet>> {
    let ckpt = Path::new(&cfg.checkpoint);
    let meta = CheckpointMeta::read(ckpt)?;
    if meta.role != Role::Student {
        bail!("--ckpt {}: this is a {} checkpoint; only students can be exported (its sampler needs many network evaluations)", ckpt.display(), crate::policy::float::role_name(meta.role));
    }
    match &cfg.calibration_data {
        Some(data) => Ok(Some(calibration_from_data(Path::new(data), ckpt)?)),
        None if !ckpt.join(CALIBRATION_FILE).exists() => {
            bail!(
                "{} has no {CALIBRATION_FILE}; pass --data with the training demonstrations",
                ckpt.display()
            )
        }
        None => Ok(None),
    }
}

/// Whether the checkpoint `cfg` names has a transformer backbone (which picks the exporter).
pub fn is_transformer(cfg: &ExportConfig) -> anyhow::Result<bool> {
    let meta = CheckpointMeta::read(Path::new(&cfg.checkpoint))?;
    Ok(matches!(
        meta.model.backbone,
        BackboneConfig::Transformer { .. }
    ))
}

/// Runs the MLP export of `cfg` (reads the calibration data it names).
pub fn export_mlp(cfg: &ExportConfig) -> anyhow::Result<Exported> {
    export_checkpoint(
        Path::new(&cfg.checkpoint),
        cfg.options()?,
        calibration_set(cfg)?,
    )
}

/// Runs the transformer export of `cfg`.
pub fn export_transformer(cfg: &ExportConfig) -> anyhow::Result<ExportedTransformer> {
    export_transformer_checkpoint(
        Path::new(&cfg.checkpoint),
        cfg.options()?,
        calibration_set(cfg)?,
    )
}

/// The `FRMT` blob of a transformer export.
pub fn transformer_blob(exported: &ExportedTransformer) -> anyhow::Result<Vec<u8>> {
    let norm = exported
        .checkpoint
        .meta
        .normalization
        .as_ref()
        .context("the checkpoint has no normalization")?;
    frmd_export::blob::write_transformer(&exported.model, norm)
        .map_err(|e| anyhow::anyhow!("encoding the transformer blob: {e}"))
}

/// An exported student: the exporter's result for its backbone and the blob bytes.
pub enum ExportedStudent {
    Mlp {
        exported: Exported,
        blob: Vec<u8>,
    },
    Transformer {
        exported: ExportedTransformer,
        blob: Vec<u8>,
    },
}

impl ExportedStudent {
    /// The self-describing blob (`policy.blob`).
    pub fn blob(&self) -> &[u8] {
        match self {
            ExportedStudent::Mlp { blob, .. } | ExportedStudent::Transformer { blob, .. } => blob,
        }
    }
}

/// Exports the checkpoint `cfg` names with the exporter of its backbone. The blob is loaded
/// back with frmd-core's loader (the firmware's) before it is returned: an export the runtime
/// would refuse is an error here, not a file.
pub fn export_student(cfg: &ExportConfig) -> anyhow::Result<ExportedStudent> {
    cfg.validate()?;
    let student = if is_transformer(cfg)? {
        let exported = export_transformer(cfg)?;
        let blob = transformer_blob(&exported)?;
        ExportedStudent::Transformer { exported, blob }
    } else {
        let exported = export_mlp(cfg)?;
        let blob = frmd_export::blob::write(&exported.policy)
            .map_err(|e| anyhow::anyhow!("encoding the blob: {e}"))?;
        ExportedStudent::Mlp { exported, blob }
    };
    crate::policy::int8::Int8Policy::from_blob(student.blob(), "int8").with_context(|| {
        format!(
            "{}: the exported blob does not load with the runtime's loader (nothing written)",
            cfg.checkpoint
        )
    })?;
    Ok(student)
}

/// Writes the module directory `dir` (MLP: `policy.rs` + `weights.bin` + `policy.blob`;
/// transformer: `policy.rs` embedding the blob + `policy.blob`; both with `export.json`) and/or
/// the blob alone at `blob_path`; returns the files written.
pub fn write_export(
    cfg: &ExportConfig,
    student: &ExportedStudent,
    dir: Option<&Path>,
    blob_path: Option<&Path>,
) -> anyhow::Result<Vec<PathBuf>> {
    let mut written = Vec::new();
    if let Some(dir) = dir {
        match student {
            ExportedStudent::Mlp { exported, blob } => {
                frmd_export::bake::write_module(&exported.policy, dir)
                    .with_context(|| format!("writing {}", dir.display()))?;
                write_atomic(&dir.join(BAKED_BLOB_FILE), blob)?;
                written.extend(["policy.rs", "weights.bin", BAKED_BLOB_FILE].map(|f| dir.join(f)));
            }
            ExportedStudent::Transformer { exported, blob } => {
                frmd_export::transformer::bake::write_module(&exported.model, blob, dir)
                    .with_context(|| format!("writing {}", dir.display()))?;
                written.extend(
                    [frmd_export::transformer::bake::MODULE_FILE, BAKED_BLOB_FILE]
                        .map(|f| dir.join(f)),
                );
            }
        }
        write_atomic(
            &dir.join(EXPORT_INFO_FILE),
            serde_json::to_string_pretty(cfg)?.as_bytes(),
        )?;
        written.push(dir.join(EXPORT_INFO_FILE));
    }
    if let Some(path) = blob_path {
        write_atomic(path, student.blob())?;
        written.push(path.to_path_buf());
    }
    Ok(written)
}
