//! Stage 5 of quickstart: int8 export of the student and its `Policy` adapter.
//!
//! This is the one place the exporter is wired in. Until `frmd export` and the frmd-core int8
//! policy adapter are part of the build, the stage reports that it is not available, and the
//! table says so instead of showing numbers.
use crate::eval::policy::Policy;
use std::path::{Path, PathBuf};

/// The exported int8 student, ready for closed-loop evaluation.
pub struct Int8Export {
    /// frmd-core running the exported int8 weights.
    pub policy: Box<dyn Policy>,
    /// Observation history the policy expects.
    pub history: usize,
    /// int8-vs-float error of the exported policy against the float student (DESIGN.md 6b).
    pub float_error: String,
    /// (what, path) of the exported files.
    pub artifacts: Vec<(String, PathBuf)>,
}

/// Exports the student checkpoint in `student_dir` into `out` and wraps it as a policy, or
/// returns why that is not possible in this build.
pub fn export_int8(student_dir: &Path, out: &Path) -> Result<Int8Export, String> {
    let _ = (student_dir, out);
    Err("not available in this build (int8 export and frmd-core policy adapter not merged yet)".into())
}
