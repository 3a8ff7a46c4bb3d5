//! int16 activations (`ExportOptions::activations`): the exported network equals the
//! wide-integer model, its blob loads as an int16 MLP, and it follows the f32 network more
//! closely than the int8 export of the same checkpoint; GPTQ weight rounding
//! (`ExportOptions::weight_rounding`) keeps both exact and brings them closer still.
use frmd_core::blob::{AlignedBlob, LoadedBlob, LoadedMlp};
use frmd_core::model::mlp::InputPrecision;
use frmd_core::policy::Network;
use frmd_core::sigma::SigmaConfig;
use frmd_export::formats::checkpoint::{
    Activation, BackboneConfig, CheckpointMeta, HeadConfig, ModelConfig, Normalization, Normalizer,
    ProDmpOutput, Role,
};
use frmd_export::host::{HostScratch, HostWork, MAX_WIDTH};
use frmd_export::{Activations, ExportOptions, ExportedStudent, WeightRounding};
use frmd_test_support::checkpoint::{scratch_dir, write_meta, write_weights, Init};
use std::path::{Path, PathBuf};

fn model() -> ModelConfig {
    ModelConfig {
        obs_dim: 3,
        history: 2,
        action_dim: 2,
        horizon: 5,
        control_dt: 0.05,
        embed_dim: 4,
        backbone: BackboneConfig::Mlp {
            hidden: vec![24, 20],
            activation: Activation::Silu,
        },
        head: HeadConfig::ProDmp {
            num_basis: 3,
            output: ProDmpOutput::Direct,
            auto_scale_basis: false,
        },
    }
}

fn student(tag: &str) -> PathBuf {
    let dir = scratch_dir(&format!("int16-export-{tag}"));
    let mut meta = CheckpointMeta::describe(Role::Student, &model(), SigmaConfig::default());
    meta.normalization = Some(Normalization {
        obs: Normalizer {
            min: vec![-1.0, 0.0, 2.0],
            max: vec![1.0, 3.0, 2.5],
        },
        action: Normalizer {
            min: vec![-0.5, 0.1],
            max: vec![0.5, 0.9],
        },
    });
    write_meta(&dir, &meta);
    write_weights(&dir, &meta, 11, Init::FanIn, |_, _| {});
    dir
}

fn export(dir: &Path, activations: Activations, steps: usize) -> ExportedStudent {
    export_with(dir, activations, steps, WeightRounding::Nearest)
}

fn export_with(
    dir: &Path,
    activations: Activations,
    steps: usize,
    weight_rounding: WeightRounding,
) -> ExportedStudent {
    let set = frmd_test_support::checkpoint::calibration_rows(&model(), 24, 5, 29);
    let options = ExportOptions {
        steps,
        activations: Some(activations),
        weight_rounding: Some(weight_rounding),
        ..Default::default()
    };
    frmd_export::export(dir, &options, Some(set)).unwrap()
}

/// Largest output difference of the exported blob's network from the f32 network, relative to
/// the largest f32 output, over the step-0 model inputs of the calibration rows times `gain`
/// (beyond 1: activations beyond the calibrated ranges, as closed loop reaches).
fn worst_relative_error(student: &ExportedStudent, gain: f32) -> f32 {
    let set = student.calibration().clone();
    let mut inputs = Vec::new();
    for row in 0..set.rows() {
        let noise = set.noise(row, student.steps(), student.dims().horizon * 2);
        student
            .sample_f32(set.row(row), &noise, |step, input| {
                if step == 0 {
                    inputs.push(input.iter().map(|v| v * gain).collect::<Vec<_>>());
                }
            })
            .unwrap();
    }
    let blob = AlignedBlob::new(student.blob());
    let loaded = LoadedBlob::load(blob.bytes()).unwrap();
    let mut work = HostWork::new();
    let mut quantized = loaded.network::<MAX_WIDTH, _>(&mut work).unwrap();
    let mut float_scratch = Box::new(HostScratch::new());
    let mut worst = 0f32;
    student
        .with_f32_network(&mut float_scratch, |float| {
            let width = float.output_width();
            for input in &inputs {
                let (mut a, mut b) = (vec![0.0; width], vec![0.0; width]);
                float.forward(0, input, &mut a)?;
                quantized.forward(0, input, &mut b)?;
                let scale = a.iter().fold(0f32, |m, v| m.max(v.abs()));
                let err = a
                    .iter()
                    .zip(&b)
                    .map(|(x, y)| (x - y).abs())
                    .fold(0.0, f32::max);
                worst = worst.max(err / scale);
            }
            Ok(())
        })
        .unwrap();
    worst
}

#[test]
fn int16_export_matches_the_wide_model_and_loads_as_int16() {
    let dir = student("exact");
    for steps in [1, 3] {
        let exported = export(&dir, Activations::Int16, steps);
        let mlp = exported.mlp16().expect("an int16 MLP export");
        assert!(exported.mlp().is_none());
        assert_eq!(mlp.policy.input_precision, InputPrecision::Int16);
        assert!(mlp
            .policy
            .hidden
            .iter()
            .all(|l| l.activation_min == i16::MIN));
        let check = exported.check_kernels(&[]).unwrap();
        assert!(check.passed(), "{check:?}");
        let blob = AlignedBlob::new(exported.blob());
        assert!(matches!(
            LoadedBlob::load(blob.bytes()).unwrap(),
            LoadedBlob::Mlp16(_)
        ));
        // The int8 loader names what it found.
        assert_eq!(
            LoadedMlp::load(blob.bytes()).err(),
            Some(frmd_core::blob::BlobError::ActivationBits { found: 16 })
        );
    }
}

#[test]
fn int16_activations_follow_the_float_network_closer_than_int8() {
    let dir = student("error");
    let (int8, int16) = (
        export(&dir, Activations::Int8, 1),
        export(&dir, Activations::Int16, 1),
    );
    for gain in [1.0, 1.3] {
        let int8 = worst_relative_error(&int8, gain);
        let int16 = worst_relative_error(&int16, gain);
        eprintln!("inputs x{gain}: worst relative output error int8 {int8:.5}, int16 {int16:.5}");
    }
    let inside = [&int8, &int16].map(|s| worst_relative_error(s, 1.0));
    let beyond = [&int8, &int16].map(|s| worst_relative_error(s, 1.3));
    // Within the calibrated ranges both carry the int8 weights' error; beyond them int8 clips
    // and int16 (ranges x1.5) does not.
    assert!(inside[1] < inside[0], "{inside:?}");
    assert!(beyond[1] < 0.5 * beyond[0], "{beyond:?}");
}

#[test]
fn int16_activations_need_the_16_bit_input() {
    let dir = student("input");
    let set = frmd_test_support::checkpoint::calibration_rows(&model(), 8, 5, 29);
    for input_precision in [InputPrecision::Int8, InputPrecision::TwoPlane] {
        let options = ExportOptions {
            activations: Some(Activations::Int16),
            input_precision,
            ..Default::default()
        };
        let err = format!(
            "{:#}",
            frmd_export::export(&dir, &options, Some(set.clone())).unwrap_err()
        );
        assert!(err.contains("16-bit input"), "{err}");
    }
    let options = ExportOptions {
        activations: Some(Activations::Int16),
        activation_headroom: 0.5,
        ..Default::default()
    };
    let err = format!(
        "{:#}",
        frmd_export::export(&dir, &options, Some(set)).unwrap_err()
    );
    assert!(err.contains("headroom"), "{err}");
}

#[test]
fn gptq_rounding_stays_exact_and_follows_the_float_network_closer() {
    let dir = student("gptq");
    for activations in [Activations::Int8, Activations::Int16] {
        let nearest = export_with(&dir, activations, 1, WeightRounding::Nearest);
        let gptq = export_with(&dir, activations, 1, WeightRounding::Gptq);
        let check = gptq.check_kernels(&[]).unwrap();
        assert!(check.passed(), "{check:?}");
        assert_ne!(nearest.blob(), gptq.blob(), "{activations}: other codes");
        let errors = [&nearest, &gptq].map(|s| worst_relative_error(s, 1.0));
        eprintln!("{activations}: worst relative output error nearest / gptq {errors:?}");
        assert!(errors[1] < errors[0], "{activations}: {errors:?}");
    }
}
