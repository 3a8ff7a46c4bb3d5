//! `frmd eval --firmware CORE`: the closed loop through the emulated MCU (the library side is
//! [`crate::firmware`]).
use crate::eval::{evaluate, EvalConfig, EvalReport};
use crate::firmware::lockstep::{Lockstep, LockstepCount};
use crate::firmware::policy::{FirmwareInfo, FirmwarePolicy, InstructionStats};
use crate::firmware::Board;
use crate::policy::int8::Int8Policy;
use crate::tasks::Policy;
use serde::Serialize;
use std::path::Path;
use std::process::ExitCode;

/// What `frmd eval --firmware` runs.
pub struct FirmwareEval<'a> {
    pub task: &'a str,
    /// Core of the `pil` image.
    pub board: Board,
    /// Baked module directory to build into the image (else the checked-in reach student).
    pub baked: Option<&'a Path>,
    /// Also run the host int8 policy of `blob` on every request and count differing chunks.
    pub check_host: bool,
    /// The host int8 policy's blob (`--blob`, or the one beside `--baked`).
    pub blob: Option<&'a Path>,
    pub json: Option<&'a Path>,
    pub episodes: usize,
    pub exec_steps: usize,
    pub first_seed: u64,
}

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

/// Runs the closed loop through the emulated MCU and prints the report.
pub fn run(args: &FirmwareEval<'_>) -> anyhow::Result<ExitCode> {
    let board = args.board;
    eprintln!("building the pil image for {board} (examples/cortex-m/run-qemu.sh) ...");
    let image = crate::firmware::build(&crate::firmware::default_repo(), board, args.baked)?;
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
        let path = args.blob.ok_or_else(|| anyhow::anyhow!("--check-host needs the host policy: pass --baked DIR (with policy.blob) or --blob FILE"))?;
        let mut lockstep = Lockstep::new(firmware, Int8Policy::load(path)?);
        let report = evaluate(args.task, &mut lockstep, &cfg)?;
        let stats = lockstep.lead.stats();
        lockstep.lead.close()?;
        (report, stats, Some(lockstep.count))
    } else {
        let mut firmware = firmware;
        let report = evaluate(args.task, &mut firmware as &mut dyn Policy, &cfg)?;
        let stats = firmware.stats();
        firmware.close()?;
        (report, stats, None)
    };
    print!("{report}");
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
    if let Some(path) = args.json {
        let full = FirmwareReport {
            report: &report,
            firmware: &info,
            instructions: &stats,
            host_check: host_check.as_ref(),
        };
        frmd_formats::artifact::write_atomic(
            path,
            serde_json::to_string_pretty(&full)?.as_bytes(),
        )?;
        println!("  report         {}", path.display());
    }
    let identical = host_check.is_none_or(|count| count.differing_chunks == 0);
    Ok(if identical {
        ExitCode::SUCCESS
    } else {
        ExitCode::FAILURE
    })
}
