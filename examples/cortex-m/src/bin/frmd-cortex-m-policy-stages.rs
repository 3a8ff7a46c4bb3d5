//! Firmware: the per-stage breakdown of the policy image (src/bin/frmd-cortex-m-policy.rs). It
//! first measures `Policy::act` of the same baked trained student exactly as that image does (same
//! inputs, seeds and report lines, so the same digest), then runs the student's baked MLP through
//! a layer-marking network and prints `stage` lines (src/stage_report.rs). The breakdown lives in
//! its own image because its second policy instance changes how the compiler inlines the shared
//! code: the totals of the two images differ slightly; the policy image's `instructions:` is the
//! reference, the stage lines show where the time goes.
#![no_std]
#![no_main]

use cortex_m_rt::entry;
use frmd_core::model::mlp::InputPrecision;
use frmd_core::policy::{Policy, PolicyError};
use frmd_cortex_m::baked_student as baked;
use frmd_cortex_m::images::{self, StudentWorkload};
use frmd_cortex_m::report::exit_failure;
use frmd_cortex_m::timer::Calibration;
use frmd_cortex_m::{bench, stage_report};
use frmd_firmware_support::policy_workload::{PolicyWorkload, CASES, STUDENT_NAME};
use frmd_firmware_support::stages::{mlp_marks, StagedMlpNetwork};

/// Hidden layers of the student's MLP.
const LAYERS: usize = frmd_firmware_support::shape::MLP_HIDDEN.len();

#[entry]
fn main() -> ! {
    let stack = bench::start();
    let mut workload = images::student_workload();
    bench::run_then::<_, { CASES * 5 }>(&mut workload, stack, |_, calibration, digest| {
        if let Err(error) = breakdown(calibration, digest) {
            exit_failure(&error);
        }
    })
}

/// The per-stage breakdown: the same baked MLP through a layer-marking network. Not inlined, so
/// its frame (a second policy) is not part of the main measurement's stack.
#[inline(never)]
fn breakdown(calibration: &Calibration, digest: u64) -> Result<(), PolicyError> {
    let (hidden, output, variants) = baked::mlp_parts()?;
    let mut layer_macs = hidden.map(|layer| (layer.fc.in_features * layer.fc.out_features) as u64);
    if baked::INPUT_PRECISION == InputPrecision::TwoPlane {
        // The first layer's kernel runs on both input planes.
        layer_macs[0] *= 2;
    }
    let output_macs = (output.fc.in_features * output.fc.out_features) as u64;
    let network = StagedMlpNetwork::<LAYERS, { mlp_marks(LAYERS) }, { baked::SCRATCH_WIDTH }>::new(
        baked::INPUT,
        hidden,
        output,
        variants,
        stage_report::systick,
    )?
    .with_input_precision(baked::INPUT_PRECISION);
    let policy = Policy::new(baked::config(), network)?;
    let mut staged: StudentWorkload<_> = PolicyWorkload::with_name(policy, STUDENT_NAME);
    stage_report::mlp_policy(&mut staged, &layer_macs, output_macs, calibration, digest)
}
