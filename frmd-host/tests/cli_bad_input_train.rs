//! Bad input to `frmd train`, `collect` and `quickstart` (issue 14): refused before any
//! training or collection, with one line naming the option or the file, exit code 2, and no
//! file changed (no checkpoint directory is even created).
mod cli_support;

use cli_support::{fixture, frmd_ok, hash_tree, rejects, scratch, TINY};
use frmd_host::data::Dataset;

/// `frmd train ROLE --data d.safetensors --out new` plus `extra`.
fn train(role: &str, extra: &[&str]) -> Vec<String> {
    let mut args: Vec<String> = ["train", role, "--data", "d.safetensors", "--out", "new"]
        .map(String::from)
        .to_vec();
    if role == "student" {
        args.extend(["--teacher", "t"].map(String::from));
    }
    args.extend(extra.iter().map(|s| s.to_string()));
    args
}

fn rejects_train(role: &str, extra: &[&str], needles: &[&str]) {
    let args = train(role, extra);
    let args: Vec<&str> = args.iter().map(String::as_str).collect();
    rejects(fixture(), &args, needles);
}

#[test]
fn training_counts_and_rates_are_checked() {
    for role in ["teacher", "student", "dp"] {
        rejects_train(role, &["--steps", "0"], &["--steps 0"]);
        rejects_train(role, &["--steps", "18446744073709551615"], &["--steps"]);
        rejects_train(role, &["--batch", "1000000"], &["--batch 1000000"]);
        rejects_train(role, &["--batch", "0"], &["--batch 0"]);
        rejects_train(role, &["--lr=-1"], &["--lr -1", "> 0"]);
        rejects_train(role, &["--lr", "nan"], &["--lr NaN"]);
        rejects_train(role, &["--lr", "inf"], &["--lr inf"]);
        rejects_train(role, &["--weight-decay=-0.1"], &["--weight-decay"]);
        rejects_train(role, &["--head-lr-scale", "0"], &["--head-lr-scale"]);
        rejects_train(
            role,
            &["--eval-episodes", "1000000000000"],
            &["--eval-episodes"],
        );
        rejects_train(role, &["--eval-steps", "0"], &["--eval-steps 0"]);
        rejects_train(role, &["--log-every", "0"], &["--log-every 0"]);
    }
    rejects_train("teacher", &["--pad-end", "1000000"], &["--pad-end 1000000"]);
    rejects_train("teacher", &["--history", "0"], &["--history 0"]);
    rejects_train("teacher", &["--horizon", "0"], &["--horizon 0"]);
    rejects_train("teacher", &["--num-basis", "100000"], &["--num-basis"]);
    rejects_train("teacher", &["--embed-dim", "3"], &["--embed-dim 3", "even"]);
    rejects_train(
        "teacher",
        &["--exec-steps", "13"],
        &["--exec-steps 13", "horizon 12"],
    );
    rejects_train("dp", &["--exec-steps", "0"], &["--exec-steps 0"]);
    rejects_train("dp", &["--pad-end", "5"], &["--pad-end", "train dp"]);
    rejects_train(
        "dp",
        &["--holdout", "d.safetensors"],
        &["--holdout", "train dp"],
    );
    rejects_train(
        "student",
        &["--exec-steps", "9"],
        &["--exec-steps 9", "horizon 8"],
    );
}

#[test]
fn probabilities_and_decays_are_in_range() {
    rejects_train("teacher", &["--aug-prob", "2"], &["--aug-prob 2", "[0, 1]"]);
    rejects_train("teacher", &["--aug-prob", "nan"], &["--aug-prob NaN"]);
    rejects_train("teacher", &["--aug-y0-std=-1"], &["--aug-y0-std"]);
    rejects_train(
        "teacher",
        &["--sigma-uniform-fraction", "1.5"],
        &["--sigma-uniform-fraction"],
    );
    rejects_train("teacher", &["--ema", "1"], &["--ema 1"]);
    rejects_train("dp", &["--ema", "1.5"], &["--ema 1.5"]);
    rejects_train("student", &["--target-ema", "nan"], &["--target-ema"]);
    rejects_train("student", &["--eval-ema=-0.5"], &["--eval-ema"]);
    rejects_train("student", &["--aug-prob=-0.1"], &["--aug-prob"]);
    rejects_train("student", &["--levels", "1"], &["--levels 1"]);
    rejects_train("student", &["--k", "0"], &["--k 0"]);
}

#[test]
fn student_model_options_must_match_the_teacher() {
    rejects_train(
        "student",
        &["--horizon", "16"],
        &["--horizon", "teacher", "horizon 8"],
    );
    rejects_train(
        "student",
        &["--num-basis", "20"],
        &["--num-basis", "teacher"],
    );
    rejects_train("student", &["--history", "3"], &["--history", "teacher"]);
    rejects_train(
        "student",
        &["--backbone", "mlp:32"],
        &["--backbone", "teacher"],
    );
    rejects_train(
        "student",
        &["--embed-dim", "8"],
        &["--embed-dim", "teacher"],
    );
    let mut args = train("student", &[]);
    args[7] = "s".into();
    let args: Vec<&str> = args.iter().map(String::as_str).collect();
    rejects(
        fixture(),
        &args,
        &["--teacher s", "student checkpoint, not a teacher"],
    );
}

#[test]
fn outputs_are_checked_before_training() {
    let f = fixture();
    rejects(
        f,
        &["train", "teacher", "--data", "d.safetensors", "--out", "t"],
        &["--out t", "not empty", "--force"],
    );
    rejects(
        f,
        &[
            "train",
            "teacher",
            "--data",
            "d.safetensors",
            "--out",
            "d.safetensors",
        ],
        &["--out", "input"],
    );
    rejects(
        f,
        &["train", "dp", "--data", "d.safetensors", "--out", "s.blob"],
        &["--out s.blob", "file"],
    );
    rejects(
        f,
        &[
            "train",
            "student",
            "--data",
            "d.safetensors",
            "--teacher",
            "t",
            "--out",
            "t",
            "--force",
        ],
        &["--out t", "input"],
    );
    rejects(
        f,
        &[
            "train",
            "teacher",
            "--data",
            "d.safetensors",
            "--out",
            "/proc/frmd-no-such/t",
        ],
        &["--out", "not writable"],
    );
    rejects(
        f,
        &[
            "train",
            "teacher",
            "--data",
            "missing.safetensors",
            "--out",
            "new",
        ],
        &["missing.safetensors"],
    );
    rejects(
        f,
        &[
            "train",
            "teacher",
            "--data",
            "d.safetensors",
            "--out",
            "new",
            "--holdout",
            "missing.safetensors",
        ],
        &["missing.safetensors"],
    );
    rejects(
        f,
        &["train", "teacher", "--data", "s.blob", "--out", "new"],
        &["s.blob", "dataset"],
    );
}

#[test]
fn data_that_does_not_fit_its_task_is_refused_before_training() {
    let dir = scratch("bad-data");
    let good = Dataset::load(&fixture().join("d.safetensors")).unwrap();
    let narrow = Dataset {
        obs: good
            .obs
            .chunks(good.obs_dim)
            .flat_map(|r| r[..3].to_vec())
            .collect(),
        obs_dim: 3,
        ..good.clone()
    };
    narrow.save(&dir.join("narrow.safetensors")).unwrap();
    Dataset {
        task: "push".into(),
        ..good.clone()
    }
    .save(&dir.join("push.safetensors"))
    .unwrap();
    Dataset {
        dt: good.dt * 2.0,
        ..good.clone()
    }
    .save(&dir.join("slow.safetensors"))
    .unwrap();
    let teach = |data: &str| {
        [
            "train",
            "teacher",
            "--data",
            data,
            "--out",
            "ckpt",
            "--steps",
            "3",
            "--eval-episodes",
            "1",
        ]
        .map(String::from)
        .to_vec()
    };
    let run = |data: &str, needles: &[&str]| {
        let args = teach(data);
        let args: Vec<&str> = args.iter().map(String::as_str).collect();
        rejects(&dir, &args, needles);
    };
    run(
        "narrow.safetensors",
        &["narrow.safetensors", "obs_dim is 3", "reach"],
    );
    run("push.safetensors", &["push.safetensors", "obs_dim", "push"]);
    run("slow.safetensors", &["slow.safetensors", "dt"]);
    // A student's data must be its teacher's task and sizes.
    let teacher = fixture().join("t");
    let args = [
        "train",
        "student",
        "--teacher",
        teacher.to_str().unwrap(),
        "--data",
        "narrow.safetensors",
        "--out",
        "ckpt",
        "--eval-episodes",
        "0",
    ];
    rejects(&dir, &args, &["narrow.safetensors", "obs_dim 3", "teacher"]);
}

#[test]
fn the_checkpoint_is_saved_before_the_final_evaluation() {
    let dir = scratch("save-first");
    let good = Dataset::load(&fixture().join("d.safetensors")).unwrap();
    good.save(&dir.join("d.safetensors")).unwrap();
    let tiny: Vec<&str> = TINY
        .iter()
        .copied()
        .filter(|a| *a != "--eval-episodes" && *a != "0")
        .collect();
    let args = [
        &[
            "train",
            "teacher",
            "--data",
            "d.safetensors",
            "--out",
            "t",
            "--steps",
            "4",
            "--backbone",
            "mlp:8",
            "--eval-episodes",
            "1",
        ][..],
        &tiny,
    ]
    .concat();
    frmd_ok(&dir, &args);
    let meta: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(dir.join("t/frmd.json")).unwrap()).unwrap();
    assert!(
        meta["training"]["final_eval"].is_object(),
        "final evaluation not recorded: {}",
        meta["training"]
    );
    let before = hash_tree(&dir);
    rejects(&dir, &args, &["--out t", "not empty"]);
    assert_eq!(before, hash_tree(&dir));
    let forced = [&args[..], &["--force"]].concat();
    frmd_ok(&dir, &forced);
}

#[test]
fn collect_is_checked_before_collecting() {
    let f = fixture();
    rejects(
        f,
        &["collect", "--task", "reach", "--out", "d.safetensors"],
        &["--out d.safetensors", "exists", "--force"],
    );
    rejects(
        f,
        &["collect", "--task", "reach", "--out", "t"],
        &["--out t", "directory"],
    );
    rejects(
        f,
        &[
            "collect",
            "--task",
            "reach",
            "--out",
            "new.safetensors",
            "--episodes",
            "0",
        ],
        &["--episodes 0"],
    );
    rejects(
        f,
        &[
            "collect",
            "--task",
            "reach",
            "--out",
            "new.safetensors",
            "--episodes",
            "1000000000000",
        ],
        &["--episodes"],
    );
    rejects(
        f,
        &[
            "collect",
            "--task",
            "reach",
            "--out",
            "new.safetensors",
            "--seed",
            "9223372036854775800",
        ],
        &["--seed", "2^63"],
    );
    rejects(
        f,
        &[
            "collect",
            "--task",
            "reach",
            "--out",
            "new.safetensors",
            "--perturb-std",
            "nan",
        ],
        &["--perturb-std"],
    );
    rejects(
        f,
        &[
            "collect",
            "--task",
            "reach",
            "--out",
            "new.safetensors",
            "--perturb-time",
            "0",
        ],
        &["--perturb-time"],
    );
    rejects(
        f,
        &[
            "collect",
            "--task",
            "nosuchtask",
            "--out",
            "new.safetensors",
        ],
        &["nosuchtask"],
    );
}

#[test]
fn quickstart_never_replaces_a_run() {
    let f = fixture();
    rejects(
        f,
        &["quickstart", "--out", "."],
        &["--out", "not empty", "--force"],
    );
    rejects(
        f,
        &["quickstart", "--out", "t", "--force", "--demos", "0"],
        &["--demos 0"],
    );
    rejects(
        f,
        &["quickstart", "--out", "new", "--teacher-steps", "0"],
        &["--teacher-steps 0"],
    );
    rejects(
        f,
        &["quickstart", "--out", "new", "--batch", "10000000"],
        &["--batch"],
    );
    rejects(
        f,
        &["quickstart", "--out", "new", "--episodes", "1000000000000"],
        &["--episodes"],
    );
    rejects(
        f,
        &["quickstart", "--out", "new", "--task", "nosuchtask"],
        &["nosuchtask"],
    );
    rejects(
        f,
        &["quickstart", "--out", "s.blob"],
        &["--out s.blob", "file"],
    );
}

#[test]
fn probe_options_are_checked() {
    let f = fixture();
    rejects(
        f,
        &[
            "train",
            "probe",
            "--ckpt",
            "t",
            "--data",
            "d.safetensors",
            "--holdout",
            "d.safetensors",
            "--windows",
            "0",
        ],
        &["--windows 0"],
    );
    rejects(
        f,
        &[
            "train",
            "probe",
            "--ckpt",
            "t",
            "--data",
            "d.safetensors",
            "--holdout",
            "d.safetensors",
            "--steps",
            "0",
        ],
        &["--steps 0"],
    );
}
