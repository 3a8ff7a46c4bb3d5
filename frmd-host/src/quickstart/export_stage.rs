//! Stage 5 of quickstart: int8 export of the student ([`crate::export`] with its defaults), its
//! frmd-core `Policy` adapter for closed-loop evaluation, and the int8-vs-float error of
//! docs/design.md section 6 (b) from the bit-accuracy harness ([`crate::equiv`], open-loop part).
use crate::equiv::{run as run_equiv, EquivConfig};
use crate::export::{export_student, write_export, ExportConfig};
use crate::policy::int8::Int8Policy;
use crate::tasks::Policy;
use std::path::{Path, PathBuf};

/// The exported int8 student, ready for closed-loop evaluation.
pub struct Int8Export {
    /// frmd-core running the exported int8 weights.
    pub policy: Box<dyn Policy>,
    /// Observation history the policy expects.
    pub history: usize,
    /// int8-vs-float error of the exported policy against the float student (docs/design.md 6b).
    pub float_error: String,
    /// (what, path) of the exported files.
    pub artifacts: Vec<(String, PathBuf)>,
}

fn export_inner(student_dir: &Path, out: &Path) -> anyhow::Result<Int8Export> {
    let baked = out.join("int8");
    std::fs::create_dir_all(&baked)?;
    // The default export (1 step, min-max calibration on the rows saved beside the student).
    let cfg = ExportConfig::for_checkpoint(student_dir);
    let exported = export_student(&cfg, false)?;
    write_export(&cfg, &exported, Some(&baked), None)?;
    let policy = Int8Policy::from_blob(exported.blob(), "int8-student-1")?;
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
    Ok(Int8Export {
        policy: Box::new(policy),
        history,
        float_error,
        artifacts: vec![
            ("int8 baked module + blob".into(), baked),
            (
                "int8 vs float report".into(),
                out.join("eval").join("equiv.json"),
            ),
        ],
    })
}

/// Exports the student checkpoint in `student_dir` into `out/int8` and wraps it as a policy,
/// or returns why that failed.
pub fn export_int8(student_dir: &Path, out: &Path) -> Result<Int8Export, String> {
    export_inner(student_dir, out).map_err(|e| format!("int8 export failed: {e:#}"))
}
