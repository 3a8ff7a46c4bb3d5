//! Shared setup of the end-to-end tests: a small `reach` dataset and a briefly trained teacher and
//! student, both through the library behind `frmd train` (which also writes
//! calibration.safetensors), and the export `frmd export` does.
use frmd_core::blob::BlobError;
use frmd_core::policy::PolicyDims;
use frmd_export::bake::BLOB_FILE;
use frmd_host::data::collect::collect_demos;
use frmd_host::diffusion::samplers::Solver;
use frmd_host::equiv::{run as equiv, EquivConfig, EquivReport};
use frmd_host::export::{export_student, write_export, ExportConfig};
use frmd_host::models::ProDmpOutput;
use frmd_host::train::distill::DistillConfig;
use frmd_host::train::recipe::{StudentRun, TeacherRun, TrainConfig};
use frmd_host::train::run::{run_student, run_teacher};
use frmd_host::train::teacher::TeacherConfig;
use std::path::{Path, PathBuf};

/// The sizes of the tiny runs: history 2, `reach` (6 observations, 2 DoF), horizon 8, 6 basis
/// functions plus the goal.
pub const TINY_DIMS: PolicyDims = PolicyDims {
    history: 2,
    obs_dim: 6,
    action_dim: 2,
    horizon: 8,
    params_per_dof: 7,
};

/// A loaded blob's `check_dims` accepts [`TINY_DIMS`] and refuses another horizon and basis.
pub fn assert_tiny_dims(check_dims: impl Fn(&PolicyDims) -> Result<(), BlobError>) {
    assert_eq!(check_dims(&TINY_DIMS), Ok(()));
    assert!(matches!(
        check_dims(&PolicyDims {
            horizon: 12,
            params_per_dof: 21,
            ..TINY_DIMS
        }),
        Err(BlobError::DimensionMismatch(_))
    ));
}

/// What differs between the tiny training runs of the tests.
pub struct Tiny {
    pub backbone: &'static str,
    pub seed: u64,
    pub batch: usize,
    pub lr: f64,
    pub warmup: usize,
    pub teacher_steps: usize,
    /// Teacher loss weight: "edm" or "uniform".
    pub loss_weight: &'static str,
    pub student_steps: usize,
}

/// Directories of one tiny run, all under a fresh per-process temporary directory.
pub struct TinyRun {
    pub dir: PathBuf,
    pub teacher: PathBuf,
    pub student: PathBuf,
    /// Where the test exports to (not created here).
    pub baked: PathBuf,
}

fn common(tiny: &Tiny, data: &Path, out: PathBuf, steps: usize) -> TrainConfig {
    TrainConfig {
        data: data.to_path_buf(),
        out,
        force: false,
        backbone: tiny.backbone.parse().unwrap(),
        steps,
        seed: tiny.seed,
        batch: tiny.batch,
        lr: tiny.lr,
        weight_decay: 1e-6,
        warmup: tiny.warmup,
        history: 2,
        horizon: 8,
        num_basis: 6,
        embed_dim: 8,
        log_every: 50,
        eval_every: 0,
        eval_episodes: 0,
        exec_steps: 8,
        eval_steps: None,
        holdout: None,
        pad_end: 0,
        head_lr_scale: 1.0,
    }
}

impl TinyRun {
    /// What `frmd export --ckpt CKPT --out BAKED --blob DIR/student.blob` does (one step,
    /// min-max calibration, the default 16-bit input): exports `ckpt` into `baked` and
    /// `dir/student.blob`.
    pub fn export(&self, ckpt: &Path) -> anyhow::Result<()> {
        let cfg = ExportConfig::for_checkpoint(ckpt);
        let student = export_student(&cfg, false)?;
        write_export(
            &cfg,
            &student,
            Some(&self.baked),
            Some(&self.dir.join("student.blob")),
        )?;
        Ok(())
    }

    /// [`Self::export`] of the student, which must succeed; the blob written next to the run
    /// equals the baked one, which is returned.
    pub fn export_student(&self) -> Vec<u8> {
        self.export(&self.student).unwrap();
        let blob = std::fs::read(self.baked.join(BLOB_FILE)).unwrap();
        assert_eq!(std::fs::read(self.dir.join("student.blob")).unwrap(), blob);
        blob
    }
}

/// Collects 12 `reach` demonstrations and trains the teacher and the student of `tiny` in
/// `<temp>/<name>-<pid>`.
pub fn train_tiny(name: &str, tiny: &Tiny) -> TinyRun {
    std::env::set_var("RAYON_NUM_THREADS", "1");
    let dir = std::env::temp_dir().join(format!("{name}-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(&dir).unwrap();
    let data = dir.join("reach.safetensors");
    let (dataset, _) = collect_demos("reach", 12, 7, None, 0, &mut |_| {}).unwrap();
    dataset.save(&data).unwrap();

    let (teacher, student, baked) = (dir.join("teacher"), dir.join("student"), dir.join("baked"));
    run_teacher(&TeacherRun {
        train: common(tiny, &data, teacher.clone(), tiny.teacher_steps),
        teacher: TeacherConfig {
            weight: tiny.loss_weight.parse().unwrap(),
            ..TeacherConfig::default()
        },
        output: ProDmpOutput::BoundarySkip,
        auto_scale_basis: false,
        eval_solver: Some(Solver::Heun),
    })
    .unwrap();
    run_student(&StudentRun {
        train: common(tiny, &data, student.clone(), tiny.student_steps),
        teacher: teacher.clone(),
        distill: DistillConfig {
            levels: 18,
            teacher_steps: 2,
            solver: Solver::Heun,
            target_ema: 0.95,
            eval_ema: 0.9,
            ..DistillConfig::default()
        },
        ..StudentRun::default()
    })
    .unwrap();
    assert!(student.join("calibration.safetensors").exists());
    TinyRun {
        dir,
        teacher,
        student,
        baked,
    }
}

/// Runs `frmd equiv` on an exported tiny student and asserts the bounds every backbone shares:
/// the blob equals a re-export, the f32 twin matches candle within 1e-4, requantization agrees
/// with the wide-integer model, the int8 vs float errors are within their stated bounds (10 % max,
/// 2 % mean of the action range), and the report passes. `episodes`/`inputs` set the effort; the
/// success-rate bound is not asserted (a briefly trained student's success is not meaningful).
/// Returns the report for backbone-specific checks.
pub fn equiv_within_bounds(
    student: &Path,
    baked: &Path,
    episodes: usize,
    inputs: usize,
) -> EquivReport {
    let mut cfg = EquivConfig::new(student.to_path_buf(), baked.to_path_buf());
    cfg.episodes = episodes;
    cfg.inputs = inputs;
    cfg.random_requant = 20_000;
    cfg.max_success_diff_points = 100.0;
    let report = equiv(&cfg).unwrap();
    frmd_host::equiv::print(&report);
    assert_eq!(row(&report, "baked blob differs"), 0.0);
    assert!(
        row(&report, "core f32 vs candle float: max") < 1e-4,
        "f32 path vs candle"
    );
    assert_eq!(row(&report, "requantization mismatches"), 0.0);
    for r in report
        .rows
        .iter()
        .filter(|r| r.check == "b" && r.metric.contains("abs error"))
    {
        assert_eq!(r.pass, Some(true), "{r:?}");
    }
    assert!(report.passed);
    report
}

/// The value of the report row whose metric starts with `metric`.
pub fn row(report: &EquivReport, metric: &str) -> f64 {
    report
        .rows
        .iter()
        .find(|r| r.metric.starts_with(metric))
        .unwrap_or_else(|| panic!("row {metric}"))
        .value
}
