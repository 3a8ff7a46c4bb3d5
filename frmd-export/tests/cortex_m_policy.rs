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
#[path = "../../examples/cortex-m/host-test-support.rs"]
mod qemu;

use std::path::Path;

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
    let root = qemu::repo_root(env!("CARGO_MANIFEST_DIR"));
    if !qemu::available("qemu_policy_digest_matches_host", &root) {
        return;
    }
    let expected = format!("digest: {:016x}", host_digest());
    for board in ["m4", "m7"] {
        let stdout = qemu::run(&root, board, "policy");
        let digest_line = qemu::digest_line(&stdout);
        assert_eq!(
            digest_line,
            Some(expected.as_str()),
            "baked policy on {board} computed different bytes than the blob on the host:\n{stdout}"
        );
        eprintln!("policy {board}: {}", qemu::one_line(&stdout));
    }
}
