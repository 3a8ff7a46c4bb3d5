//! Bad input to `frmd train`, `collect` and `quickstart` (issue 14): refused before any
//! training or collection, with one line naming the option or the file, exit code 2, and no
//! file changed (no checkpoint directory is even created).
mod cli_support;

use cli_support::{fixture, frmd_ok, hash_tree, rejects, rejects_each, scratch, words, TINY};
use frmd_host::data::Dataset;

/// `frmd train ROLE --data d.safetensors --out new` (a student with `--teacher t`) plus `extra`.
fn train(role: &str, extra: &str) -> String {
    let teacher = if role == "student" { "--teacher t" } else { "" };
    format!("train {role} --data d.safetensors --out new {teacher} {extra}")
}

/// [`rejects`] each `(role, extra options, needles)` case of [`train`].
fn rejects_train(cases: &[(&str, &str, &[&str])]) {
    for (role, extra, needles) in cases {
        rejects(fixture(), &words(&train(role, extra)), needles);
    }
}

#[test]
fn training_counts_and_rates_are_checked() {
    for role in ["teacher", "student", "dp"] {
        rejects_train(&[
            (role, "--steps 0", &["--steps 0"]),
            (role, "--steps 18446744073709551615", &["--steps"]),
            (role, "--batch 1000000", &["--batch 1000000"]),
            (role, "--batch 0", &["--batch 0"]),
            (role, "--lr=-1", &["--lr -1", "> 0"]),
            (role, "--lr nan", &["--lr NaN"]),
            (role, "--lr inf", &["--lr inf"]),
            (role, "--weight-decay=-0.1", &["--weight-decay"]),
            (role, "--head-lr-scale 0", &["--head-lr-scale"]),
            (role, "--eval-episodes 1000000000000", &["--eval-episodes"]),
            (role, "--eval-steps 0", &["--eval-steps 0"]),
            (role, "--log-every 0", &["--log-every 0"]),
        ]);
    }
    rejects_train(&[
        ("teacher", "--pad-end 1000000", &["--pad-end 1000000"]),
        ("teacher", "--history 0", &["--history 0"]),
        ("teacher", "--horizon 0", &["--horizon 0"]),
        ("teacher", "--num-basis 100000", &["--num-basis"]),
        ("teacher", "--embed-dim 3", &["--embed-dim 3", "even"]),
        (
            "teacher",
            "--exec-steps 13",
            &["--exec-steps 13", "horizon 12"],
        ),
        ("dp", "--exec-steps 0", &["--exec-steps 0"]),
        ("dp", "--pad-end 5", &["--pad-end", "train dp"]),
        ("dp", "--holdout d.safetensors", &["--holdout", "train dp"]),
        (
            "student",
            "--exec-steps 9",
            &["--exec-steps 9", "horizon 8"],
        ),
    ]);
}

#[test]
fn probabilities_and_decays_are_in_range() {
    rejects_train(&[
        ("teacher", "--aug-prob 2", &["--aug-prob 2", "[0, 1]"]),
        ("teacher", "--aug-prob nan", &["--aug-prob NaN"]),
        ("teacher", "--aug-y0-std=-1", &["--aug-y0-std"]),
        (
            "teacher",
            "--sigma-uniform-fraction 1.5",
            &["--sigma-uniform-fraction"],
        ),
        ("teacher", "--ema 1", &["--ema 1"]),
        ("dp", "--ema 1.5", &["--ema 1.5"]),
        ("student", "--target-ema nan", &["--target-ema"]),
        ("student", "--eval-ema=-0.5", &["--eval-ema"]),
        ("student", "--aug-prob=-0.1", &["--aug-prob"]),
        ("student", "--levels 1", &["--levels 1"]),
        ("student", "--k 0", &["--k 0"]),
    ]);
}

#[test]
fn student_model_options_must_match_the_teacher() {
    rejects_train(&[
        (
            "student",
            "--horizon 16",
            &["--horizon", "teacher", "horizon 8"],
        ),
        ("student", "--num-basis 20", &["--num-basis", "teacher"]),
        ("student", "--history 3", &["--history", "teacher"]),
        ("student", "--backbone mlp:32", &["--backbone", "teacher"]),
        ("student", "--embed-dim 8", &["--embed-dim", "teacher"]),
    ]);
    rejects(
        fixture(),
        &words("train student --data d.safetensors --out new --teacher s"),
        &["--teacher s", "student checkpoint, not a teacher"],
    );
}

#[test]
fn outputs_are_checked_before_training() {
    rejects_each(&[
        (
            "train teacher --data d.safetensors --out t",
            &["--out t", "not empty", "--force"],
        ),
        (
            "train teacher --data d.safetensors --out d.safetensors",
            &["--out", "input"],
        ),
        (
            "train dp --data d.safetensors --out s.blob",
            &["--out s.blob", "file"],
        ),
        (
            "train student --data d.safetensors --teacher t --out t --force",
            &["--out t", "input"],
        ),
        (
            "train teacher --data d.safetensors --out /proc/frmd-no-such/t",
            &["--out", "not writable"],
        ),
        (
            "train teacher --data missing.safetensors --out new",
            &["missing.safetensors"],
        ),
        (
            "train teacher --data d.safetensors --out new --holdout missing.safetensors",
            &["missing.safetensors"],
        ),
        (
            "train teacher --data s.blob --out new",
            &["s.blob", "dataset"],
        ),
    ]);
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
    let run = |data: &str, needles: &[&str]| {
        let line = format!("train teacher --data {data} --out ckpt --steps 3 --eval-episodes 1");
        rejects(&dir, &words(&line), needles);
    };
    run(
        "narrow.safetensors",
        &["narrow.safetensors", "obs_dim is 3", "reach"],
    );
    run("push.safetensors", &["push.safetensors", "obs_dim", "push"]);
    run("slow.safetensors", &["slow.safetensors", "dt"]);
    // A student's data must be its teacher's task and sizes.
    let teacher = fixture().join("t");
    let line = format!(
        "train student --teacher {} --data narrow.safetensors --out ckpt --eval-episodes 0",
        teacher.display()
    );
    rejects(
        &dir,
        &words(&line),
        &["narrow.safetensors", "obs_dim 3", "teacher"],
    );
}

#[test]
fn the_checkpoint_is_saved_before_the_final_evaluation() {
    let dir = scratch("save-first");
    let good = Dataset::load(&fixture().join("d.safetensors")).unwrap();
    good.save(&dir.join("d.safetensors")).unwrap();
    // The fixture's tiny sizes, but with one evaluation episode at the end.
    let tiny = TINY.replace("--eval-episodes 0", "");
    let line = format!(
        "train teacher --data d.safetensors --out t --steps 4 --backbone mlp:8 --eval-episodes 1 \
         {tiny}"
    );
    let args = words(&line);
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
    let new = "collect --task reach --out new.safetensors";
    rejects_each(&[
        (
            "collect --task reach --out d.safetensors",
            &["--out d.safetensors", "exists", "--force"],
        ),
        ("collect --task reach --out t", &["--out t", "directory"]),
        (&format!("{new} --episodes 0"), &["--episodes 0"]),
        (&format!("{new} --episodes 1000000000000"), &["--episodes"]),
        (
            &format!("{new} --seed 9223372036854775800"),
            &["--seed", "2^63"],
        ),
        (&format!("{new} --perturb-std nan"), &["--perturb-std"]),
        (&format!("{new} --perturb-time 0"), &["--perturb-time"]),
        (
            "collect --task nosuchtask --out new.safetensors",
            &["nosuchtask"],
        ),
    ]);
}

#[test]
fn quickstart_never_replaces_a_run() {
    rejects_each(&[
        ("quickstart --out .", &["--out", "not empty", "--force"]),
        ("quickstart --out t --force --demos 0", &["--demos 0"]),
        (
            "quickstart --out new --teacher-steps 0",
            &["--teacher-steps 0"],
        ),
        ("quickstart --out new --batch 10000000", &["--batch"]),
        (
            "quickstart --out new --episodes 1000000000000",
            &["--episodes"],
        ),
        ("quickstart --out new --task nosuchtask", &["nosuchtask"]),
        ("quickstart --out s.blob", &["--out s.blob", "file"]),
    ]);
}

#[test]
fn probe_options_are_checked() {
    let probe = "train probe --ckpt t --data d.safetensors --holdout d.safetensors";
    rejects_each(&[
        (&format!("{probe} --windows 0"), &["--windows 0"]),
        (&format!("{probe} --steps 0"), &["--steps 0"]),
    ]);
}

/// On-policy distillation through the CLI: its counts are checked before training, a round
/// inside `train student` records the student's rollouts and says so in frmd.json, and
/// `collect --policy` writes rollouts that `--on-policy-data` takes.
#[test]
fn on_policy_rounds_and_recorded_rollouts_train_a_student() {
    rejects_train(&[
        ("student", "--on-policy-rounds 6", &["--on-policy-rounds 6"]),
        (
            "student",
            "--on-policy-episodes 0",
            &["--on-policy-episodes 0"],
        ),
        ("student", "--on-policy-weight=-1", &["--on-policy-weight"]),
        (
            "student",
            "--on-policy-data missing.safetensors",
            &["missing.safetensors"],
        ),
    ]);
    let dir = scratch("on-policy");
    let teacher = fixture().join("t");
    let student = |out: &str, extra: &str| {
        let line = format!(
            "train student --data {} --teacher {} --out {out} --steps 3 --batch 8 --warmup 1 \
             --eval-episodes 0 {extra}",
            fixture().join("d.safetensors").display(),
            teacher.display()
        );
        frmd_ok(&dir, &words(&line));
        let meta: serde_json::Value = serde_json::from_str(
            &std::fs::read_to_string(dir.join(out).join("frmd.json")).unwrap(),
        )
        .unwrap();
        meta["training"].clone()
    };
    let rounds = student("s1", "--on-policy-rounds 1 --on-policy-episodes 2");
    assert_eq!(rounds["on_policy_rounds"], 1, "{rounds}");
    let recorded = frmd_ok(
        &dir,
        &words("collect --task reach --policy s1 --episodes 2 --seed 7 --out r.safetensors"),
    );
    assert!(recorded.contains("every episode kept"), "{recorded}");
    assert_eq!(
        Dataset::load(&dir.join("r.safetensors"))
            .unwrap()
            .num_episodes(),
        2
    );
    let from_file = student("s2", "--on-policy-data r.safetensors");
    assert_eq!(
        from_file["on_policy_data"][0], "r.safetensors",
        "{from_file}"
    );
}
