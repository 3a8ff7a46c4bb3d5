//! Bad input to `frmd eval`, `export`, `equiv` and `bench` (issue 14): each case fails before
//! any long work with one line naming the option, file or field, exit code 2, and no file
//! changed. Training, collection and the quick start are in `cli_bad_input_train.rs`.
mod cli_support;

use cli_support::{edited_checkpoint, fixture, frmd_ok, hash_tree, rejects, scratch, words};
use cli_support::{rejects_each, rejects_each_in};
use serde_json::json;

const U64_MAX: &str = "18446744073709551615";

#[test]
fn eval_options_are_checked_before_the_run() {
    rejects_each(&[
        // Counts are bounded.
        (
            "eval --task reach --blob s.blob --episodes 18446744073709551615",
            &["--episodes", U64_MAX, "1000000"],
        ),
        (
            "eval --task reach --episodes 1000000000000",
            &["--episodes"],
        ),
        ("eval --task reach --episodes 0", &["--episodes 0"]),
        (
            "eval --task reach --ckpt t --steps 18446744073709551615",
            &["--steps", "1000"],
        ),
        ("eval --task reach --ckpt t --steps 0", &["--steps 0"]),
        ("eval --task reach --ckpt dp --steps 0", &["--steps 0"]),
        (
            "eval --task reach --ckpt s --steps 5",
            &["--steps 5", "1 to 4"],
        ),
        ("eval --task reach --history 0", &["--history 0"]),
        ("eval --task reach --exec-steps 0", &["--exec-steps 0"]),
        // Seeds stay in the evaluation stream; the last is one past the last start that fits 50
        // episodes (2^63 - 50).
        (
            "eval --task reach --first-seed 9223372036854775808",
            &["--first-seed", "2^63"],
        ),
        (
            "eval --task reach --first-seed 18446744073709551615 --episodes 1",
            &["--first-seed"],
        ),
        (
            "eval --task reach --first-seed 9223372036854775759",
            &["--first-seed"],
        ),
        // Executed steps are at most the horizon.
        (
            "eval --task reach --blob s.blob --exec-steps 100",
            &["--exec-steps 100", "horizon 8"],
        ),
        (
            "eval --task reach --ckpt s --exec-steps 9",
            &["--exec-steps 9", "horizon 8"],
        ),
        (
            "eval --task reach --baked baked --exec-steps 12",
            &["--exec-steps 12"],
        ),
        // Conflicting options are named.
        (
            "eval --task reach --ckpt s --blob s.blob",
            &["--ckpt", "--blob"],
        ),
        (
            "eval --task reach --blob s.blob --baked baked",
            &["--blob", "--baked"],
        ),
        (
            "eval --task reach --policy expert --ckpt t",
            &["--policy", "--ckpt"],
        ),
        (
            "eval --task reach --blob s.blob --steps 2",
            &["--steps", "--blob"],
        ),
        (
            "eval --task reach --baked baked --solver heun",
            &["--solver", "--baked"],
        ),
        (
            "eval --task reach --ckpt s --solver heun",
            &["--solver", "student"],
        ),
        (
            "eval --task reach --ckpt dp --solver euler",
            &["--solver", "dp"],
        ),
        ("eval --task reach --solver euler", &["--solver", "expert"]),
        (
            "eval --task reach --ckpt t --history 3",
            &["--history", "--ckpt"],
        ),
        (
            "eval --task reach --plot-episodes 3",
            &["--plot-episodes", "--plot"],
        ),
        ("eval --task reach --policy nonsense", &["nonsense"]),
        ("eval --task nosuchtask", &["nosuchtask"]),
        // Outputs never replace a file without --force, nor an input even with it.
        (
            "eval --task reach --blob s.blob --json d.safetensors",
            &["--json", "exists", "--force"],
        ),
        (
            "eval --task reach --blob s.blob --json s.blob --force",
            &["--json", "input"],
        ),
        (
            "eval --task reach --ckpt s --json s/frmd.json --force",
            &["--json", "input"],
        ),
        (
            "eval --task reach --json d.safetensors/r.json",
            &["--json", "not a directory"],
        ),
        (
            "eval --task reach --plot d.safetensors/p.png",
            &["--plot", "not a directory"],
        ),
        ("eval --task reach --plot t", &["--plot", "directory"]),
        (
            "eval --task reach --json /proc/frmd-no-such-dir/r.json",
            &["--json", "not writable"],
        ),
    ]);
}

#[test]
fn eval_creates_missing_directories_and_never_clobbers() {
    // A missing directory is created, and the written report is whole.
    let dir = scratch("eval-json");
    let blob = fixture().join("s.blob");
    let eval = |episodes: u32, rest: &str| {
        format!(
            "eval --task reach --blob {} --episodes {episodes} --json new/sub/r.json {rest}",
            blob.display()
        )
    };
    let episodes_in_report = || {
        let text = std::fs::read_to_string(dir.join("new/sub/r.json")).unwrap();
        serde_json::from_str::<serde_json::Value>(&text).unwrap()["episodes"].clone()
    };
    frmd_ok(&dir, &words(&eval(2, "--plot new/p.png")));
    assert_eq!(episodes_in_report(), json!(2));
    assert!(dir.join("new/p.png").exists());
    let before = hash_tree(&dir);
    rejects(&dir, &words(&eval(2, "")), &["exists"]);
    assert_eq!(before, hash_tree(&dir));
    frmd_ok(&dir, &words(&eval(1, "--force")));
    assert_eq!(episodes_in_report(), json!(1));
    let leftovers: Vec<_> = std::fs::read_dir(dir.join("new/sub"))
        .unwrap()
        .map(|e| e.unwrap().file_name())
        .collect();
    assert_eq!(leftovers.len(), 1, "temporary files left: {leftovers:?}");
}

#[test]
fn export_refuses_existing_outputs_and_inputs() {
    rejects_each(&[
        (
            "export --ckpt s --blob s.blob",
            &["--blob", "exists", "--force"],
        ),
        (
            "export --ckpt s --blob s/model.safetensors --force",
            &["--blob", "input"],
        ),
        (
            "export --ckpt s --blob d.safetensors --data d.safetensors --force",
            &["--blob", "input"],
        ),
        (
            "export --ckpt s --out baked",
            &["--out", "not empty", "--force"],
        ),
        ("export --ckpt s --out s --force", &["--out", "input"]),
        ("export --ckpt s --out s.blob", &["--out", "file"]),
        ("export --ckpt s", &["nothing to write"]),
        ("export --ckpt s --blob x.blob --steps 0", &["--steps 0"]),
        ("export --ckpt s --blob x.blob --steps 9", &["--steps 9"]),
        (
            "export --ckpt s --blob x.blob --input-headroom 0.5",
            &["--input-headroom"],
        ),
        (
            "export --ckpt s --blob x.blob --calibration median",
            &["--calibration"],
        ),
        (
            "export --ckpt s --blob x.blob --save-calibration",
            &["--save-calibration", "--data"],
        ),
        ("export --ckpt t --blob x.blob", &["student", "teacher"]),
    ]);
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

/// Edits a checkpoint's `frmd.json`.
type Edit = fn(&mut serde_json::Value);

#[test]
fn checkpoint_config_errors_name_the_field() {
    let f = fixture();
    let dir = scratch("bad-ckpt");
    // (checkpoint edited, name of the copy, the edit, what `eval --ckpt NAME` must name)
    let cases: [(&str, &str, Edit, &[&str]); 11] = [
        (
            "s",
            "minmax",
            |j| {
                j["normalization"]["obs"]["min"][0] = json!(5.0);
                j["normalization"]["obs"]["max"][0] = json!(1.0);
            },
            &[
                "minmax",
                "frmd.json",
                "normalization.obs.min[0]",
                "min <= max",
            ],
        ),
        (
            "s",
            "short",
            |j| j["normalization"]["action"]["max"] = json!([1.0]),
            &["normalization.action.max", "expected 2"],
        ),
        (
            "t",
            "sigma",
            |j| j["sigma"]["sigma_max"] = json!(1e38),
            &["frmd.json", "sigma.sigma_max"],
        ),
        (
            "t",
            "sigmin",
            |j| j["sigma"]["sigma_min"] = json!(-1.0),
            &["sigma.sigma_min"],
        ),
        (
            "t",
            "horizon",
            |j| j["prodmp"]["tau"] = json!(9.0),
            &["frmd.json", "prodmp.tau", "expected"],
        ),
        (
            "t",
            "dt",
            |j| j["model"]["control_dt"] = json!(0.0),
            &["model.control_dt"],
        ),
        (
            "t",
            "huge",
            |j| j["model"]["obs_dim"] = json!(1u64 << 40),
            &["model.obs_dim"],
        ),
        (
            "t",
            "tensors",
            |j| j["tensors"][1]["shape"] = json!([3, 3]),
            &["tensors[1]", "mlp.layers."],
        ),
        (
            "t",
            "fewer",
            |j| {
                j["tensors"].as_array_mut().unwrap().pop();
            },
            &["not listed", "mlp.layers."],
        ),
        (
            "t",
            "missing",
            |j| {
                j["model"].as_object_mut().unwrap().remove("horizon");
            },
            &["frmd.json", "horizon"],
        ),
        (
            "t",
            "version",
            |j| j["format_version"] = json!(99),
            &["format_version 99"],
        ),
    ];
    for (from, name, edit, needles) in cases {
        edited_checkpoint(&f.join(from), &dir.join(name), edit);
        rejects(&dir, &["eval", "--task", "reach", "--ckpt", name], needles);
    }
    std::fs::write(dir.join("garbage.blob"), b"FRMD not really a blob").unwrap();
    rejects_each_in(
        &dir,
        &[
            (
                "export --ckpt minmax --blob m.blob",
                &["normalization.obs.min[0]"],
            ),
            ("eval --task reach --blob garbage.blob", &["garbage.blob"]),
            ("eval --task reach --ckpt nonexistent", &["nonexistent"]),
        ],
    );
}

#[test]
fn equiv_refuses_teachers_and_empty_checks() {
    rejects_each(&[
        (
            "equiv --ckpt t --baked baked",
            &["this is a teacher, not a student"],
        ),
        (
            "equiv --ckpt dp --baked baked",
            &["this is a dp, not a student"],
        ),
        (
            "equiv --ckpt s --baked baked --inputs 0 --random-requant 0",
            &["--inputs 0", "nothing"],
        ),
        (
            "equiv --ckpt s --baked baked --episodes 1000000000000",
            &["--episodes"],
        ),
        (
            "equiv --ckpt s --baked baked --max-f32-error nan",
            &["--max-f32-error"],
        ),
        (
            "equiv --ckpt s --baked baked --json d.safetensors",
            &["--json", "exists"],
        ),
        (
            "equiv --ckpt s --baked baked --json baked/policy.blob --force",
            &["--json", "input"],
        ),
    ]);
}

#[test]
fn bench_labels_the_core_rows_with_their_own_student() {
    rejects_each(&[
        ("bench --dir . --calls 0", &["--calls 0"]),
        (
            "bench --dir . --policy dp:10 --json d.safetensors",
            &["--json", "exists"],
        ),
    ]);
    let table = frmd_ok(
        fixture(),
        &words("bench --dir . --policy dp:10 --calls 3 --warmup 0"),
    );
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
