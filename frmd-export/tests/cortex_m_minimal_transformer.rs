//! The minimal firmware (`examples/cortex-m/minimal`) runs a transformer-lite student as it runs
//! the MLP one: its build.rs makes the same one export call (`FRMD_MINIMAL_CHECKPOINT` names the
//! checkpoint), its `main.rs` is unchanged, and the first action's bits on every core with the
//! memory for a transformer equal the host's frmd-core policy over the exported blob, with int8
//! and with int16 activations (`FRMD_MINIMAL_ACTIVATIONS`). Its own
//! test binary: it rebuilds the minimal image with another checkpoint, which must not race with
//! `cortex_m_policy.rs`'s build of the reach student.

use frmd_core::blob::{AlignedBlob, LoadedBlob};
use frmd_core::policy::{Noise, Policy};
use frmd_core::rng::Rng;
use frmd_export::host::HostWork;
use frmd_export::{Activations, ExportOptions};
use frmd_firmware_support::host::qemu;
use frmd_formats::calibration;
use frmd_formats::checkpoint::{BackboneConfig, HeadConfig, ModelConfig, Role, CALIBRATION_FILE};
use frmd_test_support::checkpoint::{
    calibration_rows, scratch_dir, unit_normalization, write_checkpoint, Init,
};
use std::path::Path;

const HISTORY: usize = 2;
const OBS: usize = 4;
const DOF: usize = 2;
const HORIZON: usize = 8;
const PARAMS: usize = 5;
const INPUT: usize = HISTORY * OBS + 2 * DOF + HORIZON * DOF;

fn model() -> ModelConfig {
    ModelConfig {
        obs_dim: OBS,
        history: HISTORY,
        action_dim: DOF,
        horizon: HORIZON,
        control_dt: 0.05,
        embed_dim: 16,
        backbone: BackboneConfig::Transformer {
            layers: 2,
            heads: 2,
            width: 32,
        },
        head: HeadConfig::prodmp(PARAMS - 1),
    }
}

/// The first action of the minimal example's inputs (last action 0.05, observation `0.1 step`,
/// noise seed 2024) on the host, as the firmware prints its bits.
fn host_first_action(blob: &[u8]) -> Vec<String> {
    let blob = AlignedBlob::new(blob);
    let loaded = LoadedBlob::load(blob.bytes()).expect("load the blob");
    let mut work = HostWork::new();
    let network = loaded.network::<INPUT, _>(&mut work).expect("network");
    let mut policy =
        Policy::<_, HISTORY, OBS, DOF, HORIZON, PARAMS, INPUT>::new(loaded.config(), network)
            .expect("policy");
    policy.reset(&[0.05; DOF]).unwrap();
    for step in 0..HISTORY {
        policy.observe(&[0.1 * step as f32; OBS]).unwrap();
    }
    let chunk = *policy.act(Noise::Rng(&mut Rng::new(2024))).unwrap();
    chunk.positions[0]
        .iter()
        .map(|v| format!("(bits {:08x})", v.to_bits()))
        .collect()
}

#[test]
fn qemu_minimal_example_runs_a_transformer_student_like_the_host() {
    let root = qemu::repo_root();
    if !qemu::available(
        "qemu_minimal_example_runs_a_transformer_student_like_the_host",
        &root,
    ) {
        return;
    }
    let dir = scratch_dir("minimal-transformer");
    let model = model();
    let norm = unit_normalization(OBS, DOF);
    write_checkpoint(&dir, Role::Student, &model, norm, 31, Init::Transformer);
    calibration::write(
        &dir.join(CALIBRATION_FILE),
        &calibration_rows(&model, 32, 5, 6),
    )
    .unwrap();
    let mut first_actions = Vec::new();
    for activations in [Activations::Int8, Activations::Int16] {
        let options = ExportOptions {
            activations: Some(activations),
            ..Default::default()
        };
        let student = frmd_export::export(&dir, &options, None).expect("export");
        assert_eq!(student.activations(), activations);
        let expected = host_first_action(student.blob());
        assert_eq!(expected.len(), DOF);
        let name = activations.to_string();
        for board in qemu::TRANSFORMER_BOARDS {
            let env: [(&str, &Path); 2] = [
                ("FRMD_MINIMAL_CHECKPOINT", &dir),
                ("FRMD_MINIMAL_ACTIVATIONS", Path::new(&name)),
            ];
            let stdout = qemu::run_with_env(&root, board, "minimal", &env);
            let got: Vec<String> = stdout
                .lines()
                .filter(|line| line.starts_with("first action, dof "))
                .filter_map(|line| line.find("(bits").map(|bits| line[bits..].to_string()))
                .collect();
            assert_eq!(
                got, expected,
                "minimal transformer example ({name}) on {board}:\n{stdout}"
            );
        }
        first_actions.push(expected);
    }
    assert_ne!(
        first_actions[0], first_actions[1],
        "int8 and int16 exports gave the same bits"
    );
    std::fs::remove_dir_all(&dir).unwrap();
}
