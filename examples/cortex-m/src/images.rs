//! The policies the `policy` and `transformer` images measure, shared by each image and its
//! `-stages` twin (which measures the same policy first, then breaks it down).

use frmd_core::model::mlp::{InputPrecision, MlpPrecision};
use frmd_core::model::transformer::{Int8Transformer, TransformerScratch};
use frmd_core::policy::{
    Int16MlpNetwork, Int8MlpNetwork, Int8TransformerNetwork, Network, Policy, PolicyError,
    QuantMlpNetwork, MAX_HIDDEN_LAYERS,
};
use frmd_firmware_support::policy_workload::{
    policy_act_macs, PolicyWorkload, CASES, STUDENT16_NAME, STUDENT_NAME,
};
use frmd_firmware_support::stages::{mlp_marks, StagedMlpNetwork};

use crate::timer::Calibration;
use frmd_firmware_support::shape::{
    DOF, HORIZON, PARAMS, POLICY_HISTORY, POLICY_INPUT, POLICY_OBS_DIM, TRANSFORMER_SCRATCH,
};

use crate::memory::StackProbe;
use crate::report::exit_failure;
use crate::{
    baked_student as student, baked_student16 as student16, baked_synthetic_policy,
    baked_transformer,
};

/// The baked student's workload (`Policy::act` of the trained one-step MLP, or of another network
/// `Net` with the student's sizes).
pub type StudentWorkload<Net = Int8MlpNetwork<'static, { student::SCRATCH_WIDTH }>> =
    PolicyWorkload<
        'static,
        Net,
        { student::HISTORY },
        { student::OBS_DIM },
        { student::ACTION_DIM },
        { student::HORIZON },
        { student::PARAMS_PER_DOF },
        { student::INPUT_WIDTH },
    >;

/// The baked student's policy as a workload that states its multiply-accumulates.
pub fn student_workload() -> StudentWorkload {
    baked_student_workload(student::policy(&mut student::Storage::new()), STUDENT_NAME)
}

/// The same student exported with int16 activations (the `policy16` image).
pub fn student16_workload(
) -> StudentWorkload<Int16MlpNetwork<'static, { student16::SCRATCH_WIDTH }>> {
    baked_student_workload(
        student16::policy(&mut student16::Storage::new()),
        STUDENT16_NAME,
    )
}

/// A stages image: measures `workload` as its policy image does (same report lines and digest),
/// then breaks the same student down by stage, `network` (the baked module's) running frmd-core's
/// staged forward pass with the SysTick clock (`stage` lines, src/stage_report.rs).
pub fn student_stages<P: MlpPrecision, const W: usize>(
    workload: impl FnOnce() -> StudentWorkload<QuantMlpNetwork<'static, P, W>>,
    network: impl FnOnce() -> Result<QuantMlpNetwork<'static, P, W>, PolicyError>,
    name: &'static str,
) -> ! {
    let stack = crate::bench::start();
    let mut workload = workload();
    crate::bench::run_then::<_, { CASES * 5 }>(&mut workload, stack, |_, calibration, digest| {
        // Not inlined into the measurement: its frame (a second policy) stays out of its stack.
        if let Err(error) = student_breakdown(network(), name, calibration, digest) {
            exit_failure(&error);
        }
    })
}

/// The per-stage breakdown of a baked student's `network` (see [`student_stages`]).
#[inline(never)]
fn student_breakdown<P: MlpPrecision, const W: usize>(
    network: Result<QuantMlpNetwork<'static, P, W>, PolicyError>,
    name: &'static str,
    calibration: &Calibration,
    digest: u64,
) -> Result<(), PolicyError> {
    let network = network?;
    let mut macs: [u64; MAX_HIDDEN_LAYERS + 1] = [0; MAX_HIDDEN_LAYERS + 1];
    let mut layers = 0;
    for (slot, (inputs, outputs)) in macs.iter_mut().zip(network.layer_shapes()) {
        *slot = (inputs * outputs) as u64;
        layers += 1;
    }
    if network.input_precision() == InputPrecision::TwoPlane {
        // The first layer's kernel runs on both input planes.
        macs[0] *= 2;
    }
    let hidden = layers - 1;
    let output_macs = macs[hidden];
    let staged = StagedMlpNetwork::<P, { mlp_marks(MAX_HIDDEN_LAYERS) }, W>::new(
        network,
        crate::stage_report::systick,
    )?;
    let policy = Policy::new(student::config(), staged)?;
    let mut staged: StudentWorkload<_> = PolicyWorkload::with_name(policy, name);
    crate::stage_report::mlp_policy(
        &mut staged,
        &macs[..hidden],
        output_macs,
        calibration,
        digest,
    )
}

/// A baked policy of the student's sizes as a workload named `name` (firmware failure if the
/// policy did not build).
fn baked_student_workload<Net: Network>(
    policy: Result<
        Policy<
            'static,
            Net,
            { student::HISTORY },
            { student::OBS_DIM },
            { student::ACTION_DIM },
            { student::HORIZON },
            { student::PARAMS_PER_DOF },
            { student::INPUT_WIDTH },
        >,
        PolicyError,
    >,
    name: &'static str,
) -> StudentWorkload<Net> {
    let policy = match policy {
        Ok(policy) => policy,
        Err(error) => exit_failure(&error),
    };
    let macs = policy_act_macs(
        student::NETWORK_MACS,
        student::HORIZON,
        student::ACTION_DIM,
        student::PARAMS_PER_DOF,
    );
    PolicyWorkload::with_name(policy, name).with_macs(macs)
}

/// Printed as the transformer images' `workload:` line.
pub const TRANSFORMER_NAME: &str = "policy act: one-step int8 transformer-lite (3 blocks, 2 heads, width 128, 14 tokens) + decode (synthetic weights)";

/// Scratch of the synthetic transformer.
pub type Scratch = TransformerScratch<
    { TRANSFORMER_SCRATCH.floats },
    { TRANSFORMER_SCRATCH.codes },
    { TRANSFORMER_SCRATCH.accumulators },
>;

/// The synthetic transformer as a policy network running in `scratch`.
pub type TransformerNetwork<'a> = Int8TransformerNetwork<'a, &'a mut Scratch>;

/// A policy over `Net` with the synthetic policy's sizes.
pub type TransformerPolicy<'a, Net> =
    Policy<'a, Net, POLICY_HISTORY, POLICY_OBS_DIM, DOF, HORIZON, PARAMS, POLICY_INPUT>;

/// [`TransformerPolicy`] as a workload.
pub type TransformerWorkload<'a, Net> =
    PolicyWorkload<'a, Net, POLICY_HISTORY, POLICY_OBS_DIM, DOF, HORIZON, PARAMS, POLICY_INPUT>;

/// The synthetic transformer's blocks (firmware failure if the baked data does not fit).
pub fn transformer_blocks(
) -> [frmd_core::model::transformer::Int8Block<'static>; baked_transformer::LAYERS] {
    match baked_transformer::blocks() {
        Some(blocks) => blocks,
        None => exit_failure(&"baked transformer: a block lies outside the generated data"),
    }
}

/// The synthetic transformer over `blocks`, running in `scratch`, as a policy network.
pub fn transformer_network<'a>(
    blocks: &'a [frmd_core::model::transformer::Int8Block<'static>],
    scratch: &'a mut Scratch,
) -> TransformerNetwork<'a> {
    let Some(model) = baked_transformer::model(blocks) else {
        exit_failure(&"baked transformer: a layer lies outside the generated data");
    };
    network_of(model, scratch)
}

/// `model` as the synthetic policy's network, running in `scratch`.
pub fn network_of<'a>(
    model: Int8Transformer<'a>,
    scratch: &'a mut Scratch,
) -> TransformerNetwork<'a> {
    let layout = baked_synthetic_policy::config().sampler.layout;
    match Int8TransformerNetwork::new(model, &layout, &[], scratch) {
        Ok(network) => network,
        Err(error) => exit_failure(&error),
    }
}

/// The synthetic policy's configuration with `network`.
pub fn transformer_policy<'a, Net: Network>(network: Net) -> TransformerPolicy<'a, Net> {
    match Policy::new(baked_synthetic_policy::config(), network) {
        Ok(policy) => policy,
        Err(error) => exit_failure(&error),
    }
}

/// [`transformer_policy`] as the transformer images' workload.
pub fn transformer_workload<'a, Net: Network>(network: Net) -> TransformerWorkload<'a, Net> {
    PolicyWorkload::with_name(transformer_policy(network), TRANSFORMER_NAME)
}

/// The start of both transformer images: paints the stack, builds the synthetic transformer
/// policy's workload (its blocks and scratch in this frame, which is `main`'s: inlined) and hands
/// the workload and the stack probe to `measure`.
#[inline(always)]
pub fn transformer_image(
    measure: fn(&mut TransformerWorkload<'_, TransformerNetwork<'_>>, StackProbe) -> !,
) -> ! {
    let stack = crate::bench::start();
    let blocks = transformer_blocks();
    let mut scratch = Scratch::new();
    let mut workload = transformer_workload(transformer_network(&blocks, &mut scratch));
    measure(&mut workload, stack)
}

/// Printed as the `transformer-student` images' `workload:` line.
pub const TRANSFORMER_STUDENT_NAME: &str = "policy act: one-step transformer-lite student (random weights) from its blob, int8 activations";
/// The same for the int16 image.
pub const TRANSFORMER_STUDENT16_NAME: &str = "policy act: one-step transformer-lite student (random weights) from its blob, int16 activations";

/// The start of the `transformer-student` images: the baked blob's policy (built by `policy` over
/// `storage`, which the caller keeps in `main`'s frame) as a workload named `name`, measured on
/// the fixed observation histories.
#[inline(always)]
pub fn transformer_student_image<'a, Net: Network, E: core::fmt::Display>(
    stack: StackProbe,
    policy: Result<TransformerPolicy<'a, Net>, E>,
    name: &'static str,
) -> ! {
    let policy = match policy {
        Ok(policy) => policy,
        Err(error) => exit_failure(&error),
    };
    let mut workload: TransformerWorkload<'a, Net> = PolicyWorkload::with_name(policy, name);
    crate::bench::run::<_, { CASES }>(&mut workload, stack)
}
