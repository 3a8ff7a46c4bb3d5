//! An exported policy runs bit-identically on Cortex-M and on the host.
//!
//! The firmware `examples/cortex-m` (binary `frmd-cortex-m-policy`) exports the checked-in trained
//! student `examples/cortex-m/policy/reach/` with `export::export_checkpoint` and bakes it with
//! `bake::write_module` in its build.rs, then times `Policy::act` on QEMU. Here the same checkpoint
//! goes through the same export call, is written as a blob, loaded with
//! `frmd_core::blob::LoadedPolicy` and driven through the same workload file; `qemu_policy_digest_matches_host` requires the
//! firmware's printed digest on mps2-an386 (Cortex-M4F) and mps2-an500 (Cortex-M7) to equal the
//! host's. It needs `bash scripts/setup-cortex-m.sh` to have run (CI does that first); without
//! it, or with FRMD_SKIP_QEMU=1, it prints why and passes without checking
//! (unless FRMD_REQUIRE_QEMU is set, as in CI: then it fails).

#[allow(dead_code)]
#[path = "../../examples/cortex-m/src/digest.rs"]
mod digest;
#[allow(dead_code)]
#[path = "../../examples/cortex-m/src/policy_workload.rs"]
mod policy_workload;
#[path = "../../examples/cortex-m/src/shape.rs"]
mod shape;
#[allow(dead_code)] // `name` is printed by the firmware only
#[path = "../../examples/cortex-m/src/workload_api.rs"]
mod workload_api;

use std::path::{Path, PathBuf};
use std::process::Command;

use frmd_core::blob::LoadedPolicy;
use frmd_export::export::{export_checkpoint, ExportOptions};
use frmd_export::QuantizedPolicy;
use shape::{DOF, HORIZON, MLP_WIDTH, PARAMS, STUDENT_HISTORY, STUDENT_INPUT, STUDENT_OBS_DIM};

/// The student the firmware's build.rs bakes, exported with the same call and options.
fn student() -> QuantizedPolicy {
    let dir = Path::new(env!("CARGO_MANIFEST_DIR")).join("../examples/cortex-m/policy/reach");
    export_checkpoint(&dir, ExportOptions::default(), None).expect("export the checked-in student").policy
}

/// The blob in 16-byte aligned storage, as the loader requires.
fn aligned(blob: &[u8]) -> Vec<u128> {
    let mut words = vec![0_u128; blob.len().div_ceil(16)];
    bytemuck::cast_slice_mut::<u128, u8>(&mut words)[..blob.len()].copy_from_slice(blob);
    words
}

fn host_digest() -> u64 {
    let blob = frmd_export::blob::write(&student()).expect("write the blob");
    let words = aligned(&blob);
    let bytes = &bytemuck::cast_slice::<u128, u8>(&words)[..blob.len()];
    let loaded = LoadedPolicy::<STUDENT_HISTORY, STUDENT_OBS_DIM, DOF, HORIZON, PARAMS>::load(bytes)
        .expect("load the blob");
    let policy = loaded
        .policy::<STUDENT_INPUT, MLP_WIDTH>()
        .expect("policy from the blob");
    let mut workload = policy_workload::PolicyWorkload::new(policy);
    workload_api::digest_all(&mut workload).expect("run the fixed cases")
}

#[test]
fn student_export_is_deterministic_and_acts() {
    let policy = student();
    assert_eq!(policy, student());
    assert_eq!(policy.scratch_width(), MLP_WIDTH);
    assert_eq!((policy.history, policy.obs_dim, policy.action_dim), (STUDENT_HISTORY, STUDENT_OBS_DIM, DOF));
    assert_eq!(host_digest(), host_digest());
}

#[test]
fn qemu_policy_digest_matches_host() {
    let root = Path::new(env!("CARGO_MANIFEST_DIR")).join("..");
    let env_file = std::env::var_os("FRMD_CORTEX_M_ENV")
        .map(PathBuf::from)
        .unwrap_or_else(|| root.join("target/cortex-m.env"));
    let qemu_found = Command::new("qemu-system-arm").arg("--version").output().is_ok();
    if std::env::var_os("FRMD_SKIP_QEMU").is_some() || !env_file.exists() || !qemu_found {
        assert!(
            std::env::var_os("FRMD_REQUIRE_QEMU").is_none(),
            "FRMD_REQUIRE_QEMU is set but the QEMU check cannot run (env file {} present: {}, qemu-system-arm found: {qemu_found})",
            env_file.display(),
            env_file.exists()
        );
        eprintln!(
            "qemu_policy_digest_matches_host: SKIPPED (FRMD_SKIP_QEMU set, or no {} / \
             qemu-system-arm: run `bash scripts/setup-cortex-m.sh`)",
            env_file.display()
        );
        return;
    }
    let expected = format!("digest: {:016x}", host_digest());
    for board in ["m4", "m7"] {
        let output = Command::new("bash")
            .arg(root.join("examples/cortex-m/run-qemu.sh"))
            .args([board, "policy"])
            // The firmware's own target directory, shared with run-qemu.sh's default.
            .env("CARGO_TARGET_DIR", root.join("examples/cortex-m/target"))
            .output()
            .expect("run examples/cortex-m/run-qemu.sh");
        let stdout = String::from_utf8_lossy(&output.stdout);
        assert!(
            output.status.success(),
            "run-qemu.sh {board} policy failed:\n{stdout}\n{}",
            String::from_utf8_lossy(&output.stderr)
        );
        let digest_line = stdout.lines().find(|line| line.starts_with("digest: "));
        assert_eq!(
            digest_line,
            Some(expected.as_str()),
            "baked policy on {board} computed different bytes than the blob on the host:\n{stdout}"
        );
        eprintln!("policy {board}: {}", stdout.lines().collect::<Vec<_>>().join(" | "));
    }
}
