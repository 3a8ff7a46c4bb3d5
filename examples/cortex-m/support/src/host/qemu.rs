//! Running the firmware images under QEMU from a host test.
//!
//! A QEMU check runs only when `bash scripts/setup-cortex-m.sh` has written its env file
//! (`FRMD_CORTEX_M_ENV`, default `<repo>/target/cortex-m.env`), `qemu-system-arm` runs and
//! `FRMD_SKIP_QEMU` is unset. Otherwise the test prints why and passes without checking, unless
//! `FRMD_REQUIRE_QEMU` is set (as in CI): then it fails.

use std::path::{Path, PathBuf};
use std::process::Command;

/// The cores `run-qemu.sh` runs: Cortex-M4F, M7 (same ELF), M33 (DSP kernels), M0 (portable
/// kernels, soft float), M55 (the M33 code on its board).
pub const BOARDS: [&str; 5] = ["m4", "m7", "m33", "m0", "m55"];

/// [`BOARDS`] that hold the transformer image (779 KB of code and weights, 26 KiB of RAM): not
/// the microbit's M0 (256 KiB flash, 16 KiB RAM) nor the M55 board's 512 KiB code memory.
pub const TRANSFORMER_BOARDS: [&str; 3] = ["m4", "m7", "m33"];

/// The repository root (this crate sits at `examples/cortex-m/support`).
pub fn repo_root() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("../../..")
}

/// Whether the QEMU check named `test` can run. Returns `false` after printing why it is skipped;
/// panics instead when `FRMD_REQUIRE_QEMU` is set.
pub fn available(test: &str, root: &Path) -> bool {
    let env_file = std::env::var_os("FRMD_CORTEX_M_ENV")
        .map(PathBuf::from)
        .unwrap_or_else(|| root.join("target/cortex-m.env"));
    let qemu_found = Command::new("qemu-system-arm")
        .arg("--version")
        .output()
        .is_ok();
    if std::env::var_os("FRMD_SKIP_QEMU").is_some() || !env_file.exists() || !qemu_found {
        assert!(
            std::env::var_os("FRMD_REQUIRE_QEMU").is_none(),
            "FRMD_REQUIRE_QEMU is set but the QEMU check cannot run (env file {} present: {}, qemu-system-arm found: {qemu_found})",
            env_file.display(),
            env_file.exists()
        );
        eprintln!(
            "{test}: SKIPPED (FRMD_SKIP_QEMU set, or no {} / qemu-system-arm: run \
             `bash scripts/setup-cortex-m.sh`)",
            env_file.display()
        );
        return false;
    }
    true
}

/// Runs `examples/cortex-m/run-qemu.sh <board> <image>` and returns its standard output; panics
/// (with both outputs) if the script fails.
///
/// The firmware builds in its own target directory (run-qemu.sh's default), so manual runs and
/// tests share one build; it is never the directory of the `cargo test` running the caller.
pub fn run(root: &Path, board: &str, image: &str) -> String {
    run_with_env(root, board, image, &[])
}

/// [`run`] with extra environment variables for the build (e.g. `FRMD_MINIMAL_CHECKPOINT`).
pub fn run_with_env(root: &Path, board: &str, image: &str, env: &[(&str, &Path)]) -> String {
    let output = Command::new("bash")
        .arg(root.join("examples/cortex-m/run-qemu.sh"))
        .args([board, image])
        .env("CARGO_TARGET_DIR", root.join("examples/cortex-m/target"))
        .envs(env.iter().copied())
        .output()
        .expect("run examples/cortex-m/run-qemu.sh");
    let stdout = String::from_utf8_lossy(&output.stdout).into_owned();
    assert!(
        output.status.success(),
        "run-qemu.sh {board} {image} failed:\n{stdout}\n{}",
        String::from_utf8_lossy(&output.stderr)
    );
    stdout
}

/// The first `digest: <16 hex digits>` line the firmware printed, whole.
pub fn digest_line(stdout: &str) -> Option<&str> {
    stdout.lines().find(|line| line.starts_with("digest: "))
}

/// The value of the first `key: value` line of `stdout`.
pub fn line_value<'a>(stdout: &'a str, key: &str) -> Option<&'a str> {
    let prefix = format!("{key}: ");
    stdout
        .lines()
        .find_map(|line| line.strip_prefix(prefix.as_str()))
}

/// Runs `image` on each of `boards` and asserts that it prints `digest: ` with `host_digest`
/// (the bytes the host computed; `what` names them in the failure); logs every run on one line.
pub fn assert_digest_on(root: &Path, boards: &[&str], image: &str, host_digest: u64, what: &str) {
    let expected = format!("digest: {host_digest:016x}");
    for board in boards {
        let stdout = run(root, board, image);
        assert_eq!(
            digest_line(&stdout),
            Some(expected.as_str()),
            "{image} firmware on {board} computed different bytes than {what}:\n{stdout}"
        );
        eprintln!("{image} {board}: {}", one_line(&stdout));
    }
}

/// All output lines joined by ` | `, for one-line logging.
pub fn one_line(stdout: &str) -> String {
    stdout.lines().collect::<Vec<_>>().join(" | ")
}
