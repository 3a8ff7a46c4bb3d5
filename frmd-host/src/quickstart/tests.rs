//! A CI-sized run of the whole quickstart pipeline (`--tiny`: numbers are meaningless, the
//! plumbing is what is tested).
use super::*;

#[test]
fn tiny_quickstart_runs_every_stage_and_writes_its_artifacts() {
    let out = std::env::temp_dir().join(format!("frmd-quickstart-test-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&out);
    let cfg = QuickstartConfig {
        out: out.clone(),
        backbone: "mlp:32,32:silu".parse().unwrap(),
        seed: 3,
        ..QuickstartConfig::default()
    };
    let summary = run_pipeline(&cfg.with_tiny_sizes()).unwrap();
    let methods: Vec<&str> = summary.rows.iter().map(|r| r.method.as_str()).collect();
    assert_eq!(
        methods,
        [
            "expert",
            "dp-ddpm-100",
            "dp-ddim-10",
            "teacher-heun-10",
            "student-1",
            "int16-student-1"
        ]
    );
    let expert = summary.rows[0].report.as_ref().unwrap();
    assert_eq!(expert.episodes, 3, "--tiny evaluates 3 episodes");
    assert_eq!(
        expert.successes, 3,
        "the scripted expert solves every evaluation episode"
    );
    for row in &summary.rows {
        let r = row
            .report
            .as_ref()
            .unwrap_or_else(|| panic!("{} not evaluated: {:?}", row.method, row.missing));
        assert!(
            r.latency_us_median.is_finite() && r.latency_us_median > 0.0,
            "{}: latency {}",
            row.method,
            r.latency_us_median
        );
        assert!(r.latency_us_p99 >= r.latency_us_median, "{}", row.method);
        assert!(
            r.chunk_calls >= 3,
            "{}: {} calls",
            row.method,
            r.chunk_calls
        );
        assert!(
            r.non_smooth_ee_mean.is_finite() && r.rms_jerk_mean.is_finite(),
            "{}",
            row.method
        );
    }
    let quantized = summary.rows.last().unwrap();
    let error = quantized.quantized_error.as_deref().unwrap();
    assert!(
        error.starts_with("max ") && !error.contains("NaN"),
        "quantized error {error}"
    );
    for path in [
        "reach-demos.safetensors",
        "teacher/model.safetensors",
        "teacher/frmd.json",
        "student/frmd.json",
        "dp/frmd.json",
        "teacher/learning_curve.png",
        "plots/student-1.png",
        "eval/expert.json",
        "eval/equiv.json",
        "quantized/policy.blob",
        "plots/int16-student-1.png",
        "summary.json",
        "summary.txt",
    ] {
        assert!(out.join(path).is_file(), "missing artifact {path}");
    }
    for (what, path) in &summary.artifacts {
        assert!(
            path.exists(),
            "{what}: {} listed but absent",
            path.display()
        );
    }
    let text = std::fs::read_to_string(out.join("summary.txt")).unwrap();
    assert!(
        text.contains("student-1") && text.contains("100.0 %"),
        "{text}"
    );
    let _ = std::fs::remove_dir_all(&out);
}

#[test]
fn unknown_task_is_rejected_before_any_work() {
    let out = std::env::temp_dir().join(format!("frmd-quickstart-bad-{}", std::process::id()));
    let stage = StageRecipe {
        steps: 1,
        lr: 1e-3,
        warmup: 0,
    };
    let cfg = QuickstartConfig {
        task: "juggle".into(),
        out: out.clone(),
        demos: 1,
        teacher: stage,
        student: stage,
        dp: stage,
        batch: 8,
        baseline: false,
        episodes: 1,
        ..QuickstartConfig::default()
    };
    let err = run_pipeline(&cfg).unwrap_err();
    assert!(format!("{err:#}").contains("juggle"), "{err:#}");
    assert!(!out.exists(), "nothing is written for a bad task");
}
