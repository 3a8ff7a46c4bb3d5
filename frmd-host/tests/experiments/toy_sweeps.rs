//! Sweeps on the toy bimodal data set (`frmd_host::data::toy`): teacher loss weights, solvers
//! and step counts, and distillation settings (levels, learning rate, steps, solver), measured
//! by the fraction of samples in the positive mode and the error of the chunk's last step.
//! No environment needed: `cargo test -p frmd-host --test experiments toy_ -- --ignored
//! --nocapture`.
use candle_core::{Device, Tensor};
use frmd_core::sigma::SigmaConfig;
use frmd_host::data::toy::toy_prodmp_config;
use frmd_host::data::toy::{bimodal_windows, last_step_error, positive_fraction, toy_condition};
use frmd_host::data::WindowSet;
use frmd_host::diffusion::loss::LossWeight;
use frmd_host::diffusion::samplers::{gaussian, sample_consistency, sample_teacher, Solver};
use frmd_host::models::ModelConfig;
use frmd_host::rng::HostRng;
use frmd_host::train::distill::{distill_quietly, DistillConfig};
use frmd_host::train::teacher::train_plain_teacher;
use frmd_host::train::LoopConfig;

/// Samples per measurement.
const BATCH: usize = 400;

/// The toy configuration and its 512 windows of seed 2.
fn toy_data() -> (ModelConfig, WindowSet) {
    let cfg = toy_prodmp_config();
    let windows = bimodal_windows(&cfg, 512, 2).unwrap();
    (cfg, windows)
}

/// `+frac` (fraction in the positive mode) and `err` (last-step error) of `samples`.
fn mode_report(samples: &Tensor, windows: &WindowSet) -> String {
    let flat = samples.flatten_all().unwrap().to_vec1::<f32>().unwrap();
    format!(
        "+frac {:.3} err {:.4}",
        positive_fraction(&flat, windows.horizon),
        last_step_error(&flat, windows)
    )
}

#[test]
#[ignore]
fn toy_teacher_weights_and_solvers() {
    let ((cfg, windows), sig) = (toy_data(), SigmaConfig::default());
    for weight in [
        LossWeight::Edm,
        LossWeight::Uniform,
        LossWeight::InvSigmaSquared,
    ] {
        for (steps, lr) in [(1500, 3e-3), (1500, 1e-3), (4000, 3e-3)] {
            let lc = LoopConfig::toy(steps, 4).with_lr(lr);
            let (teacher, rep) = train_plain_teacher(&windows, &cfg, weight, &lc).unwrap();
            let cond = toy_condition(BATCH).unwrap();
            let mut rng = HostRng::new(11);
            let z = gaussian(&mut rng, BATCH, cfg.traj_dim(), &Device::Cpu).unwrap();
            for (solver, n) in [
                (Solver::Heun, 10),
                (Solver::Euler, 10),
                (Solver::DpmPp2m, 10),
                (Solver::Heun, 40),
            ] {
                let noise = (&z * sig.sigma_max).unwrap();
                let s = sample_teacher(&teacher.net, &sig, &cond, noise, n, solver).unwrap();
                let loss = rep.final_loss().unwrap();
                let report = mode_report(&s, &windows);
                eprintln!(
                    "{weight:?} steps {steps} lr {lr}: loss {loss:.4} {solver:?}x{n}: {report}"
                );
            }
        }
    }
}

#[test]
#[ignore]
fn toy_distill_settings() {
    let ((cfg, windows), sig) = (toy_data(), SigmaConfig::default());
    let (teacher, _) =
        train_plain_teacher(&windows, &cfg, LossWeight::Edm, &LoopConfig::toy(4000, 4)).unwrap();
    let cond = toy_condition(BATCH).unwrap();
    for (levels, lr, steps, solver) in [
        (18, 1e-3, 2000, Solver::Heun),
        (18, 3e-4, 2000, Solver::Heun),
        (18, 1e-3, 5000, Solver::Heun),
        (40, 1e-3, 5000, Solver::Heun),
        (10, 1e-3, 2000, Solver::Heun),
        (18, 1e-3, 2000, Solver::Euler),
    ] {
        let settings = DistillConfig {
            levels,
            solver,
            eval_ema: 0.99,
            ..DistillConfig::default()
        };
        let t0 = std::time::Instant::now();
        let loop_cfg = LoopConfig::toy(steps, 6).with_lr(lr);
        let d = distill_quietly(&teacher, &windows, &settings, &loop_cfg).unwrap();
        let secs = t0.elapsed().as_secs_f64();
        let loss = d.report.final_loss().unwrap();
        for (name, net) in [("ema", &d.eval_student), ("raw", &d.student)] {
            for n in 1..=3 {
                let mut rng = HostRng::new(11);
                let z = gaussian(&mut rng, BATCH, cfg.traj_dim(), &Device::Cpu).unwrap();
                let s = sample_consistency(&net.net, &sig, &cond, &z, n, &mut rng).unwrap();
                let report = mode_report(&s, &windows);
                eprintln!("N {levels} lr {lr} steps {steps} {solver:?} ({secs:.1}s) loss {loss:.5} {name} x{n}: {report}");
            }
        }
    }
}
