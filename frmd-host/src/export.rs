//! Exporting a student checkpoint directory (what `frmd export` does): the settings recorded in
//! `export.json` ([`ExportConfig`], whose `Default` is the recipe), the calibration rows they
//! name, one call into the exporter ([`frmd_export::export_checkpoint`], which picks the backbone,
//! encodes and checks the blob), and the files written beside each other (the baked module,
//! `policy.blob`, `export.json`).
use crate::data::windows::CALIBRATION_ROWS;
use crate::data::Dataset;
use crate::limits::{self, OptionError};
use anyhow::{bail, Context};
use frmd_core::model::mlp::InputPrecision;
use frmd_export::calibrate::RangeMethod;
use frmd_export::{Activations, ExportOptions, ExportedStudent};
use frmd_formats::artifact::write_atomic;
use frmd_formats::calibration::CalibrationSet;
use frmd_formats::checkpoint::{Checkpoint, CheckpointMeta, CALIBRATION_FILE};
use serde::{Deserialize, Serialize};
use std::path::{Path, PathBuf};

/// `export.json` files written before the `activations` field: int8 exports.
fn int8_before_the_field() -> Option<String> {
    Some("int8".into())
}

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
    /// Input range balancing (`frmd_export::mlp::FoldedMlp::with_input_gains`).
    pub balance_inputs: bool,
    /// 16-bit input precision: the 16-bit input plane
    /// (`frmd_core::model::mlp::InputPrecision::Int16`; before blob format 3, two int8 planes).
    pub two_plane_input: bool,
    /// Input range widening with the 16-bit input (>= 1).
    pub input_headroom: f32,
    /// Hidden activations: `int8` | `int16`; `None`: the backbone's default
    /// ([`frmd_export::Activations::recipe`]). `export.json` records the precision exported; one
    /// written before int16 activations existed has no such field and means int8.
    #[serde(default = "int8_before_the_field")]
    pub activations: Option<String>,
    /// Activation range widening with int16 activations (>= 1).
    pub activation_headroom: f32,
}

impl Default for ExportConfig {
    /// The exporter's defaults ([`ExportOptions::default`]: one step, min-max calibration,
    /// balanced inputs, the 16-bit input with its headroom), calibrated on the checkpoint's own
    /// rows; no checkpoint named.
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
            activations: options.activations.map(|a| a.to_string()),
            activation_headroom: options.activation_headroom,
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

    /// The settings `export.json` in the baked module directory `dir` records.
    pub fn read(dir: &Path) -> anyhow::Result<Self> {
        let path = dir.join(EXPORT_INFO_FILE);
        let text = std::fs::read_to_string(&path)
            .with_context(|| format!("reading {}", path.display()))?;
        serde_json::from_str(&text).with_context(|| {
            format!(
                "{}: not the export settings `frmd export` writes",
                path.display()
            )
        })
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
        if !(self.activation_headroom.is_finite() && self.activation_headroom >= 1.0) {
            return Err(limits::range(
                "activation-headroom",
                self.activation_headroom,
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
        if let Some(text) = &self.activations {
            let activations = text
                .parse::<Activations>()
                .map_err(|_| limits::range("activations", text, "int8 or int16"))?;
            if activations == Activations::Int16 && !self.two_plane_input {
                return Err(limits::range(
                    "activations",
                    text,
                    "int8 with --int8-input (int16 activations take the 16-bit input)",
                ));
            }
        }
        Ok(())
    }

    fn options(&self) -> anyhow::Result<ExportOptions> {
        let input_precision = if self.two_plane_input {
            InputPrecision::Int16
        } else {
            InputPrecision::Int8
        };
        Ok(ExportOptions {
            steps: self.steps,
            ranges: self.calibration.parse()?,
            balance_inputs: self.balance_inputs,
            input_precision,
            input_headroom: self.input_headroom,
            activations: self.activations.as_deref().map(str::parse).transpose()?,
            activation_headroom: self.activation_headroom,
        })
    }
}

/// Calibration rows from the dataset file `path`, windowed as the checkpoint `meta` was trained
/// and checked against its normalization.
pub fn calibration_from_data(path: &Path, meta: &CheckpointMeta) -> anyhow::Result<CalibrationSet> {
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

/// Exports the checkpoint `cfg` names (read once) with its calibration data or its own
/// calibration file; with `save_calibration`, the rows of the calibration data are also stored as
/// the checkpoint's `calibration.safetensors`.
pub fn export_student(
    cfg: &ExportConfig,
    save_calibration: bool,
) -> anyhow::Result<ExportedStudent> {
    cfg.validate()?;
    let options = cfg.options()?;
    let checkpoint = Checkpoint::read(Path::new(&cfg.checkpoint))?;
    let rows = match &cfg.calibration_data {
        Some(data) => {
            let rows = calibration_from_data(Path::new(data), &checkpoint.meta)?;
            if save_calibration {
                frmd_formats::calibration::write(&checkpoint.dir.join(CALIBRATION_FILE), &rows)?;
            }
            Some(rows)
        }
        None if save_calibration => bail!("--save-calibration needs --data"),
        None => None,
    };
    frmd_export::export_checkpoint(checkpoint, &options, rows)
}

/// The checkpoint path `checkpoint` as `export.json` in `dir` records it: relative to `dir`
/// (`frmd serve --baked` resolves it from there, whatever its working directory, and a run
/// directory moved as a whole keeps working), or as given when either path cannot be resolved
/// (an absolute path stays absolute).
fn checkpoint_from(dir: &Path, checkpoint: &str) -> String {
    let given = Path::new(checkpoint);
    if given.is_absolute() || checkpoint.is_empty() {
        return checkpoint.to_string();
    }
    let (Ok(from), Ok(to)) = (dir.canonicalize(), given.canonicalize()) else {
        return checkpoint.to_string();
    };
    let common = from
        .components()
        .zip(to.components())
        .take_while(|(a, b)| a == b)
        .count();
    let mut relative = PathBuf::new();
    for _ in common..from.components().count() {
        relative.push("..");
    }
    relative.extend(to.components().skip(common));
    if relative.as_os_str().is_empty() {
        relative.push(".");
    }
    relative.display().to_string()
}

/// Writes the module directory `dir` (the baked module, `policy.blob` and `export.json`) and/or
/// the blob alone at `blob_path`; returns the files written.
pub fn write_export(
    cfg: &ExportConfig,
    student: &ExportedStudent,
    dir: Option<&Path>,
    blob_path: Option<&Path>,
) -> anyhow::Result<Vec<PathBuf>> {
    let mut written = Vec::new();
    if let Some(dir) = dir {
        written.extend(student.write_module(dir)?);
        let info = dir.join(EXPORT_INFO_FILE);
        // The precision exported (asked for or the backbone's default), and the checkpoint as
        // seen from the export directory.
        let recorded = ExportConfig {
            activations: Some(student.activations().to_string()),
            checkpoint: checkpoint_from(dir, &cfg.checkpoint),
            ..cfg.clone()
        };
        write_atomic(&info, serde_json::to_string_pretty(&recorded)?.as_bytes())?;
        written.push(info);
    }
    if let Some(path) = blob_path {
        write_atomic(path, student.blob())?;
        written.push(path.to_path_buf());
    }
    Ok(written)
}
