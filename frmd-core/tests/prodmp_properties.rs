//! Property and error tests of the ProDMP decoder (frmd_core::prodmp).
use frmd_core::prodmp::{
    linear_row, BakedProDmp, ProDmp, ProDmpConfig, ProDmpError, MAX_NUM_BASIS,
};
use proptest::prelude::*;

fn arb_config() -> impl Strategy<Value = ProDmpConfig> {
    (
        (
            1usize..4,
            1usize..14,
            0.2f64..3.0,
            prop_oneof![Just(0.0), 0.0f64..0.3],
        ),
        (5.0f64..60.0, 1.5f64..4.0, 1.0f64..9.0, 0usize..2),
        (
            prop_oneof![Just(0.01), Just(0.005), Just(0.03), 0.004f64..0.05],
            0.5f64..2.0,
            0.5f64..2.0,
        ),
        (any::<bool>(), any::<bool>()),
    )
        .prop_map(
            |(
                (num_dof, num_basis, tau, delay),
                (alpha, alpha_phase, bw, outside),
                (dt, ws, gs),
                (rel, auto),
            )| {
                let num_basis_outside = if num_basis > 2 * outside + 1 {
                    outside
                } else {
                    0
                };
                ProDmpConfig {
                    num_dof,
                    num_basis,
                    tau,
                    delay,
                    alpha,
                    alpha_phase,
                    bandwidth_factor: bw,
                    num_basis_outside,
                    dt,
                    weights_scale: ws,
                    goal_scale: gs,
                    relative_goal: rel,
                    auto_scale_basis: auto,
                }
            },
        )
}

#[derive(Clone, Debug)]
struct Sample {
    params: Vec<f64>,
    y0: Vec<f64>,
    v0: Vec<f64>,
}

fn arb_sample(cfg: &ProDmpConfig) -> impl Strategy<Value = Sample> {
    let n = cfg.num_dof;
    (
        prop::collection::vec(-20.0f64..20.0, n * cfg.num_params_per_dof()),
        prop::collection::vec(-2.0f64..2.0, n),
        prop::collection::vec(-2.0f64..2.0, n),
    )
        .prop_map(|(params, y0, v0)| Sample { params, y0, v0 })
}

fn decode(d: &ProDmp, t0: f64, t: f64, s: &Sample) -> (Vec<f64>, Vec<f64>) {
    let n = d.config().num_dof;
    let (mut pos, mut vel) = (vec![0.0; n], vec![0.0; n]);
    d.decode_at(t0, t, &s.params, &s.y0, &s.v0, &mut pos, &mut vel)
        .unwrap();
    (pos, vel)
}

fn close(a: f64, b: f64, tol: f64) -> bool {
    (a - b).abs() <= tol * b.abs().max(1.0)
}

proptest! {
    #![proptest_config(ProptestConfig { cases: 48, ..ProptestConfig::default() })]

    /// The decoder is linear in (theta, y0, v0) jointly.
    #[test]
    fn decoder_is_linear(
        (cfg, a, b, frac, t0_frac) in arb_config().prop_flat_map(|cfg| {
            (Just(cfg), arb_sample(&cfg), arb_sample(&cfg), 0.0f64..1.0, 0.0f64..0.3)
        }),
        alpha in -3.0f64..3.0,
        beta in -3.0f64..3.0,
    ) {
        let d = ProDmp::new(&cfg).unwrap();
        let t0 = cfg.delay + t0_frac * cfg.tau;
        let t = t0 + frac * cfg.tau;
        let mix = |x: &[f64], y: &[f64]| x.iter().zip(y).map(|(x, y)| alpha * x + beta * y).collect::<Vec<_>>();
        let c = Sample { params: mix(&a.params, &b.params), y0: mix(&a.y0, &b.y0), v0: mix(&a.v0, &b.v0) };
        let (pa, va) = decode(&d, t0, t, &a);
        let (pb, vb) = decode(&d, t0, t, &b);
        let (pc, vc) = decode(&d, t0, t, &c);
        for k in 0..cfg.num_dof {
            let scale = 1.0 + alpha.abs() * pa[k].abs().max(va[k].abs()) + beta.abs() * pb[k].abs().max(vb[k].abs());
            prop_assert!((pc[k] - (alpha * pa[k] + beta * pb[k])).abs() <= 1e-10 * scale);
            prop_assert!((vc[k] - (alpha * va[k] + beta * vb[k])).abs() <= 1e-10 * scale);
        }
    }

    /// Boundary conditions: pos(t0) = y0 and vel(t0) = v0 for any parameters.
    #[test]
    fn initial_conditions_hold(
        (cfg, s, t0_frac) in arb_config().prop_flat_map(|cfg| (Just(cfg), arb_sample(&cfg), 0.0f64..0.5)),
    ) {
        let d = ProDmp::new(&cfg).unwrap();
        let t0 = cfg.delay + t0_frac * cfg.tau;
        let (pos, vel) = decode(&d, t0, t0, &s);
        let theta_scale: f64 = s.params.iter().map(|p| p.abs()).sum::<f64>() + 1.0;
        for k in 0..cfg.num_dof {
            prop_assert!((pos[k] - s.y0[k]).abs() <= 1e-9 * theta_scale, "pos {} y0 {}", pos[k], s.y0[k]);
            prop_assert!((vel[k] - s.v0[k]).abs() <= 1e-9 * theta_scale, "vel {} v0 {}", vel[k], s.v0[k]);
        }
    }

    /// Random configs, including garbage, never panic: they build and decode or return an error.
    #[test]
    fn arbitrary_inputs_never_panic(
        num_basis in 0usize..80,
        outside in 0usize..6,
        floats in prop::array::uniform8(prop_oneof![any::<f64>(), -10.0f64..10.0, Just(f64::NAN), Just(0.0)]),
        time in prop_oneof![any::<f64>(), -1.0f64..20.0],
    ) {
        let cfg = ProDmpConfig {
            num_dof: 1, num_basis, tau: floats[0], delay: floats[1], alpha: floats[2],
            alpha_phase: floats[3], bandwidth_factor: floats[4], num_basis_outside: outside,
            dt: floats[5].abs().max(1e-4), weights_scale: floats[6], goal_scale: floats[7],
            relative_goal: true, auto_scale_basis: floats[7] > 0.0,
        };
        if let Ok(d) = ProDmp::new(&cfg) {
            let mut p = vec![0.0; num_basis + 1];
            let mut v = vec![0.0; num_basis + 1];
            let _ = d.linear_row(0.0, time, &mut p, &mut v);
        }
    }
}

/// Baked f32 tables against the f64 decoder for random policy configs and parameters.
fn baked_matches_f64<const N: usize, const P: usize, const K: usize>(
    control_dt: f64,
    theta: &[[f32; P]; K],
    y0: &[f32; K],
    v0: &[f32; K],
) -> Result<f64, TestCaseError> {
    let cfg = ProDmpConfig::policy(K, P - 1, N, control_dt);
    let baked = BakedProDmp::<N, P>::from_config(&cfg).unwrap();
    let (mut pos, mut vel) = ([[0.0f32; K]; N], [[0.0f32; K]; N]);
    baked.decode(theta, y0, v0, &mut pos, &mut vel).unwrap();
    let d = ProDmp::new(&cfg).unwrap();
    let s = Sample {
        params: theta.iter().flatten().map(|x| *x as f64).collect(),
        y0: y0.iter().map(|x| *x as f64).collect(),
        v0: v0.iter().map(|x| *x as f64).collect(),
    };
    let mut worst: f64 = 0.0;
    for t in 0..N {
        let time = (t + 1) as f64 * control_dt;
        let (p64, v64) = decode(&d, 0.0, time, &s);
        for k in 0..K {
            prop_assert!(
                close(pos[t][k] as f64, p64[k], 1e-4),
                "pos {} vs {}",
                pos[t][k],
                p64[k]
            );
            prop_assert!(
                close(vel[t][k] as f64, v64[k], 1e-4),
                "vel {} vs {}",
                vel[t][k],
                v64[k]
            );
            worst = worst.max((pos[t][k] as f64 - p64[k]).abs() / p64[k].abs().max(1.0));
            worst = worst.max((vel[t][k] as f64 - v64[k]).abs() / v64[k].abs().max(1.0));
        }
    }
    Ok(worst)
}

proptest! {
    #![proptest_config(ProptestConfig { cases: 24, ..ProptestConfig::default() })]

    #[test]
    fn baked_f32_equals_f64_policy_16x11(
        control_dt in 0.02f64..0.1,
        theta in prop::array::uniform2(prop::array::uniform11(-20.0f32..20.0)),
        y0 in prop::array::uniform2(-2.0f32..2.0),
        v0 in prop::array::uniform2(-2.0f32..2.0),
    ) {
        baked_matches_f64::<16, 11, 2>(control_dt, &theta, &y0, &v0)?;
    }

    #[test]
    fn baked_f32_equals_f64_policy_8x6(
        control_dt in 0.02f64..0.2,
        theta in prop::array::uniform7(prop::array::uniform6(-20.0f32..20.0)),
        y0 in prop::array::uniform7(-2.0f32..2.0),
        v0 in prop::array::uniform7(-2.0f32..2.0),
    ) {
        baked_matches_f64::<8, 6, 7>(control_dt, &theta, &y0, &v0)?;
    }
}

#[test]
fn policy_convention() {
    let cfg = ProDmpConfig::policy(7, 10, 16, 0.05);
    assert_eq!(cfg.num_params_per_dof(), 11);
    assert!((cfg.tau - 0.8).abs() < 1e-15);
    assert_eq!(
        (cfg.alpha, cfg.alpha_phase, cfg.bandwidth_factor, cfg.dt),
        (25.0, 2.0, 3.0, 0.01)
    );
    assert!(cfg.relative_goal && !cfg.auto_scale_basis);
    assert_eq!(cfg.validate(), Ok(()));
}

#[test]
fn config_errors_are_named() {
    let good = ProDmpConfig::policy(2, 5, 10, 0.05);
    let with = |f: &dyn Fn(&mut ProDmpConfig)| {
        let mut c = good;
        f(&mut c);
        ProDmp::new(&c).err()
    };
    assert_eq!(with(&|c| c.num_basis = 0), Some(ProDmpError::ZeroBasis));
    assert_eq!(
        with(&|c| c.num_basis = MAX_NUM_BASIS + 1),
        Some(ProDmpError::TooManyBasis)
    );
    assert_eq!(with(&|c| c.num_dof = 0), Some(ProDmpError::ZeroDof));
    assert_eq!(with(&|c| c.tau = 0.0), Some(ProDmpError::NonPositiveTau));
    assert_eq!(with(&|c| c.tau = -1.0), Some(ProDmpError::NonPositiveTau));
    assert_eq!(with(&|c| c.dt = 0.0), Some(ProDmpError::NonPositiveDt));
    assert_eq!(
        with(&|c| c.dt = f64::NAN),
        Some(ProDmpError::NonFiniteConfig)
    );
    assert_eq!(
        with(&|c| c.alpha = 0.0),
        Some(ProDmpError::NonPositiveAlpha)
    );
    assert_eq!(
        with(&|c| c.alpha_phase = -2.0),
        Some(ProDmpError::NonPositiveAlphaPhase)
    );
    assert_eq!(
        with(&|c| c.bandwidth_factor = 0.0),
        Some(ProDmpError::NonPositiveBandwidth)
    );
    assert_eq!(
        with(&|c| c.goal_scale = f64::INFINITY),
        Some(ProDmpError::NonFiniteConfig)
    );
    assert_eq!(
        with(&|c| c.num_basis_outside = 2),
        Some(ProDmpError::TooManyOutsideBasis)
    );
    assert_eq!(
        with(&|c| c.num_basis_outside = usize::MAX),
        Some(ProDmpError::TooManyOutsideBasis)
    );
    assert_eq!(with(&|c| c.dt = 10.0), Some(ProDmpError::GridTooCoarse));
    assert_eq!(with(&|c| c.dt = 1e-12), Some(ProDmpError::GridTooFine));
    assert_eq!(
        ProDmp::with_length_factor(&good, 7).err(),
        Some(ProDmpError::InvalidLengthFactor)
    );
    // b = 1 ignores num_basis_outside like the reference.
    assert!(with(&|c| {
        c.num_basis = 1;
        c.num_basis_outside = 3
    })
    .is_none());
}

#[test]
fn query_errors_are_named() {
    let cfg = ProDmpConfig::policy(2, 5, 10, 0.05);
    let d = ProDmp::new(&cfg).unwrap();
    let (mut p, mut v) = (vec![0.0; 6], vec![0.0; 6]);
    // 6 tau is the last pre-computed time; just beyond it is an error.
    assert!(d.linear_row(0.0, 6.0 * cfg.tau, &mut p, &mut v).is_ok());
    assert_eq!(
        d.linear_row(0.0, 6.0 * cfg.tau + 1e-9, &mut p, &mut v),
        Err(ProDmpError::TimeBeyondPrecompute)
    );
    assert_eq!(
        d.linear_row(f64::NAN, 0.1, &mut p, &mut v),
        Err(ProDmpError::NonFiniteInput)
    );
    assert_eq!(
        d.linear_row(0.0, f64::INFINITY, &mut p, &mut v),
        Err(ProDmpError::NonFiniteInput)
    );
    assert_eq!(
        d.linear_row(0.0, 0.1, &mut p[..5], &mut v),
        Err(ProDmpError::WrongLength)
    );
    let (mut pos, mut vel) = (vec![0.0; 2], vec![0.0; 2]);
    let params = vec![1.0; 12];
    assert_eq!(
        d.decode_at(
            0.0,
            0.1,
            &params[..11],
            &[0.0; 2],
            &[0.0; 2],
            &mut pos,
            &mut vel
        ),
        Err(ProDmpError::WrongLength)
    );
    assert_eq!(
        d.decode_at(0.0, 0.1, &params, &[0.0; 3], &[0.0; 2], &mut pos, &mut vel),
        Err(ProDmpError::WrongLength)
    );
    assert_eq!(
        d.decode_at(
            0.0,
            0.1,
            &params,
            &[f64::NAN, 0.0],
            &[0.0; 2],
            &mut pos,
            &mut vel
        ),
        Err(ProDmpError::NonFiniteInput)
    );
    // The free function agrees with the method.
    let (mut p2, mut v2) = (vec![0.0; 6], vec![0.0; 6]);
    let c1 = d.linear_row(0.0, 0.3, &mut p, &mut v).unwrap();
    let c2 = linear_row(&cfg, 0.0, 0.3, &mut p2, &mut v2).unwrap();
    assert_eq!((c1, &p, &v), (c2, &p2, &v2));
    // Times before the delay clamp to s = 0 (the rows at s = 0 with t0 = 0 are zero).
    let delayed = ProDmpConfig { delay: 0.2, ..cfg };
    let c = linear_row(&delayed, 0.0, 0.1, &mut p, &mut v).unwrap();
    assert_eq!((c.pos_y0, c.pos_v0), (1.0, 0.0));
    assert!(p.iter().all(|x| *x == 0.0));
}

#[test]
fn baked_errors_are_named() {
    let cfg = ProDmpConfig::policy(2, 5, 10, 0.05);
    assert_eq!(
        BakedProDmp::<10, 7>::from_config(&cfg).err(),
        Some(ProDmpError::ParamCountMismatch)
    );
    assert_eq!(
        BakedProDmp::<0, 6>::from_config(&cfg).err(),
        Some(ProDmpError::ZeroHorizon)
    );
    let baked = BakedProDmp::<10, 6>::from_config(&cfg).unwrap();
    let (mut pos, mut vel) = ([[0.0f32; 2]; 10], [[0.0f32; 2]; 10]);
    let mut theta = [[1.0f32; 6]; 2];
    theta[1][3] = f32::NAN;
    assert_eq!(
        baked.decode(&theta, &[0.0; 2], &[0.0; 2], &mut pos, &mut vel),
        Err(ProDmpError::NonFiniteInput)
    );
    // y0 + g near tau with both at f32::MAX overflows.
    theta[1][3] = 0.0;
    theta[1][5] = f32::MAX;
    assert_eq!(
        baked.decode(&theta, &[0.0, f32::MAX], &[0.0; 2], &mut pos, &mut vel),
        Err(ProDmpError::NonFiniteResult)
    );
    // Last baked time is tau: the relative goal dominates, pos(tau) is close to y0 + g.
    theta = [[0.0f32; 6]; 2];
    theta[0][5] = 1.0;
    baked
        .decode(&theta, &[0.5; 2], &[0.0; 2], &mut pos, &mut vel)
        .unwrap();
    assert!((pos[9][0] - 1.5).abs() < 0.05, "pos(tau) = {}", pos[9][0]);
    assert!((pos[9][1] - 0.5).abs() < 0.05, "pos(tau) = {}", pos[9][1]);
}

#[test]
fn rbf_underflow_on_the_grid_is_an_error_with_auto_scale() {
    // Slow phase, narrow RBFs: late on the 6 tau grid every RBF underflows to 0 and the
    // normalization is 0/0 (NaN in mp_pytorch too). Auto scaling needs the whole grid: error.
    let mut cfg = ProDmpConfig::policy(1, 12, 10, 0.1);
    cfg.alpha_phase = 0.7;
    cfg.bandwidth_factor = 6.7;
    cfg.auto_scale_basis = true;
    assert_eq!(ProDmp::new(&cfg).err(), Some(ProDmpError::NonFiniteResult));
    // Without auto scaling, queries inside [0, tau] never reach that part of the grid.
    cfg.auto_scale_basis = false;
    let (mut p, mut v) = (vec![0.0; 13], vec![0.0; 13]);
    assert!(linear_row(&cfg, 0.0, cfg.tau, &mut p, &mut v).is_ok());
}

#[test]
fn error_display_names_the_problem() {
    assert!(format!("{}", ProDmpError::NonPositiveTau).contains("tau"));
    assert!(format!("{}", ProDmpError::TimeBeyondPrecompute).contains("pre-computed"));
}

#[test]
fn lookup_beyond_the_last_grid_point_extrapolates_like_the_reference() {
    // tau / dt = 33.3: the grid has 6 * 33 + 1 = 199 points but s = 6 maps to index 200, so the
    // reference clips the lower index to 197 and extrapolates with weight 3.
    let mut cfg = ProDmpConfig::policy(1, 6, 10, 0.1);
    cfg.dt = 0.03;
    let d = ProDmp::new(&cfg).unwrap();
    assert_eq!(d.num_grid_points(), 199);
    let row = |time: f64| {
        let (mut p, mut v) = (vec![0.0; 7], vec![0.0; 7]);
        let c = d.linear_row(0.0, time, &mut p, &mut v).unwrap();
        p.push(c.pos_y0);
        p
    };
    // Times whose index is (to rounding) exactly 197, 198 and 200.
    let (r197, r198, r200) = (row(197.0 * 0.03), row(198.0 * 0.03), row(6.0));
    for k in 0..8 {
        let extrapolated = r197[k] + 3.0 * (r198[k] - r197[k]);
        let scale = r197[k].abs().max(r198[k].abs()).max(1e-300);
        assert!(
            (r200[k] - extrapolated).abs() <= 1e-6 * scale,
            "{k}: {} vs {extrapolated}",
            r200[k]
        );
    }
    assert!((r200[0] - r198[0]).abs() > 0.0);
}
