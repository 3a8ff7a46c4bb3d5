//! An exported policy runs bit-identically on Cortex-M and on the host.
//!
//! The firmware `examples/cortex-m` (binary `frmd-cortex-m-policy`) exports the checked-in trained
//! student `examples/cortex-m/policy/reach/` with `export::export_checkpoint` and bakes it with
//! `bake::write_module` in its build.rs, then times `Policy::act` on QEMU. Here the same checkpoint
//! goes through the same export call (`frmd_firmware_support::host::student`), is written as a
//! blob, loaded with `frmd_core::blob::LoadedPolicy` and driven through the same workload;
//! `qemu_policy_digest_matches_host` requires the firmware's printed digest on mps2-an386
//! (Cortex-M4F) and mps2-an500 (Cortex-M7) to equal the host's. It needs `bash scripts/setup-cortex-m.sh` to have run (CI does that first); without
//! it, or with FRMD_SKIP_QEMU=1, it prints why and passes without checking
//! (unless FRMD_REQUIRE_QEMU is set, as in CI: then it fails).

use frmd_core::blob::LoadedPolicy;
use frmd_firmware_support::host::qemu;
use frmd_firmware_support::host::student::{student, AlignedBlob};
use frmd_firmware_support::policy_workload::PolicyWorkload;
use frmd_firmware_support::shape::{DOF, HORIZON, MLP_WIDTH, PARAMS, STUDENT_HISTORY, STUDENT_INPUT, STUDENT_OBS_DIM};
use frmd_firmware_support::workload::digest_all;

fn host_digest() -> u64 {
    let blob = AlignedBlob::of(&student());
    let loaded = LoadedPolicy::<STUDENT_HISTORY, STUDENT_OBS_DIM, DOF, HORIZON, PARAMS>::load(blob.bytes())
        .expect("load the blob");
    let policy = loaded
        .policy::<STUDENT_INPUT, MLP_WIDTH>()
        .expect("policy from the blob");
    let mut workload = PolicyWorkload::new(policy);
    digest_all(&mut workload).expect("run the fixed cases")
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
    let root = qemu::repo_root();
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
