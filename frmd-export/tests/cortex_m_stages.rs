//! The per-stage breakdown of the Cortex-M policy firmware measures the real computation.
//!
//! `examples/cortex-m` (binary `frmd-cortex-m-policy-stages`) times each layer by running the baked MLP
//! through `stages::StagedMlpNetwork`, which re-composes `Int8Mlp::forward` from frmd-core's
//! kernels with a clock reading between layers. The firmware itself checks that the staged chunks
//! hash to the measured policy's digest; this host test checks the same without QEMU: the staged
//! network behind `Policy` gives bit-identical chunks to frmd-core's `Int8Network` (the blob form of
//! the same policy: the checked-in trained student `examples/cortex-m/policy/reach/`, exported
//! as the firmware's build.rs exports it, 16-bit first-layer input included), and records one clock
//! reading per stage boundary.

use std::sync::atomic::{AtomicU32, Ordering};

use frmd_core::blob::AlignedBlob;
use frmd_core::blob::LoadedMlp;
use frmd_core::model::linear::RequantizedLinear;
use frmd_core::model::mlp::InputPrecision;
use frmd_core::policy::Policy;
use frmd_export::mlp::QuantizedMlp;
use frmd_firmware_support::host::qemu::{self, line_value};
use frmd_firmware_support::host::student::student;
use frmd_firmware_support::policy_workload::PolicyWorkload;
use frmd_firmware_support::shape::{
    DOF, HORIZON, MLP_HIDDEN, MLP_WIDTH, PARAMS, STUDENT_HISTORY, STUDENT_INPUT, STUDENT_OBS_DIM,
};
use frmd_firmware_support::stages::{mlp_marks, StagedMlpNetwork};
use frmd_firmware_support::workload::digest_all;

const LAYERS: usize = MLP_HIDDEN.len();

/// A clock that advances by one per reading.
static TICKS: AtomicU32 = AtomicU32::new(0);
fn counting_clock() -> u32 {
    TICKS.fetch_add(1, Ordering::Relaxed)
}

/// The hidden layers of `quantized` as frmd-core layers over its own arrays.
fn hidden_layers(quantized: &QuantizedMlp) -> [RequantizedLinear<'_>; LAYERS] {
    let layers = quantized.hidden_layers();
    std::array::from_fn(|i| layers[i])
}

#[test]
fn staged_mlp_network_matches_int8_network() {
    let quantized = student();
    // The firmware's breakdown must cover the exporter's default 16-bit first-layer input.
    assert_eq!(quantized.input_precision, InputPrecision::Int16);
    assert_eq!(quantized.hidden.len(), LAYERS);
    let blob = AlignedBlob::new(&quantized.blob().expect("write the blob"));
    let loaded = LoadedMlp::load(blob.bytes()).expect("load the blob");
    let reference = loaded
        .policy::<STUDENT_HISTORY, STUDENT_OBS_DIM, DOF, HORIZON, PARAMS, STUDENT_INPUT, MLP_WIDTH>(
        )
        .expect("policy from the blob");
    let mut reference = PolicyWorkload::new(reference);
    let expected = digest_all(&mut reference).expect("reference chunks");

    let network = StagedMlpNetwork::<LAYERS, { mlp_marks(LAYERS) }, MLP_WIDTH>::new(
        quantized.input,
        hidden_layers(&quantized),
        quantized.output_layer(),
        &quantized.first_layer_biases,
        counting_clock,
    )
    .expect("staged network")
    .with_input_precision(quantized.input_precision);
    let policy =
        Policy::<_, STUDENT_HISTORY, STUDENT_OBS_DIM, DOF, HORIZON, PARAMS, STUDENT_INPUT>::new(
            loaded.config(),
            network,
        )
        .expect("staged policy");
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
fn staged_mlp_network_refuses_small_scratch() {
    let quantized = student();
    // WIDTH 128 is narrower than the 256-wide hidden layers.
    let result = StagedMlpNetwork::<LAYERS, { mlp_marks(LAYERS) }, 128>::new(
        quantized.input,
        hidden_layers(&quantized),
        quantized.output_layer(),
        &[],
        counting_clock,
    );
    assert!(result.is_err());
}

/// Runs both breakdown images on the Cortex-M4F board: each must print stage lines whose sum is
/// within 2 % of its measured `instructions:` and a `stage_digest` equal to its `digest` (the
/// firmware also refuses to finish otherwise). Skips like the other QEMU tests.
#[test]
fn qemu_stage_breakdowns_add_up() {
    let root = qemu::repo_root();
    if !qemu::available("qemu_stage_breakdowns_add_up", &root) {
        return;
    }
    for image in ["policy-stages", "transformer-stages"] {
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
