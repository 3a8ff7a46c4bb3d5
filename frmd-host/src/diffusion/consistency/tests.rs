use super::*;
use candle_core::Device;

fn sig() -> SigmaConfig {
    SigmaConfig::default()
}

#[test]
fn pseudo_huber_is_quadratic_near_zero_and_linear_far_away() {
    let d = Device::Cpu;
    let a = Tensor::from_vec(vec![0.0f32, 0.0, 0.0, 0.0, 3.0, 4.0], (2, 3), &d).unwrap();
    let b = Tensor::zeros((2, 3), candle_core::DType::F32, &d).unwrap();
    let per: Vec<f32> = Distance::PseudoHuber
        .per_sample(&a, &b)
        .unwrap()
        .to_vec1()
        .unwrap();
    let c = PSEUDO_HUBER_C * 3f64.sqrt();
    assert!(per[0].abs() < 1e-9, "zero error gives zero distance");
    let far = (25.0 + c * c).sqrt() - c;
    assert!(
        (f64::from(per[1]) - far).abs() < 1e-5,
        "{} vs {far}",
        per[1]
    );
    let l2: Vec<f32> = Distance::L2.per_sample(&a, &b).unwrap().to_vec1().unwrap();
    assert!((l2[1] - 25.0 / 3.0).abs() < 1e-5);
}

#[test]
fn unit_weights_give_the_plain_mean_square() {
    let d = Device::Cpu;
    let a = Tensor::from_vec(vec![1.0f32, -2.0, 0.5, 4.0], (2, 2), &d).unwrap();
    let b = Tensor::from_vec(vec![0.0f32, 1.0, 0.5, 2.0], (2, 2), &d).unwrap();
    let plain: f32 = (&a - &b)
        .unwrap()
        .sqr()
        .unwrap()
        .mean_all()
        .unwrap()
        .to_scalar()
        .unwrap();
    let got: f32 = Distance::L2
        .weighted_mean(&a, &b, &[1.0, 1.0])
        .unwrap()
        .to_scalar()
        .unwrap();
    assert_eq!(plain, got);
    let weighted: f32 = Distance::L2
        .weighted_mean(&a, &b, &[2.0, 0.0])
        .unwrap()
        .to_scalar()
        .unwrap();
    // (1 + 9) / 2 per element on row 0, times 2, averaged over 2 rows.
    assert!((weighted - 5.0).abs() < 1e-6, "{weighted}");
}

#[test]
fn uniform_adjacent_pairs_use_one_draw_per_sample() {
    let grid = LevelGrid::new(&sig(), 40, 2, Jump::Adjacent, LevelSampling::Uniform).unwrap();
    let mut a = HostRng::new(3);
    let mut b = HostRng::new(3);
    let pairs = grid.draw(64, &mut a);
    for (h, l) in pairs.high.iter().zip(&pairs.low) {
        let j = b.below(38);
        assert_eq!(*h, grid.levels[j]);
        assert_eq!(*l, grid.levels[j + 2]);
    }
    assert_eq!(a.next_u64(), b.next_u64(), "the streams stay in step");
}

#[test]
fn log_normal_sampling_prefers_the_middle_levels() {
    let grid = LevelGrid::new(&sig(), 40, 1, Jump::Adjacent, LevelSampling::LogNormal).unwrap();
    let total: f64 = (0..39).map(|j| grid.probability(j)).sum();
    assert!((total - 1.0).abs() < 1e-12);
    let peak = (0..39)
        .max_by(|&x, &y| grid.probability(x).total_cmp(&grid.probability(y)))
        .unwrap();
    let centre = grid.levels[peak];
    assert!(
        (0.05..5.0).contains(&centre),
        "peak at sigma {centre}, expected near exp(-1.1)"
    );
    assert!(grid.probability(0) < grid.probability(peak) / 10.0);
    let mut rng = HostRng::new(1);
    let pairs = grid.draw(20_000, &mut rng);
    let at_peak = pairs.high.iter().filter(|&&h| h == centre).count() as f64 / 20_000.0;
    assert!((at_peak - grid.probability(peak)).abs() < 0.01);
}

#[test]
fn inverse_gap_weights_average_to_one() {
    for (jump, sampling) in [
        (Jump::Adjacent, LevelSampling::Uniform),
        (Jump::Adjacent, LevelSampling::LogNormal),
        (Jump::Far, LevelSampling::Uniform),
    ] {
        let grid = LevelGrid::new(&sig(), 20, 2, jump, sampling).unwrap();
        let mut rng = HostRng::new(9);
        let pairs = grid.draw(200_000, &mut rng);
        let w = grid.weights(&pairs, LevelWeight::InverseGap);
        let mean = w.iter().sum::<f64>() / w.len() as f64;
        // Heavy-tailed (the smallest gap is tiny): a loose Monte Carlo check of the exact scale.
        assert!(
            (mean - 1.0).abs() < 0.1,
            "{jump:?} {sampling:?}: mean weight {mean}"
        );
        assert!(w.iter().all(|&x| x > 0.0 && x.is_finite()));
    }
}

#[test]
fn far_jumps_reach_every_lower_level_and_zero() {
    let grid = LevelGrid::new(&sig(), 8, 3, Jump::Far, LevelSampling::Uniform).unwrap();
    let mut rng = HostRng::new(5);
    let pairs = grid.draw(5_000, &mut rng);
    assert!(pairs.high.iter().zip(&pairs.low).all(|(h, l)| l < h));
    assert!(pairs.low.contains(&0.0));
    assert!(
        pairs.high.contains(&grid.levels[7]),
        "sigma_min pairs with 0"
    );
    let from_top: Vec<f64> = pairs
        .high
        .iter()
        .zip(&pairs.low)
        .filter(|(h, _)| **h == grid.levels[0])
        .map(|(_, l)| *l)
        .collect();
    for i in 1..8 {
        assert!(from_top.contains(&grid.levels[i]), "level {i} never paired");
    }
}

#[test]
fn grid_rejects_gaps_it_cannot_hold() {
    assert!(LevelGrid::new(&sig(), 2, 2, Jump::Adjacent, LevelSampling::Uniform).is_err());
    assert!(LevelGrid::new(&sig(), 10, 0, Jump::Adjacent, LevelSampling::Uniform).is_err());
}

#[test]
fn curriculum_doubles_in_equal_stages() {
    let c = LevelCurriculum {
        start: 10,
        end: 40,
        total_steps: 300,
    };
    assert_eq!(c.levels_at(0), 10);
    assert_eq!(c.levels_at(99), 10);
    assert_eq!(c.levels_at(100), 20);
    assert_eq!(c.levels_at(200), 40);
    assert_eq!(c.levels_at(299), 40);
    let fixed = LevelCurriculum {
        start: 40,
        end: 40,
        total_steps: 300,
    };
    assert_eq!(fixed.levels_at(0), 40);
}

#[test]
fn sub_grid_runs_from_high_to_low() {
    let g = sub_grid(&[80.0, 2.0], &[0.5, 0.0], 4, 7.0);
    assert_eq!(g.len(), 5);
    assert!((g[0][0] - 80.0).abs() < 1e-9 && (g[4][0] - 0.5).abs() < 1e-9);
    assert!((g[0][1] - 2.0).abs() < 1e-9 && g[4][1] == 0.0);
    for s in 1..5 {
        assert!(g[s][0] < g[s - 1][0] && g[s][1] < g[s - 1][1]);
    }
}
