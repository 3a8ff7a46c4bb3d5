//! Wall time of one teacher training step (forward, backward, AdamW) on real windows.
//!
//! `cargo run -p frmd-host --example train_step_ms -- [DATA] [BACKBONE] [STEPS] [BATCH]`
//! (defaults: /work/models-runs/reach.safetensors, transformer-lite, 20, 128). Run with
//! `RAYON_NUM_THREADS=1`. Prints the median and mean ms/step over STEPS steps after 3 warm-up
//! steps, and the loss after the last step (a seeded run, so two builds can be compared).
use candle_core::Device;
use frmd_core::sigma::SigmaConfig;
use frmd_host::data::Dataset;
use frmd_host::diffusion::loss::{teacher_loss, LossWeight, SigmaSampling};
use frmd_host::models::{BackboneConfig, HeadConfig, ModelConfig, OwnedNetwork};
use frmd_host::rng::HostRng;
use frmd_host::train::batch::sample;
use frmd_host::train::optim::{OptimConfig, ScheduledAdamW};
use mimalloc::MiMalloc;
use std::time::Instant;

#[global_allocator]
static GLOBAL: MiMalloc = MiMalloc;

fn main() -> anyhow::Result<()> {
    let args: Vec<String> = std::env::args().collect();
    let data = args
        .get(1)
        .map(String::as_str)
        .unwrap_or("/work/models-runs/reach.safetensors");
    let backbone = args
        .get(2)
        .map(String::as_str)
        .unwrap_or("transformer-lite");
    let steps: usize = args.get(3).map(|s| s.parse()).transpose()?.unwrap_or(20);
    let batch: usize = args.get(4).map(|s| s.parse()).transpose()?.unwrap_or(128);
    let dataset = Dataset::load(std::path::Path::new(data))?;
    let (windows, _norm) = dataset.windows(2, 12)?;
    let model = ModelConfig {
        obs_dim: dataset.obs_dim,
        history: 2,
        action_dim: dataset.action_dim,
        horizon: 12,
        control_dt: f64::from(dataset.dt),
        embed_dim: 16,
        backbone: BackboneConfig::parse(backbone)?,
        head: HeadConfig::prodmp(20),
    };
    let device = Device::Cpu;
    let net = OwnedNetwork::new_seeded(&model, 1, &device)?;
    let mut opt = ScheduledAdamW::new(net.varmap.all_vars(), OptimConfig::paper(1000))?;
    let sig = SigmaConfig::default();
    let sampling = SigmaSampling {
        uniform_fraction: 0.2,
    };
    let mut rng = HostRng::derive(1, "train-step-ms");
    let mut times = Vec::new();
    let mut last = 0f32;
    for i in 0..steps + 3 {
        let b = sample(&windows, &model, batch, &mut rng, &device)?;
        let start = Instant::now();
        let loss = teacher_loss(
            &net.net,
            &sig,
            &b.x0,
            &b.cond,
            LossWeight::Uniform,
            sampling,
            &mut rng,
        )?;
        opt.backward_step(&loss)?;
        last = loss.to_scalar::<f32>()?;
        if i >= 3 {
            times.push(start.elapsed().as_secs_f64() * 1e3);
        }
    }
    let mean = times.iter().sum::<f64>() / times.len().max(1) as f64;
    times.sort_by(f64::total_cmp);
    let median = times.get(times.len() / 2).copied().unwrap_or(f64::NAN);
    println!("{backbone} batch {batch}: median {median:.1} ms/step, mean {mean:.1} ms/step over {steps} steps; last loss {last:.6}");
    Ok(())
}
