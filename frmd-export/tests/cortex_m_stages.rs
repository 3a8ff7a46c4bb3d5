//! The per-stage breakdown of the Cortex-M policy firmware measures the real computation.
//!
//! `examples/cortex-m` (binaries `frmd-cortex-m-policy-stages`, `-policy16-stages`) times each
//! layer by running the baked network through `stages::StagedMlpNetwork`, which drives
//! frmd-core's own staged forward pass (`QuantMlpNetwork::forward_staged`) with a clock reading
//! at every stage boundary. The firmware itself checks that the staged chunks hash to the measured
//! policy's digest; this host test checks the same without QEMU for both activation precisions:
//! the staged network behind `Policy` gives bit-identical chunks to the blob form of the same
//! policy (the checked-in trained student `examples/cortex-m/policy/reach/`, exported as the
//! firmware's build.rs exports it), and records one clock reading per stage boundary.

use std::sync::atomic::{AtomicU32, Ordering};

use frmd_core::blob::{AlignedBlob, LoadedBlob};
use frmd_core::policy::{Policy, QuantMlpNetwork};
use frmd_export::mlp::{ExportPrecision, QuantizedMlp};
use frmd_export::Activations;
use frmd_firmware_support::host::qemu::{self, line_value};
use frmd_firmware_support::host::student::student_export_as;
use frmd_firmware_support::policy_workload::PolicyWorkload;
use frmd_firmware_support::shape::{
    DOF, HORIZON, MLP_HIDDEN, MLP_WIDTH, PARAMS, STUDENT_HISTORY, STUDENT_INPUT, STUDENT_OBS_DIM,
};
use frmd_firmware_support::stages::{mlp_marks, StagedMlpNetwork};
use frmd_firmware_support::workload::digest_all;

const LAYERS: usize = MLP_HIDDEN.len();

/// The student's policy type over `Net`.
type StudentPolicy<'a, Net> =
    Policy<'a, Net, STUDENT_HISTORY, STUDENT_OBS_DIM, DOF, HORIZON, PARAMS, STUDENT_INPUT>;

/// A clock that advances by one per reading.
static TICKS: AtomicU32 = AtomicU32::new(0);
fn counting_clock() -> u32 {
    TICKS.fetch_add(1, Ordering::Relaxed)
}

fn network_of<P: ExportPrecision>(policy: &QuantizedMlp<P>) -> QuantMlpNetwork<'_, P, MLP_WIDTH> {
    frmd_export::mlp::reference::quantized_network::<P, MLP_WIDTH>(policy).expect("network")
}

/// The staged network of the student exported with `P` activations gives the chunks of its blob
/// and one reading per stage boundary.
fn staged_matches_blob<P: ExportPrecision>(policy: &QuantizedMlp<P>) {
    let blob = AlignedBlob::new(&policy.blob().expect("write the blob"));
    let loaded = LoadedBlob::load(blob.bytes()).expect("load the blob");
    let mut work = frmd_export::host::HostWork::new();
    let network = loaded
        .network::<MLP_WIDTH, _>(&mut work)
        .expect("the blob's network");
    let reference = StudentPolicy::new(loaded.config(), network).expect("policy from the blob");
    let expected = digest_all(&mut PolicyWorkload::new(reference)).expect("reference chunks");
    let staged = StagedMlpNetwork::<P, { mlp_marks(LAYERS) }, MLP_WIDTH>::new(
        network_of(policy),
        counting_clock,
    )
    .expect("staged network");
    let policy = StudentPolicy::new(loaded.config(), staged).expect("staged policy");
    let mut staged = PolicyWorkload::new(policy);
    assert_eq!(digest_all(&mut staged).expect("staged chunks"), expected);
    let marks = staged.policy().network().marks().ticks();
    assert_eq!(marks.len(), mlp_marks(LAYERS));
    assert!(
        marks.windows(2).all(|pair| pair[1] == pair[0] + 1),
        "{marks:?}"
    );
}

#[test]
fn staged_mlp_network_matches_the_blob_for_both_precisions() {
    let int8 = student_export_as(Activations::Int8);
    staged_matches_blob(&int8.mlp().expect("an int8 MLP").policy);
    let int16 = student_export_as(Activations::Int16);
    staged_matches_blob(&int16.mlp16().expect("an int16 MLP").policy);
}

#[test]
fn staged_mlp_network_refuses_too_few_readings() {
    let int8 = student_export_as(Activations::Int8);
    let policy = &int8.mlp().expect("an int8 MLP").policy;
    let result = StagedMlpNetwork::<i8, { mlp_marks(LAYERS) - 1 }, MLP_WIDTH>::new(
        network_of(policy),
        counting_clock,
    );
    assert!(result.is_err());
}

#[test]
fn qemu_stage_breakdowns_add_up() {
    let root = qemu::repo_root();
    if !qemu::available("qemu_stage_breakdowns_add_up", &root) {
        return;
    }
    for image in ["policy-stages", "policy16-stages", "transformer-stages"] {
        let stdout = qemu::run(&root, "m4", image);
        assert_eq!(
            line_value(&stdout, "stage_digest"),
            line_value(&stdout, "digest"),
            "{stdout}"
        );
        let number = |key: &str| -> f64 {
            line_value(&stdout, key)
                .and_then(|v| v.parse().ok())
                .unwrap_or_else(|| panic!("no numeric '{key}:' line in\n{stdout}"))
        };
        let stages: Vec<f64> = stdout
            .lines()
            .filter(|line| line.starts_with("stage ") && !line.starts_with("stage_"))
            .map(|line| {
                line.rsplit(": ")
                    .next()
                    .and_then(|v| v.parse().ok())
                    .expect("stage value")
            })
            .collect();
        assert!(stages.len() >= 8, "{image}: too few stages\n{stdout}");
        let sum: f64 = stages.iter().sum();
        assert_eq!(sum, number("stage_sum"));
        let total = number("instructions_mean");
        assert!(
            (sum - total).abs() <= 0.02 * total,
            "{image}: stages sum to {sum}, the measured call takes {total}\n{stdout}"
        );
        eprintln!("{image} m4: stages sum {sum}, instructions_mean {total}");
    }
}
