//! The measurement harness shared by the firmware binaries: calibrates SysTick, runs every case of
//! a [`Workload`] `CALLS / cases` times, timing each call, and prints the report lines.

use crate::memory::{ImageSizes, StackProbe};
use crate::report::{self, exit_failure, exit_success, report};
use crate::timer::{calibrate, Calibration, CycleCounter, TickCounter};
use frmd_core::hash::Fnv1a64;
use frmd_firmware_support::cpuid::core_name;
use frmd_firmware_support::workload::Workload;

/// Entered right before each measured call, outside the timed interval. The two markers are
/// separate functions (one `nop` and two, so that they are neither removed nor merged) whose
/// addresses tell a trace of executed code (`qemu-cycles.py`) where each measured call starts and
/// ends.
#[no_mangle]
#[inline(never)]
pub extern "C" fn frmd_measure_begin() {
    cortex_m::asm::nop();
}

/// Entered right after each measured call (see [`frmd_measure_begin`]).
#[no_mangle]
#[inline(never)]
pub extern "C" fn frmd_measure_end() {
    cortex_m::asm::nop();
    cortex_m::asm::nop();
}

fn median(samples: &mut [u32]) -> u32 {
    samples.sort_unstable();
    samples.get(samples.len() / 2).copied().unwrap_or(0)
}

/// Paints the stack; call first thing in `main`, before anything deep runs.
pub fn start() -> StackProbe {
    StackProbe::paint()
}

/// Measures `workload` with `CALLS` timed calls (a multiple of its case count), prints the
/// report and ends the run.
pub fn run<W: Workload, const CALLS: usize>(workload: &mut W, stack: StackProbe) -> ! {
    run_then::<W, CALLS>(workload, stack, |_, _, _| {})
}

/// As [`run`], then calls `after` with the workload, the SysTick calibration and the digest (for further
/// measurements such as the per-stage breakdown, which print their own lines) once the main
/// measurement and the peak stack are taken, and before the report lines are printed; `ram:`
/// therefore covers the main measurement only.
pub fn run_then<W: Workload, const CALLS: usize>(
    workload: &mut W,
    stack: StackProbe,
    after: impl FnOnce(&mut W, &Calibration, u64),
) -> ! {
    let Some(mut peripherals) = cortex_m::Peripherals::take() else {
        exit_failure(&"core peripherals already taken");
    };
    let ticks = TickCounter::start(peripherals.SYST);
    let cycles = CycleCounter::start(&mut peripherals.DCB, &mut peripherals.DWT);
    let calibration = calibrate(&ticks);
    if calibration.ticks == 0 {
        exit_failure(&"SysTick calibration failed: the long spin did not take more ticks than the short one (under QEMU, pass -icount shift=0)");
    }
    let cases = workload.cases();
    if cases == 0 || !CALLS.is_multiple_of(cases) {
        exit_failure(&"CALLS must be a non-zero multiple of the workload's case count");
    }
    let repeats = CALLS / cases;

    let mut tick_samples = [0u32; CALLS];
    let mut cycle_samples = [0u32; CALLS];
    let mut total_ticks: u64 = 0;
    // Per case: ticks over its repeats (same input, so the mean is exact to 1/repeats tick).
    let (mut case_min, mut case_max) = (u64::MAX, 0_u64);
    let mut digest = Fnv1a64::new();
    let mut samples = tick_samples.iter_mut().zip(cycle_samples.iter_mut());
    for case in 0..cases {
        if let Err(error) = workload.prepare(case) {
            exit_failure(&error);
        }
        let case_start = total_ticks;
        for _ in 0..repeats {
            frmd_measure_begin();
            let tick_start = ticks.now();
            let cycle_start = cycles.now();
            let result = workload.run();
            let cycle_end = cycles.now();
            let tick_end = ticks.now();
            frmd_measure_end();
            if let Err(error) = result {
                exit_failure(&error);
            }
            let elapsed = TickCounter::elapsed(tick_start, tick_end);
            total_ticks += u64::from(elapsed);
            if let Some((tick_sample, cycle_sample)) = samples.next() {
                *tick_sample = elapsed;
                *cycle_sample = cycle_end.wrapping_sub(cycle_start);
            }
        }
        let case_ticks = total_ticks - case_start;
        case_min = case_min.min(case_ticks);
        case_max = case_max.max(case_ticks);
        workload.digest_outputs(&mut digest);
    }
    let median_ticks = median(&mut tick_samples);
    let median_cycles = median(&mut cycle_samples);
    let peak_stack = stack.peak_bytes();
    let sizes = ImageSizes::of_this_image();
    let digest = digest.finish();
    after(workload, &calibration, digest);

    report!("workload: {}", workload.name());
    report!("core: {}", core_name(peripherals.CPUID.base.read()));
    report!("calls: {}", CALLS);
    report::hex64("digest", digest);
    report!(
        "instructions: {}",
        calibration.instructions(u64::from(median_ticks))
    );
    report::milli(
        "instructions_mean",
        calibration.instructions(total_ticks * 1000) / CALLS as u64,
    );
    let per_call = |ticks: u64| calibration.instructions(ticks * 1000) / repeats as u64;
    report::milli("instructions_min", per_call(case_min));
    report::milli("instructions_max", per_call(case_max));
    report!("systick_ticks: {}", median_ticks);
    if workload.macs() != 0 {
        report!("macs: {}", workload.macs());
    }
    report::milli(
        "instructions_per_systick",
        calibration.milli_instructions_per_tick(),
    );
    if median_cycles != 0 {
        report!("cycles: {}", median_cycles);
    }
    report!("flash: {}", sizes.flash);
    report!("ram: {}", sizes.ram_static + peak_stack);
    report!("flash_text: {}", sizes.text);
    report!("flash_rodata: {}", sizes.rodata);
    report!("ram_static: {}", sizes.ram_static);
    report!("stack_peak: {}", peak_stack);
    exit_success()
}
