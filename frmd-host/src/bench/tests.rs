//! `frmd bench` times frmd-core's policies of every backbone, not only the MLP's.

use super::*;

#[test]
fn synthetic_transformer_student_gets_its_frmd_core_rows() {
    let cfg = BenchConfig {
        synthetic: true,
        backbone: "transformer:1,2,32".parse().unwrap(),
        calls: 2,
        warmup: 0,
        ..BenchConfig::default()
    };
    let (rows, note) = bench_rows(&cfg).unwrap();
    assert_eq!(note, None, "frmd-core policies missing");
    for label in ["frmd-core int8 1-step", "frmd-core f32 1-step"] {
        let row = rows
            .iter()
            .find(|r| r.label == label)
            .unwrap_or_else(|| panic!("no `{label}` row in {rows:?}"));
        assert_eq!(row.backbone, "transformer 1x2h 32");
        assert!(row.median_us > 0.0 && row.p99_us >= row.median_us);
    }
    assert_eq!(rows[0].label, "frmd-core int8 1-step");
}

/// The stage breakdown of an MLP student's chunk (both activation precisions) recombines into
/// the policy's own chunk bit for bit, and names every layer's parts.
#[test]
fn mlp_chunk_stages_recombine_into_the_policy_chunk() {
    use crate::tasks::PolicyInput;
    let dir = std::env::temp_dir().join(format!("frmd-stages-test-{}", std::process::id()));
    let policies = fixtures::reach_student(&dir, &"mlp:32,24".parse().unwrap(), 3);
    let _ = std::fs::remove_dir_all(&dir);
    let core = policies.unwrap().core.unwrap();
    let (history, prev, rate) = fixtures::reach_input();
    let input = PolicyInput {
        obs_history: &history,
        prev_action: &prev,
        prev_rate: &rate,
    };
    let int16 = (core.int16, core.int16_blob);
    for (mut policy, blob) in [(core.int8, core.int8_blob), int16] {
        let names = stages::with_stages(&blob, &mut policy, &input, |stages| {
            stages.check()?;
            for index in 0..stages.names().len() {
                stages.run(index)?;
            }
            Ok(stages.names())
        })
        .unwrap();
        for name in [
            "noise",
            "input",
            "L0 rows",
            "L1 requant",
            "L1 table",
            "decode",
        ] {
            assert!(
                names.iter().any(|n| n == name),
                "no stage {name} in {names:?}"
            );
        }
        assert_eq!(names.last().map(String::as_str), Some("chunk"));
    }
}

/// With `--policy` naming a student, the frmd-core rows export that student (not the one under
/// `--dir`, which here does not exist) and say so in their labels.
#[test]
fn frmd_core_rows_follow_the_student_given_as_policy() {
    let root = std::env::temp_dir().join(format!("frmd-bench-policy-{}", std::process::id()));
    let student = root.join("mine");
    let made = fixtures::reach_student(&student, &"mlp:32,24".parse().unwrap(), 5);
    let cfg = BenchConfig {
        dir: root.join("no-such-quickstart"),
        policies: vec![format!("{}:1", student.display()).parse().unwrap()],
        calls: 2,
        warmup: 0,
        ..BenchConfig::default()
    };
    let result = made.map(|_| bench_rows(&cfg));
    let _ = std::fs::remove_dir_all(&root);
    let (rows, note) = result.unwrap().unwrap();
    assert_eq!(note, None, "frmd-core policies missing");
    let label = format!("frmd-core int8 1-step ({})", student.display());
    assert!(
        rows.iter().any(|r| r.label == label),
        "no `{label}` row in {rows:?}"
    );
}
