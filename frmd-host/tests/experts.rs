//! Task-suite tests: expert success rates, determinism, bimodality of `avoid`, bad actions.
use frmd_host::eval::{eval_seed, rollout, run_episodes, EvalConfig};
use frmd_host::tasks::avoid::AvoidExpert;
use frmd_host::tasks::{make_task, TASK_NAMES};
use frmd_host::tasks::{Policy, PolicyInput};

#[test]
fn every_expert_succeeds_on_at_least_95_percent_of_50_seeds() {
    for &name in TASK_NAMES {
        let mut expert = make_task(name).unwrap().expert();
        let cfg = EvalConfig {
            episodes: 50,
            warmup_calls: 0,
            ..EvalConfig::default()
        };
        let report = run_episodes(name, expert.as_mut(), &cfg).unwrap();
        assert!(
            report.success_rate >= 0.95,
            "{name}: expert success {}",
            report.success_rate
        );
        let task = make_task(name).unwrap();
        assert!(
            report.mean_length < task.max_steps() as f64,
            "{name}: mean length {}",
            report.mean_length
        );
        // Smooth demonstrations: well under one non-smooth transition per episode.
        assert!(
            report.non_smooth_ee_mean < 1.0,
            "{name}: {} non-smooth per episode",
            report.non_smooth_ee_mean
        );
    }
}

#[test]
fn layouts_and_rollouts_are_deterministic_given_the_seed() {
    for &name in TASK_NAMES {
        let mut task = make_task(name).unwrap();
        let mut expert = task.expert();
        let mut record = |seed| {
            let mut obs = Vec::new();
            rollout(
                task.as_mut(),
                expert.as_mut(),
                seed,
                1,
                1,
                0,
                &mut |o, a| {
                    obs.extend_from_slice(o);
                    obs.extend_from_slice(a);
                },
            )
            .unwrap();
            obs
        };
        let (a, b, c) = (record(5), record(5), record(6));
        assert_eq!(a, b, "{name}: same seed, different rollout");
        assert_ne!(a, c, "{name}: different seeds, same rollout");
    }
}

#[test]
fn observations_have_the_documented_size_and_actions_are_checked() {
    for &name in TASK_NAMES {
        let mut task = make_task(name).unwrap();
        task.reset(3);
        assert_eq!(task.observe().len(), task.obs_dim(), "{name}");
        assert_eq!(task.obs_fields().len(), task.obs_dim(), "{name}");
        let before = task.observe();
        assert!(task.step(&[0.0]).is_err(), "{name}: short action accepted");
        assert!(
            task.step(&[f32::NAN, 0.0]).is_err(),
            "{name}: NaN action accepted"
        );
        assert!(
            task.step(&[0.0, 0.0, 0.0]).is_err(),
            "{name}: long action accepted"
        );
        assert_eq!(
            task.observe(),
            before,
            "{name}: rejected action changed the state"
        );
        // A wild but finite action is clamped, not propagated into a blow-up.
        for _ in 0..5 {
            task.step(&[1e30, -1e30]).unwrap();
        }
        assert!(
            task.observe().iter().all(|v| v.is_finite()),
            "{name}: state not finite"
        );
    }
    assert!(make_task("fly").is_err());
}

/// A regressor's answer to bimodal data: the mean of the two modes.
struct MeanOfSides {
    left: AvoidExpert,
    right: AvoidExpert,
}

impl Policy for MeanOfSides {
    fn name(&self) -> String {
        "mean".into()
    }
    fn reset(&mut self, seed: u64) {
        self.left.reset(seed);
        self.right.reset(seed);
    }
    fn act(&mut self, input: &PolicyInput<'_>) -> anyhow::Result<Vec<Vec<f32>>> {
        let (l, r) = (self.left.act(input)?, self.right.act(input)?);
        Ok(vec![l[0]
            .iter()
            .zip(&r[0])
            .map(|(a, b)| 0.5 * (a + b))
            .collect()])
    }
}

#[test]
fn avoid_is_bimodal_and_the_average_of_the_modes_collides() {
    let sides: Vec<f64> = (0..200)
        .map(|i| AvoidExpert::side(eval_seed(0, i)))
        .collect();
    let left = sides.iter().filter(|&&s| s > 0.0).count();
    assert!(
        (70..=130).contains(&left),
        "{left} of 200 episodes pass left"
    );
    // Each forced side alone succeeds; their average drives into the obstacle.
    for side in [1.0, -1.0] {
        let mut expert = AvoidExpert::with_side(side);
        let cfg = EvalConfig {
            episodes: 20,
            warmup_calls: 0,
            ..EvalConfig::default()
        };
        let report = run_episodes("avoid", &mut expert, &cfg).unwrap();
        assert_eq!(report.successes, 20, "side {side}");
    }
    let mut mean = MeanOfSides {
        left: AvoidExpert::with_side(1.0),
        right: AvoidExpert::with_side(-1.0),
    };
    let cfg = EvalConfig {
        episodes: 20,
        warmup_calls: 0,
        ..EvalConfig::default()
    };
    let report = run_episodes("avoid", &mut mean, &cfg).unwrap();
    assert_eq!(
        report.successes, 0,
        "the averaged path got around the obstacle"
    );
    assert!(
        report.per_episode.iter().all(|r| r.failed),
        "averaged path should collide"
    );
}

#[test]
fn insert_jams_when_pressing_beside_the_slot() {
    let mut task = make_task("insert").unwrap();
    task.reset(11);
    let obs = task.observe();
    let (slot_x, wall_y) = (obs[0] + obs[4], obs[1] + obs[5]);
    // Hover 3 cm beside the slot, then press down: the peg lands on the top and stays there.
    for _ in 0..30 {
        task.step(&[slot_x + 0.03, wall_y + 0.2]).unwrap();
    }
    for _ in 0..20 {
        task.step(&[slot_x + 0.03, wall_y - 0.3]).unwrap();
    }
    let obs = task.observe();
    assert!(
        (obs[1] - wall_y).abs() < 1e-4,
        "tip at {} vs wall {wall_y}",
        obs[1]
    );
    assert_eq!(obs[6], 1.0, "contact flag");
    assert!(!task.success());
    // Lifting, centring and pressing again inserts it.
    for target in [
        [slot_x + 0.03, wall_y + 0.2],
        [slot_x, wall_y + 0.2],
        [slot_x, wall_y - 0.3],
    ] {
        for _ in 0..20 {
            task.step(&target).unwrap();
        }
    }
    assert!(task.success(), "tip at {:?}", task.ee_position());
}

#[test]
fn push_moves_the_puck_only_through_contact() {
    let mut task = make_task("push").unwrap();
    task.reset(2);
    let obs = task.observe();
    // The observation holds the puck relative to the end effector.
    let puck = [obs[0] + obs[4], obs[1] + obs[5]];
    // Moving the end effector away from the puck leaves it where it is.
    let away = [
        obs[0] + (obs[0] - puck[0]) * 0.3,
        obs[1] + (obs[1] - puck[1]) * 0.3,
    ];
    for _ in 0..10 {
        task.step(&away).unwrap();
    }
    let after = task.observe();
    let moved_puck = [after[0] + after[4], after[1] + after[5]];
    assert!((moved_puck[0] - puck[0]).abs() < 1e-5 && (moved_puck[1] - puck[1]).abs() < 1e-5);
    // Driving through the puck displaces it.
    for _ in 0..20 {
        task.step(&[puck[0], puck[1]]).unwrap();
    }
    let pushed = task.observe();
    let moved = (pushed[4] - puck[0]).hypot(pushed[5] - puck[1]);
    assert!(moved > 0.1, "puck moved {moved} m");
}

#[test]
fn demonstrations_start_at_the_end_effector_position() {
    // The first commanded action equals the initial end-effector position, so the window
    // padding a_{-1} = a_0 agrees with the evaluator's prev_action at episode start.
    for &name in TASK_NAMES {
        let (data, _) =
            frmd_host::data::collect::collect_demos(name, 3, 40, None, 0, &mut |_| {}).unwrap();
        for range in data.episode_ranges() {
            let obs = &data.obs[range.start * data.obs_dim..][..2];
            let action = &data.action[range.start * data.action_dim..][..2];
            assert_eq!(obs, action, "{name}");
        }
    }
}

/// Median wall time of one `Task::step` under the expert, microseconds (timing: run alone with
/// `cargo test -p frmd-host --test experts step_cost -- --ignored --nocapture`).
#[test]
#[ignore = "timing measurement; flaky on a loaded machine"]
fn step_cost_is_well_under_50_us() {
    for &name in TASK_NAMES {
        let mut task = make_task(name).unwrap();
        let mut expert = task.expert();
        let mut times = Vec::new();
        for index in 0..20 {
            let seed = eval_seed(0, index);
            task.reset(seed);
            expert.reset(seed);
            let mut obs = vec![task.observe()];
            let prev = vec![0.0f32; 2];
            for _ in 0..task.max_steps() {
                let action = expert
                    .act(&PolicyInput {
                        obs_history: &obs,
                        prev_action: &prev,
                        prev_rate: &prev,
                    })
                    .unwrap();
                let started = std::time::Instant::now();
                task.step(&action[0]).unwrap();
                times.push(started.elapsed().as_secs_f64() * 1e6);
                obs[0] = task.observe();
                if task.success() || task.failed() {
                    break;
                }
            }
        }
        let median = frmd_host::eval::metrics::quantile(&times, 0.5);
        let p99 = frmd_host::eval::metrics::quantile(&times, 0.99);
        println!(
            "{name}: step median {median:.2} us, p99 {p99:.2} us over {} steps",
            times.len()
        );
        assert!(median < 25.0, "{name}: median step {median} us");
    }
}

/// Adds a fixed offset to a policy's commands for the first `steps` control steps.
struct Shifted {
    inner: Box<dyn Policy>,
    shift: [f32; 2],
    steps: usize,
    step: usize,
}

impl Policy for Shifted {
    fn name(&self) -> String {
        "shifted".into()
    }

    fn reset(&mut self, seed: u64) {
        self.inner.reset(seed);
        self.step = 0;
    }

    fn act(&mut self, input: &PolicyInput<'_>) -> anyhow::Result<Vec<Vec<f32>>> {
        let mut chunk = self.inner.act(input)?;
        if self.step < self.steps {
            for action in &mut chunk {
                action[0] += self.shift[0];
                action[1] += self.shift[1];
            }
        }
        self.step += 1;
        Ok(chunk)
    }
}

#[test]
fn insert_expert_realigns_instead_of_jamming() {
    // A 3 cm sideways disturbance through the whole approach and descent: pressing down there
    // jams the peg for good (see above). The expert's descent guard holds it above the wall
    // instead, so once the disturbance ends the peg still goes in.
    let mut task = make_task("insert").unwrap();
    for seed in [3, 11, 27] {
        let mut shifted = Shifted {
            inner: task.expert(),
            shift: [0.03, 0.0],
            steps: 90,
            step: 0,
        };
        let run = rollout(task.as_mut(), &mut shifted, seed, 1, 1, 0, &mut |_, _| {}).unwrap();
        assert!(run.success, "seed {seed}: tip at {:?}", task.ee_position());
        assert!(run.steps > 90, "seed {seed}: inserted while disturbed");
    }
}

#[test]
fn push_expert_pushes_again_when_the_puck_stops_short() {
    // Pushing 6 cm off the planned line for the first half of the episode leaves the puck off
    // the target; the expert re-plans from where the puck came to rest.
    let mut task = make_task("push").unwrap();
    for seed in [1, 5, 9] {
        let mut shifted = Shifted {
            inner: task.expert(),
            shift: [0.06, -0.06],
            steps: 60,
            step: 0,
        };
        let run = rollout(task.as_mut(), &mut shifted, seed, 1, 1, 0, &mut |_, _| {}).unwrap();
        assert!(run.success, "seed {seed}: {:?}", task.observe());
    }
}
