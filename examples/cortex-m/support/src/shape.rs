//! Shape of the policies the firmware runs, shared by `build.rs` (which bakes the ProDMP tables on
//! the host), the firmware images, the synthetic generators and the host digest tests.
//! Values follow the built-in tasks: 2 DoF (x, y targets in metres), 0.1 s control period,
//! horizon 12, 20 basis functions (docs/design.md s.2 policy convention).

use frmd_core::prodmp::ProDmpConfig;

/// Degrees of freedom (action dimension).
pub const DOF: usize = 2;
/// Query times per decoded chunk.
pub const HORIZON: usize = 12;
/// ProDMP basis functions per DoF.
pub const NUM_BASIS: usize = 20;
/// Parameters per DoF: the basis weights, then the goal.
pub const PARAMS: usize = NUM_BASIS + 1;
/// Control period, seconds.
pub const CONTROL_DT: f64 = 0.1;

/// Synthetic int8 MLP (`synthetic::mlp`): input width (observation history, noisy trajectory
/// and noise features of a small policy, rounded to 40), hidden widths, widest layer.
pub const MLP_INPUT: usize = 40;
pub const MLP_HIDDEN: [usize; 3] = [256, 256, 256];
pub const MLP_WIDTH: usize = 256;
/// MLP output: the ProDMP parameters of every DoF, DoF-major.
pub const MLP_OUTPUT: usize = DOF * PARAMS;

/// Synthetic one-step policy (`synthetic::policy`): observation history length, observation
/// dimension, sampling steps, model input width (standard layout: `M*O + K + K + N*K`).
pub const POLICY_HISTORY: usize = 2;
pub const POLICY_OBS_DIM: usize = 8;
pub const POLICY_STEPS: usize = 1;
pub const POLICY_INPUT: usize = POLICY_HISTORY * POLICY_OBS_DIM + 2 * DOF + HORIZON * DOF;

/// The trained student the `policy` image runs (checked in under `policy/reach/`, exported by
/// build.rs): observation history length and observation dimension of the built-in `reach` task,
/// model input width (standard layout, 40).
pub const STUDENT_HISTORY: usize = 2;
pub const STUDENT_OBS_DIM: usize = 6;
pub const STUDENT_INPUT: usize = STUDENT_HISTORY * STUDENT_OBS_DIM + 2 * DOF + HORIZON * DOF;

/// The ProDMP configuration of the policy (tau = HORIZON * CONTROL_DT = 1.2 s).
pub fn config() -> ProDmpConfig {
    ProDmpConfig::policy(DOF, NUM_BASIS, HORIZON, CONTROL_DT)
}

/// Synthetic transformer-lite policy network (`synthetic::transformer`): 3 pre-LayerNorm
/// blocks of width 128 with 2 heads over `HORIZON + 2 = 14` tokens; the condition is the standard
/// layout's first three segments (observation history, previous action, its rate times the control
/// period), the trajectory tokens the `c_in`-scaled noisy trajectory; the head outputs the ProDMP
/// parameters.
pub const TRANSFORMER_CONDITION: usize = POLICY_HISTORY * POLICY_OBS_DIM + 2 * DOF;
pub const TRANSFORMER_SHAPE: frmd_core::model::transformer::TransformerShape =
    frmd_core::model::transformer::TransformerShape {
        horizon: HORIZON,
        action_dim: DOF,
        cond_dim: TRANSFORMER_CONDITION,
        width: 128,
        heads: 2,
        layers: 3,
        output: DOF * PARAMS,
    };
/// Scratch lengths of the int8 forward pass.
pub const TRANSFORMER_SCRATCH: frmd_core::model::transformer::ScratchLens =
    TRANSFORMER_SHAPE.int8_scratch();
/// Linear layers in generation order: `traj_in`, `cond_in`, then `qkv, proj, fc1, fc2` per block,
/// then `head`.
pub const TRANSFORMER_LINEARS: usize = 2 + 4 * TRANSFORMER_SHAPE.layers + 1;
/// LayerNorms: `norm1, norm2` per block, then the final one.
pub const TRANSFORMER_NORMS: usize = 2 * TRANSFORMER_SHAPE.layers + 1;
