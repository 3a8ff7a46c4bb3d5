//! Stage 5 of quickstart: the quantized export of the student ([`crate::export`] with its
//! defaults: int16 activations for an MLP), its frmd-core `Policy` adapter for closed-loop
//! evaluation, and the quantized-vs-float error of docs/design.md section 6 (b) from the
//! bit-accuracy harness ([`crate::equiv`], open-loop part).
use crate::equiv::{run as run_equiv, EquivConfig};
use crate::export::{export_student, write_export, ExportConfig};
use crate::policy::int8::Int8Policy;
use crate::tasks::Policy;
use std::path::{Path, PathBuf};

/// The exported student, ready for closed-loop evaluation.
pub struct QuantizedExport {
    /// The table's name of the policy, by its activations (`int16-student-1`).
    pub label: String,
    /// frmd-core running the exported weights.
    pub policy: Box<dyn Policy>,
    /// Observation history the policy expects.
    pub history: usize,
    /// Error of the exported policy against the float student (docs/design.md 6b).
    pub float_error: String,
    /// (what, path) of the exported files.
    pub artifacts: Vec<(String, PathBuf)>,
}

fn export_inner(student_dir: &Path, out: &Path) -> anyhow::Result<QuantizedExport> {
    let baked = out.join("quantized");
    std::fs::create_dir_all(&baked)?;
    // The default export (1 step, min-max calibration on the rows saved beside the student).
    let cfg = ExportConfig::for_checkpoint(student_dir);
    let exported = export_student(&cfg, false)?;
    write_export(&cfg, &exported, Some(&baked), None)?;
    let label = format!("{}-student-1", exported.activations());
    let policy = Int8Policy::from_blob(exported.blob(), &label)?;
    let history = policy.history();
    // Open-loop error only (the harness's default inputs): the closed-loop rows of the table are
    // the success comparison.
    let cfg = EquivConfig {
        episodes: 0,
        random_requant: 10_000,
        ..EquivConfig::new(student_dir.to_path_buf(), baked.clone())
    };
    let report = run_equiv(&cfg)?;
    let pick = |metric: &str| {
        report
            .rows
            .iter()
            .find(|r| r.check == "b" && r.metric.contains(metric))
            .map(|r| r.value)
    };
    let float_error = match (pick("max abs"), pick("mean abs")) {
        (Some(max), Some(mean)) => format!("max {max:.4} / mean {mean:.4} m"),
        _ => "equiv report has no (b) rows".into(),
    };
    frmd_formats::artifact::write_atomic(
        &out.join("eval").join("equiv.json"),
        serde_json::to_string_pretty(&report)?.as_bytes(),
    )?;
    let what = format!("{} baked module + blob", exported.activations());
    Ok(QuantizedExport {
        label,
        policy: Box::new(policy),
        history,
        float_error,
        artifacts: vec![
            (what, baked),
            (
                "quantized vs float report".into(),
                out.join("eval").join("equiv.json"),
            ),
        ],
    })
}

/// Exports the student checkpoint in `student_dir` into `out/quantized` and wraps it as a
/// policy, or returns why that failed.
pub fn export_quantized(student_dir: &Path, out: &Path) -> Result<QuantizedExport, String> {
    export_inner(student_dir, out).map_err(|e| format!("export failed: {e:#}"))
}
