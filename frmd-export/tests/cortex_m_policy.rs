//! An exported policy runs bit-identically on Cortex-M and on the host.
//!
//! The firmware `examples/cortex-m` (binary `frmd-cortex-m-policy`) exports the checked-in trained
//! student `examples/cortex-m/policy/reach/` with `frmd_export::export` and bakes it with
//! `ExportedStudent::write_module` in its build.rs, then times `Policy::act` on QEMU. Here the same checkpoint
//! goes through the same export call (`frmd_firmware_support::host::student`), is written as a
//! blob, loaded with `frmd_core::blob::LoadedMlp` and driven through the same workload;
//! `qemu_policy_digest_matches_host` requires the firmware's printed digest on every board of
//! `run-qemu.sh` (Cortex-M4F, M7, M33, M0, M55) to equal the host's. It needs `bash scripts/setup-cortex-m.sh` to have run (CI does that first); without
//! it, or with FRMD_SKIP_QEMU=1, it prints why and passes without checking
//! (unless FRMD_REQUIRE_QEMU is set, as in CI: then it fails).

use frmd_core::blob::AlignedBlob;
use frmd_core::blob::{LoadedMlp, LoadedMlp16};
use frmd_firmware_support::host::qemu;
use frmd_firmware_support::host::student::{student, student_export_as};
use frmd_firmware_support::policy_workload::PolicyWorkload;
use frmd_firmware_support::shape::{
    DOF, HORIZON, MLP_WIDTH, PARAMS, STUDENT_HISTORY, STUDENT_INPUT, STUDENT_OBS_DIM,
};
use frmd_firmware_support::workload::digest_all;

fn host_digest() -> u64 {
    let blob = AlignedBlob::new(&student().blob().expect("write the blob"));
    let loaded = LoadedMlp::load(blob.bytes()).expect("load the blob");
    let policy = loaded
        .policy::<STUDENT_HISTORY, STUDENT_OBS_DIM, DOF, HORIZON, PARAMS, STUDENT_INPUT, MLP_WIDTH>(
        )
        .expect("policy from the blob");
    let mut workload = PolicyWorkload::new(policy);
    digest_all(&mut workload).expect("run the fixed cases")
}

/// The host digest of the `policy16` image: the student exported with int16 activations.
fn host_digest16() -> u64 {
    let exported = student_export_as(frmd_export::Activations::Int16);
    let blob = AlignedBlob::new(exported.blob());
    let loaded = LoadedMlp16::load(blob.bytes()).expect("load the int16 blob");
    let policy = loaded
        .policy::<STUDENT_HISTORY, STUDENT_OBS_DIM, DOF, HORIZON, PARAMS, STUDENT_INPUT, MLP_WIDTH>(
        )
        .expect("policy from the blob");
    let mut workload = PolicyWorkload::new(policy);
    digest_all(&mut workload).expect("run the fixed cases")
}

#[test]
fn student_export_is_deterministic_and_acts() {
    let policy = student();
    assert_eq!(policy, student());
    assert_eq!(policy.scratch_width(), MLP_WIDTH);
    assert_eq!(
        (policy.history, policy.obs_dim, policy.action_dim),
        (STUDENT_HISTORY, STUDENT_OBS_DIM, DOF)
    );
    assert_eq!(host_digest(), host_digest());
}

/// The default 16-bit first-layer input is no less accurate than the two-plane input it replaced:
/// int8 network against the folded f32 model on the student's own calibration conditions
/// (network outputs, normalized units), and on the same inputs with the observations at three
/// times their calibrated magnitude (closed-loop states the demonstrations never reached).
#[test]
fn student_sixteen_bit_input_is_as_accurate_as_two_planes() {
    use frmd_core::model::mlp::{InputPrecision, Probe};
    use frmd_core::policy::Network;
    use frmd_export::ExportOptions;
    let dir = frmd_firmware_support::host::student::student_dir();
    let export = |input_precision| {
        let options = ExportOptions {
            input_precision,
            activations: Some(frmd_export::Activations::Int8),
            ..Default::default()
        };
        let student = frmd_export::export(&dir, &options, None).expect("export the student");
        student.mlp().expect("an MLP student").clone()
    };
    let (wide, two) = (
        export(InputPrecision::Int16),
        export(InputPrecision::TwoPlane),
    );
    let set = frmd_export::formats::calibration::read(
        &dir.join("calibration.safetensors"),
        wide.folded.base.config.cond_dim(),
    )
    .expect("calibration rows");
    let mut nets = [
        frmd_export::mlp::reference::quantized_network::<i8, MLP_WIDTH>(&wide.policy).unwrap(),
        frmd_export::mlp::reference::quantized_network::<i8, MLP_WIDTH>(&two.policy).unwrap(),
    ];
    let traj = wide.policy.horizon * wide.policy.action_dim;
    let mut errors = [[0_f64; 2]; 2];
    for row in 0..set.rows() {
        let mut input = Vec::new();
        wide.folded
            .sample(
                set.row(row),
                &set.noise(row, 1, traj),
                |_, probe, values| {
                    if probe == Probe::Input {
                        input = values.to_vec()
                    }
                },
            )
            .unwrap();
        let mut beyond = input.clone();
        for v in beyond
            .iter_mut()
            .take(wide.policy.history * wide.policy.obs_dim)
        {
            *v *= 3.0;
        }
        for (case, input) in [input, beyond].iter().enumerate() {
            let float = wide.folded.forward_observed(0, input, |_, _| {}).unwrap();
            for (error, net) in errors[case].iter_mut().zip(nets.iter_mut()) {
                let mut out = vec![0_f32; float.len()];
                net.forward(0, input, &mut out).unwrap();
                *error += out
                    .iter()
                    .zip(&float)
                    .map(|(a, f)| f64::from((a - f).abs()))
                    .sum::<f64>();
            }
        }
    }
    eprintln!(
        "int8 vs f32 abs error sums (16-bit, two-plane): in range {:?}, observations x3 {:?}",
        errors[0], errors[1]
    );
    for [sixteen_bit, two_plane] in errors {
        assert!(
            sixteen_bit <= 1.02 * two_plane,
            "16-bit {sixteen_bit} vs two-plane {two_plane}"
        );
    }
}

/// The minimal example (`examples/cortex-m/minimal`, `run-qemu.sh CORE minimal`) acts like the
/// host on every core: same inputs (last action 0.05, observation `0.1 step`), same noise seed,
/// the first action's bits.
#[test]
fn qemu_minimal_example_acts_like_the_host() {
    let root = qemu::repo_root();
    if !qemu::available("qemu_minimal_example_acts_like_the_host", &root) {
        return;
    }
    // The minimal example bakes the student as `frmd export` does by default.
    let dir = frmd_firmware_support::host::student::student_dir();
    let exported = frmd_export::export(&dir, &frmd_export::ExportOptions::default(), None)
        .expect("export the student");
    let blob = AlignedBlob::new(exported.blob());
    let loaded = frmd_core::blob::LoadedBlob::load(blob.bytes()).expect("load the blob");
    let mut work = frmd_export::host::HostWork::new();
    let network = loaded
        .network::<MLP_WIDTH, _>(&mut work)
        .expect("network from the blob");
    let mut policy = frmd_core::policy::Policy::<
        _,
        STUDENT_HISTORY,
        STUDENT_OBS_DIM,
        DOF,
        HORIZON,
        PARAMS,
        STUDENT_INPUT,
    >::new(loaded.config(), network)
    .expect("policy from the blob");
    policy.reset(&[0.05; DOF]).unwrap();
    for step in 0..STUDENT_HISTORY {
        policy
            .observe(&[0.1 * step as f32; STUDENT_OBS_DIM])
            .unwrap();
    }
    let chunk = *policy
        .act(frmd_core::policy::Noise::Rng(
            &mut frmd_core::rng::Rng::new(2024),
        ))
        .unwrap();
    let expected: Vec<String> = chunk.positions[0]
        .iter()
        .map(|v| format!("(bits {:08x})", v.to_bits()))
        .collect();
    for board in qemu::BOARDS {
        let stdout = qemu::run(&root, board, "minimal");
        let got: Vec<String> = stdout
            .lines()
            .filter(|line| line.starts_with("first action, dof "))
            .filter_map(|line| line.find("(bits").map(|bits| line[bits..].to_string()))
            .collect();
        assert_eq!(got, expected, "minimal example on {board}:\n{stdout}");
    }
}

#[test]
fn qemu_policy_digest_matches_host() {
    let root = qemu::repo_root();
    if !qemu::available("qemu_policy_digest_matches_host", &root) {
        return;
    }
    let what = "the blob on the host";
    qemu::assert_digest_on(&root, &qemu::BOARDS, "policy", host_digest(), what);
}

/// The int16-activation student: the same digest on every core as its blob on the host (and
/// not the int8 student's).
#[test]
fn qemu_policy16_digest_matches_host() {
    let host = host_digest16();
    assert_ne!(host, host_digest());
    assert_eq!(host, host_digest16());
    let root = qemu::repo_root();
    if !qemu::available("qemu_policy16_digest_matches_host", &root) {
        return;
    }
    let what = "the int16 blob on the host";
    qemu::assert_digest_on(&root, &qemu::BOARDS, "policy16", host, what);
}
