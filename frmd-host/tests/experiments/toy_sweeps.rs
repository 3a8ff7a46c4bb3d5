//! Sweeps on the toy bimodal data set (`frmd_host::data::toy`): teacher loss weights, solvers
//! and step counts, and distillation settings (levels, learning rate, steps, solver), measured
//! by the fraction of samples in the positive mode and the error of the chunk's last step.
//! No environment needed: `cargo test -p frmd-host --test experiments toy_ -- --ignored
//! --nocapture`.
use candle_core::Device;
use frmd_core::sigma::SigmaConfig;
use frmd_host::data::toy::{bimodal_windows, positive_fraction, toy_condition, toy_config};
use frmd_host::diffusion::loss::{LossWeight, SigmaSampling};
use frmd_host::diffusion::samplers::{gaussian, sample_consistency, sample_teacher, Solver};
use frmd_host::models::{HeadConfig, ProDmpOutput};
use frmd_host::rng::HostRng;
use frmd_host::train::distill::{distill, DistillConfig};
use frmd_host::train::teacher::{train_teacher, TeacherConfig};
use frmd_host::train::{LoopConfig, Progress};

/// The log-normal noise levels alone.
const LOGNORMAL: SigmaSampling = SigmaSampling {
    uniform_fraction: 0.0,
};

#[test]
#[ignore]
fn toy_teacher_weights_and_solvers() {
    let cfg = toy_config(HeadConfig::ProDmp {
        num_basis: 4,
        output: ProDmpOutput::Direct,
        auto_scale_basis: false,
    });
    let windows = bimodal_windows(&cfg, 512, 2).unwrap();
    let sig = SigmaConfig::default();
    let goal_end = windows.actions[cfg.horizon - 1].abs() as f64;
    for weight in [
        LossWeight::Edm,
        LossWeight::Uniform,
        LossWeight::InvSigmaSquared,
    ] {
        for (steps, lr) in [(1500, 3e-3), (1500, 1e-3), (4000, 3e-3)] {
            let mut lc = LoopConfig::toy(steps, 4);
            lc.optim.lr = lr;
            let (teacher, rep) = train_teacher(
                &windows,
                &cfg,
                &sig,
                &TeacherConfig::plain(weight, LOGNORMAL),
                &lc,
                &mut |_: &Progress| Ok(()),
            )
            .unwrap();
            let batch = 400;
            let cond = toy_condition(batch).unwrap();
            let mut rng = HostRng::new(11);
            let z = gaussian(&mut rng, batch, cfg.traj_dim(), &Device::Cpu).unwrap();
            for (solver, n) in [
                (Solver::Heun, 10),
                (Solver::Euler, 10),
                (Solver::DpmPp2m, 10),
                (Solver::Heun, 40),
            ] {
                let s = sample_teacher(
                    &teacher.net,
                    &sig,
                    &cond,
                    (&z * sig.sigma_max).unwrap(),
                    n,
                    solver,
                )
                .unwrap();
                let flat = s.flatten_all().unwrap().to_vec1::<f32>().unwrap();
                let err = flat
                    .chunks_exact(cfg.horizon)
                    .map(|r| ((*r.last().unwrap() as f64).abs() - goal_end).abs())
                    .sum::<f64>()
                    / batch as f64;
                eprintln!("{weight:?} steps {steps} lr {lr}: loss {:.4} {solver:?}x{n}: +frac {:.3} err {err:.4}", rep.final_loss().unwrap(), positive_fraction(&flat, cfg.horizon));
            }
        }
    }
}

#[test]
#[ignore]
fn toy_distill_settings() {
    let cfg = toy_config(HeadConfig::ProDmp {
        num_basis: 4,
        output: ProDmpOutput::Direct,
        auto_scale_basis: false,
    });
    let windows = bimodal_windows(&cfg, 512, 2).unwrap();
    let sig = SigmaConfig::default();
    let goal_end = windows.actions[cfg.horizon - 1].abs() as f64;
    let (teacher, _) = train_teacher(
        &windows,
        &cfg,
        &sig,
        &TeacherConfig::plain(LossWeight::Edm, LOGNORMAL),
        &LoopConfig::toy(4000, 4),
        &mut |_: &Progress| Ok(()),
    )
    .unwrap();
    let batch = 400;
    let cond = toy_condition(batch).unwrap();
    for (levels, lr, steps, solver) in [
        (18, 1e-3, 2000, Solver::Heun),
        (18, 3e-4, 2000, Solver::Heun),
        (18, 1e-3, 5000, Solver::Heun),
        (40, 1e-3, 5000, Solver::Heun),
        (10, 1e-3, 2000, Solver::Heun),
        (18, 1e-3, 2000, Solver::Euler),
    ] {
        let mut dcfg = LoopConfig::toy(steps, 6);
        dcfg.optim.lr = lr;
        let t0 = std::time::Instant::now();
        let d = distill(
            &teacher,
            &windows,
            &sig,
            &DistillConfig {
                levels,
                solver,
                eval_ema: 0.99,
                ..DistillConfig::default()
            },
            &dcfg,
            &mut |_: &Progress| Ok(()),
        )
        .unwrap();
        let secs = t0.elapsed().as_secs_f64();
        for (name, net) in [("ema", &d.eval_student), ("raw", &d.student)] {
            for n in 1..=3 {
                let mut rng = HostRng::new(11);
                let z = gaussian(&mut rng, batch, cfg.traj_dim(), &Device::Cpu).unwrap();
                let s = sample_consistency(&net.net, &sig, &cond, &z, n, &mut rng).unwrap();
                let flat = s.flatten_all().unwrap().to_vec1::<f32>().unwrap();
                let err = flat
                    .chunks_exact(cfg.horizon)
                    .map(|r| ((*r.last().unwrap() as f64).abs() - goal_end).abs())
                    .sum::<f64>()
                    / batch as f64;
                eprintln!("N {levels} lr {lr} steps {steps} {solver:?} ({secs:.1}s) loss {:.5} {name} x{n}: +frac {:.3} err {err:.4}", d.report.final_loss().unwrap(), positive_fraction(&flat, cfg.horizon));
            }
        }
    }
}
