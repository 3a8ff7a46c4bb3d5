//! The distillation objectives of `DistillConfig` on the toy bimodal set: each trains, and the
//! ODE-map student reproduces its teacher's one-step map.
use super::distill::{distill_quietly, DistillConfig};
use super::teacher::{train_teacher, TeacherConfig};
use super::{LoopConfig, Progress};
use crate::data::toy::{bimodal_windows, positive_fraction, toy_condition, toy_prodmp_config};
use crate::diffusion::consistency::{Distance, Jump, LevelSampling, LevelWeight};
use crate::diffusion::loss::{LossWeight, SigmaSampling};
use crate::diffusion::samplers::{gaussian, sample_consistency, sample_teacher, Solver};
use crate::models::OwnedNetwork;
use crate::rng::HostRng;
use candle_core::Device;
use frmd_core::sigma::SigmaConfig;

fn toy_teacher(
    steps: usize,
) -> (
    crate::models::ModelConfig,
    crate::data::WindowSet,
    OwnedNetwork,
) {
    let cfg = toy_prodmp_config();
    let windows = bimodal_windows(&cfg, 512, 2).unwrap();
    let sampling = SigmaSampling {
        uniform_fraction: 0.2,
    };
    let (teacher, _) = train_teacher(
        &windows,
        &cfg,
        &SigmaConfig::default(),
        &TeacherConfig::plain(LossWeight::Uniform, sampling),
        &LoopConfig::toy(steps, 4),
        &mut |_: &Progress| Ok(()),
    )
    .unwrap();
    (cfg, windows, teacher)
}

fn weights_of(net: &OwnedNetwork) -> Vec<f32> {
    crate::models::init::sorted_vars(&net.varmap)
        .iter()
        .flat_map(|(_, v)| {
            v.as_tensor()
                .flatten_all()
                .unwrap()
                .to_vec1::<f32>()
                .unwrap()
        })
        .collect()
}

#[test]
fn every_objective_trains_and_moves_the_student() {
    let (_, windows, teacher) = toy_teacher(200);
    let base = DistillConfig {
        levels: 10,
        ..DistillConfig::default()
    };
    let variants = [
        DistillConfig {
            distance: Distance::PseudoHuber,
            level_weight: LevelWeight::InverseGap,
            level_sampling: LevelSampling::LogNormal,
            target_ema: 0.0,
            levels_start: Some(4),
            ..base.clone()
        },
        DistillConfig {
            anchor_sigma: 0.5,
            ..base.clone()
        },
        DistillConfig {
            jump: Jump::Far,
            teacher_steps: 3,
            dsm_weight: 1.0,
            ..base.clone()
        },
        DistillConfig {
            consistency_weight: 0.0,
            map_weight: 1.0,
            map_steps: 4,
            ..base.clone()
        },
        DistillConfig {
            map_only_steps: 20,
            map_weight: 0.5,
            ..base.clone()
        },
    ];
    let before = weights_of(&teacher);
    let run = |dcfg: &DistillConfig| {
        distill_quietly(&teacher, &windows, dcfg, &LoopConfig::toy(40, 1)).unwrap()
    };
    for dcfg in variants {
        let out = run(&dcfg);
        assert!(
            out.report.loss_curve.iter().all(|(_, l)| l.is_finite()),
            "{dcfg:?}"
        );
        assert_ne!(
            weights_of(&out.student),
            before,
            "{dcfg:?}: nothing learned"
        );
        let again = run(&dcfg);
        assert_eq!(
            out.report.loss_curve, again.report.loss_curve,
            "{dcfg:?}: not reproducible"
        );
    }
}

/// On-policy windows add the ODE-map term on their states: the run is reproducible, differs
/// from the run without them, and a zero weight gives that run back bit for bit.
#[test]
fn on_policy_windows_add_a_map_term_on_their_states() {
    let (cfg, windows, teacher) = toy_teacher(200);
    let visited = bimodal_windows(&cfg, 64, 9).unwrap();
    let sig = SigmaConfig::default();
    let run = |on_policy: Option<&crate::data::WindowSet>, weight: f64| {
        let dcfg = DistillConfig {
            levels: 10,
            on_policy_weight: weight,
            ..DistillConfig::default()
        };
        super::distill::distill(
            &teacher,
            &windows,
            on_policy,
            &sig,
            &dcfg,
            &LoopConfig::toy(30, 1),
            &mut |_: &Progress| Ok(()),
        )
        .unwrap()
    };
    let plain = run(None, 1.0);
    let with = run(Some(&visited), 1.0);
    assert_eq!(
        with.report.loss_curve,
        run(Some(&visited), 1.0).report.loss_curve
    );
    assert_ne!(weights_of(&with.student), weights_of(&plain.student));
    assert!(with.report.loss_curve.iter().all(|(_, l)| l.is_finite()));
    let off = run(Some(&visited), 0.0);
    assert_eq!(weights_of(&off.student), weights_of(&plain.student));
}

/// Regressing one student step on the teacher's DPM-Solver++(2M) solution keeps both modes of
/// the bimodal set in the teacher's proportion.
#[test]
fn ode_map_student_keeps_the_teachers_modes() {
    let (cfg, windows, teacher) = toy_teacher(3000);
    let sig = SigmaConfig::default();
    let dcfg = DistillConfig {
        consistency_weight: 0.0,
        map_weight: 1.0,
        ..DistillConfig::default()
    };
    let loop_cfg = LoopConfig::toy(600, 6).with_lr(1e-3);
    let out = distill_quietly(&teacher, &windows, &dcfg, &loop_cfg).unwrap();
    let first = out.report.loss_curve.first().unwrap().1;
    let last = out.report.final_loss().unwrap();
    assert!(last < 0.5 * first, "map loss {first} -> {last}");
    let batch = 400;
    let cond = toy_condition(batch).unwrap();
    let mut rng = HostRng::new(11);
    let z = gaussian(&mut rng, batch, cfg.traj_dim(), &Device::Cpu).unwrap();
    let start = (&z * sig.sigma_max).unwrap();
    let teacher_out =
        sample_teacher(&teacher.net, &sig, &cond, start, 10, Solver::DpmPp2m).unwrap();
    let student_out =
        sample_consistency(&out.eval_student.net, &sig, &cond, &z, 1, &mut rng).unwrap();
    let flat = |t: &candle_core::Tensor| t.flatten_all().unwrap().to_vec1::<f32>().unwrap();
    let (tf, sf) = (flat(&teacher_out), flat(&student_out));
    let (tp, sp) = (
        positive_fraction(&tf, cfg.horizon),
        positive_fraction(&sf, cfg.horizon),
    );
    // Same z, same mode: the student follows the teacher's map sample by sample.
    let agree = tf
        .chunks_exact(cfg.horizon)
        .zip(sf.chunks_exact(cfg.horizon))
        .filter(|(a, b)| (a.last().unwrap() > &0.0) == (b.last().unwrap() > &0.0))
        .count() as f64
        / batch as f64;
    assert!(
        (tp - sp).abs() <= 0.1,
        "mode weights teacher {tp}, student {sp}"
    );
    assert!(
        agree > 0.85,
        "student picks the teacher's mode for {agree} of the draws"
    );
}
