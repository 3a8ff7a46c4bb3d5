//! A deterministic synthetic one-step policy as a `frmd_export::mlp::QuantizedMlp` (used by
//! `build.rs`, which bakes it with `frmd_export::mlp::bake::write_module` for the `transformer`
//! images,
//! and by the host test `frmd-export/tests/cortex_m_transformer.rs`, which writes it as a blob and
//! runs it with `frmd_core::blob::LoadedMlp`). Only its configuration (normalization, step
//! constants, decoder, input layout) is used: the transformer replaces its MLP as the network.
//!
//! Shape: history 2 x 8 observations, 2 DoF, horizon 12, 20 basis functions, one sampling step at
//! sigma_max, standard input layout (44 inputs), int8 MLP 44-256-256-256-42 with SiLU LUTs from
//! [`super::mlp`]. Weights are random: only cost, memory and host/firmware equality
//! matter, not what it computes.

use super::mlp::{generate_with, LayerData};
use crate::shape::{
    config, CONTROL_DT, DOF, HORIZON, PARAMS, POLICY_HISTORY, POLICY_INPUT, POLICY_OBS_DIM,
    POLICY_STEPS,
};
use frmd_core::policy::{InputLayout, StepConstants};
use frmd_core::prodmp::BakedProDmp;
use frmd_core::sigma::SigmaConfig;
use frmd_export::fold::ProDmpTablesOwned;
use frmd_export::mlp::{QuantizedLayer, QuantizedMlp, QuantizedOutput};

/// Seed of the weight stream.
pub const POLICY_WEIGHT_SEED: u64 = 0x4652_4D44_504F_4C31;
/// Real range of the model input (normalized observations/actions in [-1, 1], rates and the
/// c_in-scaled noisy trajectory mostly within a few units).
const MODEL_INPUT_RANGE: (f32, f32) = (-4.0, 4.0);
/// One-step constants at sigma_max from frmd-core's EDM/consistency schedule (defaults of
/// docs/design.md s.3: sigma_min 0.002, sigma_max 80, sigma_data 0.5).
fn first_step() -> StepConstants {
    let sigma = SigmaConfig::default();
    StepConstants::consistency(&sigma, sigma.sigma_max, 0).expect("schedule defined at sigma_max")
}

fn hidden_layer(layer: &LayerData) -> QuantizedLayer {
    QuantizedLayer {
        in_features: layer.in_features,
        out_features: layer.out_features,
        weights: layer.weights.clone(),
        bias: layer.bias.clone(),
        multipliers: layer.multipliers.clone(),
        shifts: layer.shifts.clone(),
        output_zero_point: layer.output_zero_point,
        activation_min: i8::MIN,
        activation_max: i8::MAX,
        // Every hidden layer uses the same SiLU table (same pre/post-activation parameters).
        lut: layer.lut.map(|_| 0),
    }
}

/// Generates the policy (deterministic: the same bytes on every host).
pub fn generate() -> QuantizedMlp {
    let layout = InputLayout::standard(CONTROL_DT as f32);
    let input_width = layout.width(POLICY_HISTORY, POLICY_OBS_DIM, DOF, HORIZON);
    assert_eq!(
        input_width,
        Some(POLICY_INPUT),
        "shape::POLICY_INPUT disagrees with the layout"
    );
    let model = generate_with(POLICY_INPUT, POLICY_WEIGHT_SEED, MODEL_INPUT_RANGE);
    let lut = model.hidden[0].lut.expect("hidden layers have a SiLU LUT");
    let baked = BakedProDmp::<HORIZON, PARAMS>::from_config(&config()).expect("bake the decoder");
    QuantizedMlp {
        history: POLICY_HISTORY,
        obs_dim: POLICY_OBS_DIM,
        action_dim: DOF,
        horizon: HORIZON,
        params_per_dof: PARAMS,
        control_dt: CONTROL_DT as f32,
        layout,
        input: model.input,
        input_precision: frmd_core::model::mlp::InputPrecision::Int8,
        obs_min: vec![-1.0; POLICY_OBS_DIM],
        obs_max: vec![1.0; POLICY_OBS_DIM],
        action_min: vec![-0.3; DOF],
        action_max: vec![0.3; DOF],
        prodmp: ProDmpTablesOwned::from_baked(&baked),
        steps: (0..POLICY_STEPS).map(|_| first_step()).collect(),
        // The first layer's own bias stands in for "noise embedding at sigma_max folded in".
        first_layer_biases: model.hidden[0].bias.clone(),
        luts: vec![lut.table],
        hidden: model.hidden.iter().map(hidden_layer).collect(),
        output: QuantizedOutput {
            in_features: model.output.in_features,
            out_features: model.output.out_features,
            weights: model.output.weights.clone(),
            bias: model.output.bias.clone(),
            scales: model.output.output_scales.clone(),
        },
    }
}
