//! Bad input to `frmd eval`, `export`, `equiv` and `bench` (issue 14): each case fails before
//! any long work with one line naming the option, file or field, exit code 2, and no file
//! changed. Training, collection and the quick start are in `cli_bad_input_train.rs`.
mod cli_support;

use cli_support::{edited_checkpoint, fixture, frmd, frmd_ok, hash_tree, rejects, scratch};
use serde_json::json;

const U64_MAX: &str = "18446744073709551615";

#[test]
fn eval_counts_are_bounded() {
    let f = fixture();
    rejects(
        f,
        &[
            "eval",
            "--task",
            "reach",
            "--blob",
            "s.blob",
            "--episodes",
            U64_MAX,
        ],
        &["--episodes", U64_MAX, "1000000"],
    );
    rejects(
        f,
        &["eval", "--task", "reach", "--episodes", "1000000000000"],
        &["--episodes"],
    );
    rejects(
        f,
        &["eval", "--task", "reach", "--episodes", "0"],
        &["--episodes 0"],
    );
    rejects(
        f,
        &["eval", "--task", "reach", "--ckpt", "t", "--steps", U64_MAX],
        &["--steps", "1000"],
    );
    rejects(
        f,
        &["eval", "--task", "reach", "--ckpt", "t", "--steps", "0"],
        &["--steps 0"],
    );
    rejects(
        f,
        &["eval", "--task", "reach", "--ckpt", "dp", "--steps", "0"],
        &["--steps 0"],
    );
    rejects(
        f,
        &["eval", "--task", "reach", "--ckpt", "s", "--steps", "5"],
        &["--steps 5", "1 to 4"],
    );
    rejects(
        f,
        &["eval", "--task", "reach", "--history", "0"],
        &["--history 0"],
    );
    rejects(
        f,
        &["eval", "--task", "reach", "--exec-steps", "0"],
        &["--exec-steps 0"],
    );
}

#[test]
fn eval_seeds_stay_in_the_evaluation_stream() {
    let f = fixture();
    rejects(
        f,
        &[
            "eval",
            "--task",
            "reach",
            "--first-seed",
            "9223372036854775808",
        ],
        &["--first-seed", "2^63"],
    );
    rejects(
        f,
        &[
            "eval",
            "--task",
            "reach",
            "--first-seed",
            U64_MAX,
            "--episodes",
            "1",
        ],
        &["--first-seed"],
    );
    // One past the last start that fits 50 episodes (2^63 - 50).
    rejects(
        f,
        &[
            "eval",
            "--task",
            "reach",
            "--first-seed",
            "9223372036854775759",
        ],
        &["--first-seed"],
    );
}

#[test]
fn eval_exec_steps_are_at_most_the_horizon() {
    let f = fixture();
    rejects(
        f,
        &[
            "eval",
            "--task",
            "reach",
            "--blob",
            "s.blob",
            "--exec-steps",
            "100",
        ],
        &["--exec-steps 100", "horizon 8"],
    );
    rejects(
        f,
        &[
            "eval",
            "--task",
            "reach",
            "--ckpt",
            "s",
            "--exec-steps",
            "9",
        ],
        &["--exec-steps 9", "horizon 8"],
    );
    rejects(
        f,
        &[
            "eval",
            "--task",
            "reach",
            "--baked",
            "baked",
            "--exec-steps",
            "12",
        ],
        &["--exec-steps 12"],
    );
}

#[test]
fn eval_conflicting_options_are_named() {
    let f = fixture();
    rejects(
        f,
        &["eval", "--task", "reach", "--ckpt", "s", "--blob", "s.blob"],
        &["--ckpt", "--blob"],
    );
    rejects(
        f,
        &[
            "eval", "--task", "reach", "--blob", "s.blob", "--baked", "baked",
        ],
        &["--blob", "--baked"],
    );
    rejects(
        f,
        &[
            "eval", "--task", "reach", "--policy", "expert", "--ckpt", "t",
        ],
        &["--policy", "--ckpt"],
    );
    rejects(
        f,
        &[
            "eval", "--task", "reach", "--blob", "s.blob", "--steps", "2",
        ],
        &["--steps", "--blob"],
    );
    rejects(
        f,
        &[
            "eval", "--task", "reach", "--baked", "baked", "--solver", "heun",
        ],
        &["--solver", "--baked"],
    );
    rejects(
        f,
        &["eval", "--task", "reach", "--ckpt", "s", "--solver", "heun"],
        &["--solver", "student"],
    );
    rejects(
        f,
        &[
            "eval", "--task", "reach", "--ckpt", "dp", "--solver", "euler",
        ],
        &["--solver", "dp"],
    );
    rejects(
        f,
        &["eval", "--task", "reach", "--solver", "euler"],
        &["--solver", "expert"],
    );
    rejects(
        f,
        &["eval", "--task", "reach", "--ckpt", "t", "--history", "3"],
        &["--history", "--ckpt"],
    );
    rejects(
        f,
        &["eval", "--task", "reach", "--plot-episodes", "3"],
        &["--plot-episodes", "--plot"],
    );
    rejects(
        f,
        &["eval", "--task", "reach", "--policy", "nonsense"],
        &["nonsense"],
    );
    rejects(f, &["eval", "--task", "nosuchtask"], &["nosuchtask"]);
}

#[test]
fn eval_outputs_are_checked_before_the_run_and_never_clobber() {
    let f = fixture();
    rejects(
        f,
        &[
            "eval",
            "--task",
            "reach",
            "--blob",
            "s.blob",
            "--json",
            "d.safetensors",
        ],
        &["--json", "exists", "--force"],
    );
    rejects(
        f,
        &[
            "eval", "--task", "reach", "--blob", "s.blob", "--json", "s.blob", "--force",
        ],
        &["--json", "input"],
    );
    rejects(
        f,
        &[
            "eval",
            "--task",
            "reach",
            "--ckpt",
            "s",
            "--json",
            "s/frmd.json",
            "--force",
        ],
        &["--json", "input"],
    );
    rejects(
        f,
        &["eval", "--task", "reach", "--json", "d.safetensors/r.json"],
        &["--json", "not a directory"],
    );
    rejects(
        f,
        &["eval", "--task", "reach", "--plot", "d.safetensors/p.png"],
        &["--plot", "not a directory"],
    );
    rejects(
        f,
        &["eval", "--task", "reach", "--plot", "t"],
        &["--plot", "directory"],
    );
    rejects(
        f,
        &[
            "eval",
            "--task",
            "reach",
            "--json",
            "/proc/frmd-no-such-dir/r.json",
        ],
        &["--json", "not writable"],
    );
    // A missing directory is created, and the written report is whole.
    let dir = scratch("eval-json");
    let blob = fixture().join("s.blob");
    frmd_ok(
        &dir,
        &[
            "eval",
            "--task",
            "reach",
            "--blob",
            blob.to_str().unwrap(),
            "--episodes",
            "2",
            "--json",
            "new/sub/r.json",
            "--plot",
            "new/p.png",
        ],
    );
    let report: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(dir.join("new/sub/r.json")).unwrap())
            .unwrap();
    assert_eq!(report["episodes"], json!(2));
    assert!(dir.join("new/p.png").exists());
    let before = hash_tree(&dir);
    rejects(
        &dir,
        &[
            "eval",
            "--task",
            "reach",
            "--blob",
            blob.to_str().unwrap(),
            "--episodes",
            "2",
            "--json",
            "new/sub/r.json",
        ],
        &["exists"],
    );
    assert_eq!(before, hash_tree(&dir));
    frmd_ok(
        &dir,
        &[
            "eval",
            "--task",
            "reach",
            "--blob",
            blob.to_str().unwrap(),
            "--episodes",
            "1",
            "--json",
            "new/sub/r.json",
            "--force",
        ],
    );
    let report: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(dir.join("new/sub/r.json")).unwrap())
            .unwrap();
    assert_eq!(report["episodes"], json!(1));
    let leftovers: Vec<_> = std::fs::read_dir(dir.join("new/sub"))
        .unwrap()
        .map(|e| e.unwrap().file_name())
        .collect();
    assert_eq!(leftovers.len(), 1, "temporary files left: {leftovers:?}");
}

#[test]
fn export_refuses_existing_outputs_and_inputs() {
    let f = fixture();
    rejects(
        f,
        &["export", "--ckpt", "s", "--blob", "s.blob"],
        &["--blob", "exists", "--force"],
    );
    rejects(
        f,
        &[
            "export",
            "--ckpt",
            "s",
            "--blob",
            "s/model.safetensors",
            "--force",
        ],
        &["--blob", "input"],
    );
    rejects(
        f,
        &[
            "export",
            "--ckpt",
            "s",
            "--blob",
            "d.safetensors",
            "--data",
            "d.safetensors",
            "--force",
        ],
        &["--blob", "input"],
    );
    rejects(
        f,
        &["export", "--ckpt", "s", "--out", "baked"],
        &["--out", "not empty", "--force"],
    );
    rejects(
        f,
        &["export", "--ckpt", "s", "--out", "s", "--force"],
        &["--out", "input"],
    );
    rejects(
        f,
        &["export", "--ckpt", "s", "--out", "s.blob"],
        &["--out", "file"],
    );
    rejects(f, &["export", "--ckpt", "s"], &["nothing to write"]);
    rejects(
        f,
        &["export", "--ckpt", "s", "--blob", "x.blob", "--steps", "0"],
        &["--steps 0"],
    );
    rejects(
        f,
        &["export", "--ckpt", "s", "--blob", "x.blob", "--steps", "9"],
        &["--steps 9"],
    );
    rejects(
        f,
        &[
            "export",
            "--ckpt",
            "s",
            "--blob",
            "x.blob",
            "--input-headroom",
            "0.5",
        ],
        &["--input-headroom"],
    );
    rejects(
        f,
        &[
            "export",
            "--ckpt",
            "s",
            "--blob",
            "x.blob",
            "--calibration",
            "median",
        ],
        &["--calibration"],
    );
    rejects(
        f,
        &[
            "export",
            "--ckpt",
            "s",
            "--blob",
            "x.blob",
            "--save-calibration",
        ],
        &["--save-calibration", "--data"],
    );
    rejects(
        f,
        &["export", "--ckpt", "t", "--blob", "x.blob"],
        &["student", "teacher"],
    );
}

#[test]
fn export_with_force_replaces_atomically() {
    let dir = scratch("export-force");
    let ckpt = fixture().join("s");
    let ckpt = ckpt.to_str().unwrap();
    std::fs::write(dir.join("p.blob"), b"old contents").unwrap();
    frmd_ok(
        &dir,
        &["export", "--ckpt", ckpt, "--blob", "p.blob", "--force"],
    );
    assert_eq!(
        std::fs::read(dir.join("p.blob")).unwrap(),
        std::fs::read(fixture().join("s.blob")).unwrap()
    );
    // A write cut short (file-size limit) leaves the previous blob whole and no temporary file.
    std::fs::write(dir.join("q.blob"), b"previous blob").unwrap();
    let script = format!(
        "trap '' XFSZ; ulimit -f 1; exec {} export --ckpt {ckpt} --blob q.blob --force",
        env!("CARGO_BIN_EXE_frmd")
    );
    let out = std::process::Command::new("sh")
        .arg("-c")
        .arg(&script)
        .current_dir(&dir)
        .output()
        .unwrap();
    assert_eq!(
        out.status.code(),
        Some(2),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    assert_eq!(std::fs::read(dir.join("q.blob")).unwrap(), b"previous blob");
    let names: Vec<_> = std::fs::read_dir(&dir)
        .unwrap()
        .map(|e| e.unwrap().file_name().into_string().unwrap())
        .collect();
    assert_eq!(names.len(), 2, "left behind: {names:?}");
}

#[test]
fn checkpoint_config_errors_name_the_field() {
    let f = fixture();
    let dir = scratch("bad-ckpt");
    edited_checkpoint(&f.join("s"), &dir.join("minmax"), |j| {
        j["normalization"]["obs"]["min"][0] = json!(5.0);
        j["normalization"]["obs"]["max"][0] = json!(1.0);
    });
    rejects(
        &dir,
        &["eval", "--task", "reach", "--ckpt", "minmax"],
        &[
            "minmax",
            "frmd.json",
            "normalization.obs.min[0]",
            "min <= max",
        ],
    );
    rejects(
        &dir,
        &["export", "--ckpt", "minmax", "--blob", "m.blob"],
        &["normalization.obs.min[0]"],
    );
    edited_checkpoint(&f.join("s"), &dir.join("short"), |j| {
        j["normalization"]["action"]["max"] = json!([1.0]);
    });
    rejects(
        &dir,
        &["eval", "--task", "reach", "--ckpt", "short"],
        &["normalization.action.max", "expected 2"],
    );
    edited_checkpoint(&f.join("t"), &dir.join("sigma"), |j| {
        j["sigma"]["sigma_max"] = json!(1e38)
    });
    rejects(
        &dir,
        &["eval", "--task", "reach", "--ckpt", "sigma"],
        &["frmd.json", "sigma.sigma_max"],
    );
    edited_checkpoint(&f.join("t"), &dir.join("sigmin"), |j| {
        j["sigma"]["sigma_min"] = json!(-1.0)
    });
    rejects(
        &dir,
        &["eval", "--task", "reach", "--ckpt", "sigmin"],
        &["sigma.sigma_min"],
    );
    edited_checkpoint(&f.join("t"), &dir.join("horizon"), |j| {
        j["prodmp"]["tau"] = json!(9.0)
    });
    rejects(
        &dir,
        &["eval", "--task", "reach", "--ckpt", "horizon"],
        &["frmd.json", "prodmp.tau", "expected"],
    );
    edited_checkpoint(&f.join("t"), &dir.join("dt"), |j| {
        j["model"]["control_dt"] = json!(0.0)
    });
    rejects(
        &dir,
        &["eval", "--task", "reach", "--ckpt", "dt"],
        &["model.control_dt"],
    );
    edited_checkpoint(&f.join("t"), &dir.join("huge"), |j| {
        j["model"]["obs_dim"] = json!(1u64 << 40)
    });
    rejects(
        &dir,
        &["eval", "--task", "reach", "--ckpt", "huge"],
        &["model.obs_dim"],
    );
    edited_checkpoint(&f.join("t"), &dir.join("tensors"), |j| {
        j["tensors"][1]["shape"] = json!([3, 3])
    });
    rejects(
        &dir,
        &["eval", "--task", "reach", "--ckpt", "tensors"],
        &["tensors[1]", "mlp.layers."],
    );
    edited_checkpoint(&f.join("t"), &dir.join("fewer"), |j| {
        j["tensors"].as_array_mut().unwrap().pop();
    });
    rejects(
        &dir,
        &["eval", "--task", "reach", "--ckpt", "fewer"],
        &["not listed", "mlp.layers."],
    );
    edited_checkpoint(&f.join("t"), &dir.join("missing"), |j| {
        j["model"].as_object_mut().unwrap().remove("horizon");
    });
    rejects(
        &dir,
        &["eval", "--task", "reach", "--ckpt", "missing"],
        &["frmd.json", "horizon"],
    );
    edited_checkpoint(&f.join("t"), &dir.join("version"), |j| {
        j["format_version"] = json!(99)
    });
    rejects(
        &dir,
        &["eval", "--task", "reach", "--ckpt", "version"],
        &["format_version 99"],
    );
    std::fs::write(dir.join("garbage.blob"), b"FRMD not really a blob").unwrap();
    rejects(
        &dir,
        &["eval", "--task", "reach", "--blob", "garbage.blob"],
        &["garbage.blob"],
    );
    rejects(
        &dir,
        &["eval", "--task", "reach", "--ckpt", "nonexistent"],
        &["nonexistent"],
    );
}

#[test]
fn equiv_refuses_teachers_and_empty_checks() {
    let f = fixture();
    rejects(
        f,
        &["equiv", "--ckpt", "t", "--baked", "baked"],
        &["this is a teacher, not a student"],
    );
    rejects(
        f,
        &["equiv", "--ckpt", "dp", "--baked", "baked"],
        &["this is a dp, not a student"],
    );
    rejects(
        f,
        &[
            "equiv",
            "--ckpt",
            "s",
            "--baked",
            "baked",
            "--inputs",
            "0",
            "--random-requant",
            "0",
        ],
        &["--inputs 0", "nothing"],
    );
    rejects(
        f,
        &[
            "equiv",
            "--ckpt",
            "s",
            "--baked",
            "baked",
            "--episodes",
            "1000000000000",
        ],
        &["--episodes"],
    );
    rejects(
        f,
        &[
            "equiv",
            "--ckpt",
            "s",
            "--baked",
            "baked",
            "--max-f32-error",
            "nan",
        ],
        &["--max-f32-error"],
    );
    rejects(
        f,
        &[
            "equiv",
            "--ckpt",
            "s",
            "--baked",
            "baked",
            "--json",
            "d.safetensors",
        ],
        &["--json", "exists"],
    );
    rejects(
        f,
        &[
            "equiv",
            "--ckpt",
            "s",
            "--baked",
            "baked",
            "--json",
            "baked/policy.blob",
            "--force",
        ],
        &["--json", "input"],
    );
}

#[test]
fn bench_labels_the_core_rows_with_their_own_student() {
    let f = fixture();
    rejects(f, &["bench", "--dir", ".", "--calls", "0"], &["--calls 0"]);
    rejects(
        f,
        &[
            "bench",
            "--dir",
            ".",
            "--policy",
            "dp:10",
            "--json",
            "d.safetensors",
        ],
        &["--json", "exists"],
    );
    let out = frmd(
        f,
        &[
            "bench", "--dir", ".", "--policy", "dp:10", "--calls", "3", "--warmup", "0",
        ],
    );
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let table = String::from_utf8_lossy(&out.stdout);
    let core: Vec<&str> = table
        .lines()
        .filter(|l| l.starts_with("frmd-core"))
        .collect();
    assert!(!core.is_empty(), "{table}");
    for line in core {
        assert!(
            line.contains("mlp[16]") && line.contains("./student"),
            "core row not labelled with the student's backbone: {line}"
        );
    }
    let dp = table.lines().find(|l| l.starts_with("candle dp")).unwrap();
    assert!(dp.contains("mlp[8]"), "{dp}");
}
