//! Shared by the `cli_bad_input*` tests: a tiny fixture built with the `frmd` binary itself
//! (a few demonstrations, a teacher, a student, a DP model and their exports, all trained for a
//! handful of steps: well under a second), a runner, and the check every bad-input case makes
//! (clean exit code, one-line error naming what is wrong, no file changed).
#![allow(dead_code)]
use std::collections::BTreeMap;
use std::path::{Path, PathBuf};
use std::process::{Command, Output};
use std::sync::OnceLock;

/// Tiny model sizes shared by every fixture model.
pub const TINY: &str =
    "--batch 8 --warmup 1 --eval-episodes 0 --horizon 8 --num-basis 4 --embed-dim 4";

/// The words of a command line, split at white space (the tests' paths have none).
pub fn words(line: &str) -> Vec<&str> {
    line.split_whitespace().collect()
}

/// Runs `frmd args` in `cwd` with one candle thread.
pub fn frmd(cwd: &Path, args: &[&str]) -> Output {
    Command::new(env!("CARGO_BIN_EXE_frmd"))
        .args(args)
        .current_dir(cwd)
        .env("RAYON_NUM_THREADS", "1")
        .output()
        .expect("the frmd binary runs")
}

/// Runs `frmd args` and asserts success.
pub fn frmd_ok(cwd: &Path, args: &[&str]) -> String {
    let out = frmd(cwd, args);
    assert!(
        out.status.success(),
        "frmd {args:?} failed: {}",
        String::from_utf8_lossy(&out.stderr)
    );
    String::from_utf8_lossy(&out.stdout).into_owned()
}

/// The fixture directory (built once per test binary):
/// `d.safetensors` (reach), `t` (teacher), `s` (student), `dp`, `baked` + `s.blob` (export of
/// `s`), `student` (a copy of `s`, for `bench --dir`).
pub fn fixture() -> &'static Path {
    static DIR: OnceLock<PathBuf> = OnceLock::new();
    DIR.get_or_init(|| {
        let dir =
            std::env::temp_dir().join(format!("frmd-cli-bad-{}-{}", std::process::id(), exe_tag()));
        let _ = std::fs::remove_dir_all(&dir);
        std::fs::create_dir_all(&dir).unwrap();
        for line in [
            "collect --task reach --episodes 3 --out d.safetensors".to_string(),
            format!("train teacher --data d.safetensors --out t --steps 5 --backbone mlp:16 {TINY}"),
            "train student --data d.safetensors --out s --teacher t --steps 5 --batch 8 --warmup 1 \
             --eval-episodes 0"
                .to_string(),
            format!("train dp --data d.safetensors --out dp --steps 5 --backbone mlp:8 {TINY}"),
            "export --ckpt s --out baked --blob s.blob".to_string(),
        ] {
            frmd_ok(&dir, &words(&line));
        }
        copy_dir(&dir.join("s"), &dir.join("student"));
        dir
    })
}

/// A name per test binary, so two test files do not share (and race on) one directory.
fn exe_tag() -> String {
    std::env::current_exe()
        .ok()
        .and_then(|p| p.file_stem().map(|s| s.to_string_lossy().into_owned()))
        .unwrap_or_default()
}

pub fn copy_dir(from: &Path, to: &Path) {
    std::fs::create_dir_all(to).unwrap();
    for entry in std::fs::read_dir(from).unwrap() {
        let entry = entry.unwrap();
        std::fs::copy(entry.path(), to.join(entry.file_name())).unwrap();
    }
}

/// A fresh scratch directory inside the fixture's parent for cases that write.
pub fn scratch(name: &str) -> PathBuf {
    let dir = std::env::temp_dir().join(format!(
        "frmd-cli-scratch-{}-{}-{name}",
        std::process::id(),
        exe_tag()
    ));
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(&dir).unwrap();
    dir
}

/// FNV-1a of every file under `dir` by relative path (what "no file changed" compares). The
/// write probes of `frmd_formats::artifact` (created and removed at once by an `frmd` that another
/// test runs in the same fixture directory at the same time) are not files of the tree.
pub fn hash_tree(dir: &Path) -> BTreeMap<PathBuf, u64> {
    let mut out = BTreeMap::new();
    let mut stack = vec![dir.to_path_buf()];
    while let Some(d) = stack.pop() {
        for entry in std::fs::read_dir(&d).unwrap() {
            let path = entry.unwrap().path();
            if path
                .file_name()
                .is_some_and(|n| n.to_string_lossy().starts_with(".frmd-write-probe-"))
            {
                continue;
            }
            if path.is_dir() {
                out.insert(path.strip_prefix(dir).unwrap().to_path_buf(), 0);
                stack.push(path);
            } else {
                let bytes = std::fs::read(&path).unwrap();
                let hash = bytes.iter().fold(0xcbf2_9ce4_8422_2325u64, |h, &b| {
                    (h ^ u64::from(b)).wrapping_mul(0x100_0000_01b3)
                });
                out.insert(path.strip_prefix(dir).unwrap().to_path_buf(), hash);
            }
        }
    }
    out
}

/// Runs `frmd args` in `cwd` and asserts the bad-input contract: exit code 2 (an error, not a
/// panic 101 or an abort 134), a single line `error: ...` on stderr containing every one of
/// `needles`, and no file under `cwd` created, removed or changed.
pub fn rejects(cwd: &Path, args: &[&str], needles: &[&str]) {
    let before = hash_tree(cwd);
    let out = frmd(cwd, args);
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert_eq!(
        out.status.code(),
        Some(2),
        "frmd {args:?}: exit {:?}, stderr: {stderr}",
        out.status
    );
    let lines: Vec<&str> = stderr.lines().filter(|l| !l.trim().is_empty()).collect();
    assert_eq!(
        lines.len(),
        1,
        "frmd {args:?}: expected one error line, got: {stderr}"
    );
    assert!(lines[0].starts_with("error: "), "frmd {args:?}: {stderr}");
    assert!(
        lines[0].len() < 400,
        "frmd {args:?}: error line too long ({} chars): {stderr}",
        lines[0].len()
    );
    for needle in needles {
        assert!(
            lines[0].contains(needle),
            "frmd {args:?}: error does not mention {needle:?}: {stderr}"
        );
    }
    assert_eq!(
        before,
        hash_tree(cwd),
        "frmd {args:?} changed files in {}",
        cwd.display()
    );
}

/// [`rejects`] for each `(command line, needles)` case in turn, all in `cwd`.
pub fn rejects_each_in(cwd: &Path, cases: &[(&str, &[&str])]) {
    for (line, needles) in cases {
        rejects(cwd, &words(line), needles);
    }
}

/// [`rejects_each_in`] the [`fixture`] directory.
pub fn rejects_each(cases: &[(&str, &[&str])]) {
    rejects_each_in(fixture(), cases);
}

/// Writes a copy of checkpoint `from` to `to` with `frmd.json` edited by `edit`.
pub fn edited_checkpoint(from: &Path, to: &Path, edit: impl FnOnce(&mut serde_json::Value)) {
    copy_dir(from, to);
    let path = to.join("frmd.json");
    let mut json: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(&path).unwrap()).unwrap();
    edit(&mut json);
    std::fs::write(&path, serde_json::to_string_pretty(&json).unwrap()).unwrap();
}
