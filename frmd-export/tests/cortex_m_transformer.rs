//! transformer-lite runs bit-identically on Cortex-M and on the host.
//!
//! The firmware `examples/cortex-m` (binary `frmd-cortex-m-transformer`) bakes a synthetic int8
//! transformer-lite (`frmd_firmware_support::synthetic::transformer`) in its build.rs and runs
//! it as the network of the synthetic one-step policy's configuration (baked by frmd-export), timing `Policy::act` on
//! QEMU. Here the same backbone is regenerated in memory, the configuration comes from the blob
//! form of the same policy (`frmd_core::blob::LoadedMlp::config`), and the same workload
//! runs it; `qemu_transformer_digest_matches_host` requires the firmware's printed digest on
//! every board with the memory for it (Cortex-M4F, M7, M33) to equal the host's, and
//! `qemu_transformer_student_digests_match_host` does the same for the images that run a random
//! transformer-lite student from its exported blob with int8 and int16 activations
//! (`frmd-cortex-m-transformer-student[16]`). It needs
//! `bash scripts/setup-cortex-m.sh` to have run (CI does that first); without it, or with
//! FRMD_SKIP_QEMU=1, it prints why and passes without checking (unless FRMD_REQUIRE_QEMU is set,
//! as in CI: then it fails).

use frmd_core::blob::AlignedBlob;
use frmd_core::blob::LoadedMlp;
use frmd_core::policy::{Int8TransformerNetwork, Policy, PolicyError};
use frmd_firmware_support::host::qemu;
use frmd_firmware_support::policy_workload::PolicyWorkload;
use frmd_firmware_support::shape::{
    self, DOF, HORIZON, PARAMS, POLICY_HISTORY, POLICY_INPUT, POLICY_OBS_DIM, TRANSFORMER_SCRATCH,
};
use frmd_firmware_support::synthetic::{
    policy as synthetic_policy, transformer as synthetic_transformer,
};
use frmd_firmware_support::workload::digest_all;

type Scratch = frmd_core::model::transformer::TransformerScratch<
    { TRANSFORMER_SCRATCH.floats },
    { TRANSFORMER_SCRATCH.codes },
    { TRANSFORMER_SCRATCH.accumulators },
>;

type Network<'a> = Int8TransformerNetwork<'a, &'a mut Scratch>;

/// Digest of the fixed cases (and the first chunk's positions, to check they vary).
fn host_digest() -> Result<u64, PolicyError> {
    let blob = AlignedBlob::new(&synthetic_policy::generate().blob().expect("write the blob"));
    let loaded = LoadedMlp::load(blob.bytes()).expect("load the blob");
    let config = loaded.config();
    let data = synthetic_transformer::generate();
    let blocks = data.blocks();
    let mut scratch = Box::new(Scratch::new());
    let network = Network::new(
        data.model(&blocks),
        &config.sampler.layout,
        &[],
        &mut scratch,
    )
    .expect("the synthetic transformer validates");
    let policy =
        Policy::<_, POLICY_HISTORY, POLICY_OBS_DIM, DOF, HORIZON, PARAMS, POLICY_INPUT>::new(
            config, network,
        )?;
    let mut workload = PolicyWorkload::with_name(policy, "transformer");
    digest_all(&mut workload)
}

#[test]
fn synthetic_transformer_is_deterministic_and_acts() {
    let first = synthetic_transformer::generate();
    let second = synthetic_transformer::generate();
    assert_eq!(first.weight_bytes(), second.weight_bytes());
    assert_eq!(first.rust_source(), second.rust_source());
    // 3 x 12 W^2 block weights + traj_in + cond_in + head (T W x 42).
    let width = shape::TRANSFORMER_SHAPE.width;
    let expected = 3 * 12 * width * width
        + DOF * width
        + shape::TRANSFORMER_CONDITION * width
        + shape::TRANSFORMER_SHAPE.token_values() * DOF * PARAMS;
    assert_eq!(first.weight_bytes().len(), expected);
    let digest = host_digest().expect("the transformer policy acts on every case");
    assert_eq!(digest, host_digest().expect("second run"));
}

#[test]
fn transformer_network_rejects_a_non_standard_layout() {
    use frmd_core::policy::{InputLayout, InputSegment};
    let data = synthetic_transformer::generate();
    let blocks = data.blocks();
    let layout = InputLayout::new(
        &[
            InputSegment::NoisyTrajectory,
            InputSegment::ObsHistory,
            InputSegment::PrevAction,
            InputSegment::PrevRate,
        ],
        0.1,
    )
    .expect("a valid layout");
    let mut scratch = Box::new(Scratch::new());
    assert_eq!(
        Network::new(data.model(&blocks), &layout, &[], &mut scratch).err(),
        Some(PolicyError::TransformerLayout)
    );
}

#[test]
fn qemu_transformer_digest_matches_host() {
    let root = qemu::repo_root();
    if !qemu::available("qemu_transformer_digest_matches_host", &root) {
        return;
    }
    let digest = host_digest().expect("host digest");
    qemu::assert_digest_on(
        &root,
        &qemu::TRANSFORMER_BOARDS,
        "transformer",
        digest,
        "the host",
    );
}

/// Digest of the fixed cases for the random transformer-lite student exported with
/// `activations`, run from its blob as the `transformer-student` images run it.
fn student_digest(activations: frmd_export::Activations) -> u64 {
    use frmd_firmware_support::host::transformer_student;
    let dir = frmd_test_support::checkpoint::scratch_dir(&format!("tstudent-{activations}"));
    transformer_student::write(&dir);
    let student = transformer_student::export(&dir, activations);
    assert_eq!(student.activations(), activations);
    let blob = AlignedBlob::new(student.blob());
    let loaded = frmd_core::blob::LoadedBlob::load(blob.bytes()).expect("load the blob");
    assert_eq!(
        loaded.activation_bits(),
        if activations == frmd_export::Activations::Int16 {
            16
        } else {
            8
        }
    );
    let mut work = frmd_export::host::HostWork::new();
    let network = loaded
        .network::<POLICY_INPUT, _>(&mut work)
        .expect("the blob's network");
    let policy =
        Policy::<_, POLICY_HISTORY, POLICY_OBS_DIM, DOF, HORIZON, PARAMS, POLICY_INPUT>::new(
            loaded.config(),
            network,
        )
        .expect("the blob's policy");
    let mut workload = PolicyWorkload::with_name(policy, "transformer student");
    let digest = digest_all(&mut workload).expect("the student acts on every case");
    std::fs::remove_dir_all(&dir).unwrap();
    digest
}

#[test]
fn qemu_transformer_student_digests_match_host() {
    use frmd_export::Activations;
    let int8 = student_digest(Activations::Int8);
    let int16 = student_digest(Activations::Int16);
    assert_ne!(int8, int16, "int8 and int16 students gave the same chunks");
    assert_eq!(
        int16,
        student_digest(Activations::Int16),
        "not reproducible"
    );
    let root = qemu::repo_root();
    if !qemu::available("qemu_transformer_student_digests_match_host", &root) {
        return;
    }
    for (image, digest) in [
        ("transformer-student", int8),
        ("transformer-student16", int16),
    ] {
        qemu::assert_digest_on(&root, &qemu::TRANSFORMER_BOARDS, image, digest, "the host");
    }
}
