//! Shared setup of the end-to-end tests: a small `reach` dataset and a briefly trained teacher and
//! student, both through the `frmd train` code paths (which also write calibration.safetensors).
use frmd_host::cli::train::{run as train, CommonArgs, StudentArgs, TeacherArgs, TrainCommand};
use frmd_host::data::collect::collect_demos;
use std::path::{Path, PathBuf};

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

fn common(tiny: &Tiny, data: &Path, out: PathBuf, steps: usize) -> CommonArgs {
    CommonArgs {
        data: data.to_path_buf(),
        out,
        backbone: tiny.backbone.into(),
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

/// Collects 12 `reach` demonstrations and trains the teacher and the student of `tiny` in
/// `<temp>/<name>-<pid>`.
pub fn train_tiny(name: &str, tiny: &Tiny) -> TinyRun {
    std::env::set_var("RAYON_NUM_THREADS", "1");
    let dir = std::env::temp_dir().join(format!("{name}-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(&dir).unwrap();
    let data = dir.join("reach.safetensors");
    let (dataset, _) = collect_demos("reach", 12, 7, &mut |_| {}).unwrap();
    dataset.save(&data).unwrap();

    let (teacher, student, baked) = (dir.join("teacher"), dir.join("student"), dir.join("baked"));
    train(TrainCommand::Teacher(TeacherArgs {
        common: common(tiny, &data, teacher.clone(), tiny.teacher_steps),
        loss_weight: tiny.loss_weight.into(),
        eval_solver: "heun".into(),
        sigma_uniform_fraction: 0.2,
        ema: 0.0,
        augment: Default::default(),
    }))
    .unwrap();
    train(TrainCommand::Student(StudentArgs {
        common: common(tiny, &data, student.clone(), tiny.student_steps),
        teacher: teacher.clone(),
        levels: 18,
        k: 2,
        solver: "heun".into(),
        target_ema: 0.95,
        eval_ema: 0.9,
        augment: Default::default(),
    }))
    .unwrap();
    assert!(student.join("calibration.safetensors").exists());
    TinyRun {
        dir,
        teacher,
        student,
        baked,
    }
}
