//! Where does the int8 student's error come from? Exports a student (as `frmd export`), then runs
//! the f32 sampler of the folded network with one quantization source switched on at a time
//! ("fake quantization": the value is quantized and dequantized in f32) and reports the chunk
//! error against the exact f32 path in action units; the last line is frmd-core's real int8
//! network on the same inputs.
//!
//! `cargo run -p frmd-host --example int8_breakdown -- CKPT DATA [ROWS] [CALIBRATION]`
//!
//! Environment: `EPISODES=n` also runs every variant closed loop on the checkpoint's task (the
//! f32 sampler with the variant's fake quantization; `VARIANTS=a;b` picks variants by label);
//! `HEADROOM` / `ACT_HEADROOM` widen the simulated input / activation ranges; `OBS_STATS=1`
//! prints how far closed-loop observations leave the training range; `INT8_INPUT=1` and
//! `EXPORT_HEADROOM` set the export options of the "real int8" line.
mod sim;
mod variants;

use anyhow::Context;
use frmd_core::policy::Network;
use frmd_core::rng::Rng;
use frmd_export::calibrate::RangeMethod;
use frmd_export::host::MAX_WIDTH;
use frmd_export::ExportOptions;
use frmd_formats::checkpoint::Checkpoint;
use sim::{obs_stats, Sim, SimPolicy};
use std::path::Path;

/// One network evaluation: (step, model input) -> network output.
type Forward<'a> = Box<dyn FnMut(usize, &[f32]) -> anyhow::Result<Vec<f32>> + 'a>;

fn main() -> anyhow::Result<()> {
    let args: Vec<String> = std::env::args().collect();
    let ckpt = Path::new(args.get(1).context("CKPT")?);
    let data = Path::new(args.get(2).context("DATA")?);
    let rows: usize = args.get(3).map(|s| s.parse()).transpose()?.unwrap_or(200);
    let ranges: RangeMethod = args
        .get(4)
        .map(String::as_str)
        .unwrap_or("minmax")
        .parse()?;
    let checkpoint = Checkpoint::read(ckpt)?;
    let set = frmd_host::export::calibration_from_data(data, &checkpoint.meta)?;
    let student = frmd_export::export_checkpoint(
        checkpoint,
        &ExportOptions {
            ranges,
            input_precision: if std::env::var_os("INT8_INPUT").is_none() {
                frmd_core::model::mlp::InputPrecision::Int16
            } else {
                frmd_core::model::mlp::InputPrecision::Int8
            },
            input_headroom: std::env::var("EXPORT_HEADROOM")
                .ok()
                .and_then(|h| h.parse().ok())
                .unwrap_or(frmd_export::DEFAULT_INPUT_HEADROOM),
            activations: Some(frmd_export::Activations::Int8),
            ..ExportOptions::default()
        },
        Some(set.clone()),
    )?;
    let exported = student
        .mlp()
        .context("the breakdown takes an MLP student")?;
    let folded = &exported.folded;
    let c = &folded.base.config;
    let norm = student.normalization().context("normalization")?.clone();
    let traj = c.traj_dim();
    let steps = folded.base.steps.len();
    let rows = rows.min(set.rows());
    println!("input {:?}", exported.ranges.input);
    for (l, (p, o)) in exported.ranges.hidden.iter().enumerate() {
        println!("layer {l}: pre {p:?} out {o:?}");
    }
    let run = |label: &str, mut forward: Forward<'_>| -> anyhow::Result<()> {
        let (mut max_e, mut sum_e, mut n, mut max_p, mut sum_p, mut signed) =
            (0f64, 0f64, 0usize, 0f64, 0f64, 0f64);
        for r in 0..rows {
            let cond = set.row(r);
            let mut noise = vec![0f32; steps * traj];
            Rng::new(0xe901_0000 + r as u64).fill_gaussian(&mut noise);
            let mut exact_params = Vec::new();
            let mut exact = folded.base.sample(cond, &noise, |i, input| {
                let p = folded.forward_observed(i, input, |_, _| {})?;
                exact_params = p.clone();
                Ok(p)
            })?;
            let mut got_params = Vec::new();
            let mut got = folded.base.sample(cond, &noise, |i, input| {
                let p = forward(i, input)?;
                got_params = p.clone();
                Ok(p)
            })?;
            norm.action.denormalize(&mut exact);
            norm.action.denormalize(&mut got);
            for (a, b) in exact.iter().zip(&got) {
                let e = f64::from((a - b).abs());
                signed += f64::from(b - a);
                max_e = max_e.max(e);
                sum_e += e;
                n += 1;
            }
            for (a, b) in exact_params.iter().zip(&got_params) {
                let e = f64::from((a - b).abs());
                max_p = max_p.max(e);
                sum_p += e;
            }
        }
        let np = (rows * folded.output.out_features) as f64;
        println!("{label:<28} chunk max {max_e:.5} mean {:.6} signed {:+.6} (action units) | params max {max_p:.5} mean {:.6}", sum_e / n as f64, signed / n as f64, sum_p / np);
        Ok(())
    };
    let variants = variants::all();
    let closed_loop = std::env::var("EPISODES")
        .ok()
        .map(|e| e.parse::<usize>())
        .transpose()?
        .unwrap_or(0);
    if closed_loop > 0 {
        let task = student.meta().dataset.task.clone();
        let eval = frmd_host::eval::EvalConfig {
            episodes: closed_loop,
            history: c.history,
            ..Default::default()
        };
        let only: Option<Vec<String>> = std::env::var("VARIANTS")
            .ok()
            .map(|v| v.split(';').map(String::from).collect());
        for (label, src) in variants
            .iter()
            .filter(|(l, _)| only.as_ref().is_none_or(|o| o.iter().any(|x| x == l)))
        {
            let sim = Sim::new(folded, &exported.ranges, *src);
            let mut policy = SimPolicy {
                sim: &sim,
                norm: &norm,
                rng: Rng::new(0),
            };
            let report = frmd_host::eval::run_episodes(&task, &mut policy, &eval)?;
            println!(
                "closed loop {label:<28} {task} {closed_loop} episodes: success {:.1} %",
                100.0 * report.success_rate
            );
            if std::env::var_os("OBS_STATS").is_some() {
                println!("  observations (normalized, max |.| per observation) above 1, 1.05, 1.25, 1.5, 2, 3, 4; total; max*1000: {:?}", obs_stats());
            }
        }
        return Ok(());
    }
    for (label, src) in variants {
        let sim = Sim::new(folded, &exported.ranges, src);
        run(label, Box::new(move |i, input| Ok(sim.forward(i, input))))?;
    }
    let mut net = Box::new(frmd_export::mlp::reference::quantized_network::<
        i8,
        MAX_WIDTH,
    >(&exported.policy)?);
    run(
        "real int8 (frmd-core)",
        Box::new(move |i, input| {
            let mut out = vec![0f32; net.output_width()];
            net.forward(i, input, &mut out)?;
            Ok(out)
        }),
    )?;
    Ok(())
}
