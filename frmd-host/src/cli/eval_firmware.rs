//! `frmd eval --firmware CORE`: the closed loop through the emulated MCU (the library side is
//! [`crate::firmware`]).
use super::eval::{print_report, EvalArgs};
use crate::eval::{evaluate, EvalConfig, EvalReport};
use crate::firmware::lockstep::{Lockstep, LockstepCount};
use crate::firmware::policy::{FirmwareInfo, FirmwarePolicy, InstructionStats};
use crate::policy::int8::Int8Policy;
use crate::tasks::Policy;
use serde::Serialize;
use std::process::ExitCode;

/// The JSON report of a firmware evaluation: the usual fields plus the firmware's.
#[derive(Serialize)]
struct FirmwareReport<'a> {
    #[serde(flatten)]
    report: &'a EvalReport,
    firmware: &'a FirmwareInfo,
    instructions: &'a InstructionStats,
    #[serde(skip_serializing_if = "Option::is_none")]
    host_check: Option<&'a LockstepCount>,
}

/// `blob`: the host int8 policy's blob (from `--blob`, or beside `--baked`), for `--check-host`.
pub fn run(
    args: &EvalArgs,
    board: &str,
    blob: Option<&std::path::Path>,
) -> anyhow::Result<ExitCode> {
    anyhow::ensure!(
        args.ckpt.is_none(),
        "--firmware runs a baked int8 policy; --ckpt does not apply (use --baked DIR)"
    );
    eprintln!("building the pil image for {board} (examples/cortex-m/run-qemu.sh) ...");
    let image = crate::firmware::build(
        &crate::firmware::default_repo(),
        board,
        args.baked.as_deref(),
    )?;
    let firmware = FirmwarePolicy::start(&image)?;
    let info = firmware.info().clone();
    let cfg = EvalConfig {
        episodes: args.episodes,
        exec_steps: args.exec_steps,
        history: info.history,
        first_seed: args.first_seed,
        ..EvalConfig::default()
    };
    let (report, stats, host_check) = if args.check_host {
        let path = blob.ok_or_else(|| anyhow::anyhow!("--check-host needs the host policy: pass --baked DIR (with policy.blob) or --blob FILE"))?;
        let mut lockstep = Lockstep::new(firmware, Int8Policy::load(path)?);
        let report = evaluate(&args.task, &mut lockstep, &cfg)?;
        let stats = lockstep.lead.stats();
        lockstep.lead.close()?;
        (report, stats, Some(lockstep.count))
    } else {
        let mut firmware = firmware;
        let report = evaluate(&args.task, &mut firmware as &mut dyn Policy, &cfg)?;
        let stats = firmware.stats();
        firmware.close()?;
        (report, stats, None)
    };
    print_report(&report);
    println!(
        "  firmware       {} ({}, {} / {}), flash {} B, static RAM {} B",
        info.board, info.core, image.machine, image.cpu, info.flash_bytes, info.ram_static_bytes
    );
    println!(
        "  instructions   per chunk (Policy::act) min {} / max {} / mean {:.1} over {} chunks; whole request mean {:.1}",
        stats.act_min, stats.act_max, stats.act_mean, stats.chunks, stats.request_mean
    );
    if let Some(count) = &host_check {
        println!(
            "  host check     {} of {} chunks bit-identical to the host int8 policy{}",
            count.chunks - count.differing_chunks,
            count.chunks,
            count
                .first_difference
                .map_or(String::new(), |i| format!(" (first difference: chunk {i})"))
        );
    }
    if let Some(path) = &args.json {
        let full = FirmwareReport {
            report: &report,
            firmware: &info,
            instructions: &stats,
            host_check: host_check.as_ref(),
        };
        frmd_export::artifact::write_atomic(path, serde_json::to_string_pretty(&full)?.as_bytes())?;
        println!("  report         {}", path.display());
    }
    let identical = host_check.is_none_or(|count| count.differing_chunks == 0);
    Ok(if identical {
        ExitCode::SUCCESS
    } else {
        ExitCode::FAILURE
    })
}
