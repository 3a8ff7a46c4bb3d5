//! Evaluator tests: chunk execution, seed streams, input conventions, plotting.
use super::{plot::plot_paths, run_episodes, EvalConfig};
use crate::tasks::{Policy, PolicyInput};

/// Holds the end effector still with 12-action chunks, and checks the input conventions.
struct Hold {
    calls: usize,
    first_prev: Option<Vec<f32>>,
}

impl Policy for Hold {
    fn name(&self) -> String {
        "hold".into()
    }
    fn reset(&mut self, _seed: u64) {
        self.first_prev = None;
    }
    fn act(&mut self, input: &PolicyInput<'_>) -> anyhow::Result<Vec<Vec<f32>>> {
        self.calls += 1;
        assert_eq!(input.obs_history.len(), 3);
        let obs = input.obs_history.last().unwrap();
        if self.first_prev.is_none() {
            // At the start the previous action is the end-effector position, at rest.
            assert_eq!(input.prev_action, &obs[..2]);
            assert_eq!(input.prev_rate, &[0.0, 0.0]);
            assert_eq!(input.obs_history[0], input.obs_history[2]);
            self.first_prev = Some(input.prev_action.to_vec());
        }
        Ok(vec![input.prev_action.to_vec(); 12])
    }
}

#[test]
fn executes_the_configured_part_of_each_chunk() {
    let mut hold = Hold {
        calls: 0,
        first_prev: None,
    };
    let cfg = EvalConfig {
        episodes: 2,
        exec_steps: 8,
        history: 3,
        warmup_calls: 3,
        ..EvalConfig::default()
    };
    let report = run_episodes("reach", &mut hold, &cfg).unwrap();
    // reach allows 100 steps: ceil(100 / 8) = 13 chunks per episode, plus 3 warm-up calls.
    assert_eq!(report.successes, 0);
    assert!(report.per_episode.iter().all(|r| r.length == 100));
    assert_eq!(report.chunk_calls, 26);
    assert_eq!(hold.calls, 29);
    assert_eq!(report.success_ci95[0], 0.0);
    assert_eq!(report.non_smooth_ee_mean, 0.0);
}

struct Wrong;

impl Policy for Wrong {
    fn name(&self) -> String {
        "wrong".into()
    }
    fn reset(&mut self, _seed: u64) {}
    fn act(&mut self, _input: &PolicyInput<'_>) -> anyhow::Result<Vec<Vec<f32>>> {
        Ok(vec![vec![0.0; 3]])
    }
}

#[test]
fn bad_policy_output_is_an_error_not_a_panic() {
    let cfg = EvalConfig {
        episodes: 1,
        warmup_calls: 0,
        ..EvalConfig::default()
    };
    let message = format!("{:#}", run_episodes("push", &mut Wrong, &cfg).unwrap_err());
    assert!(
        message.contains("3 values") && message.contains("expects 2"),
        "{message}"
    );
    let zero = EvalConfig {
        exec_steps: 0,
        ..cfg.clone()
    };
    assert!(run_episodes("push", &mut Wrong, &zero).is_err());
    assert!(run_episodes("nope", &mut Wrong, &cfg).is_err());
}

#[test]
fn plots_expert_paths_as_png() {
    let mut expert = crate::eval::expert_policy("avoid").unwrap();
    let cfg = EvalConfig {
        episodes: 4,
        keep_paths: 3,
        warmup_calls: 0,
        ..EvalConfig::default()
    };
    let report = run_episodes("avoid", expert.as_mut(), &cfg).unwrap();
    assert_eq!(report.kept_paths.len(), 3);
    for (kept, record) in report.kept_paths.iter().zip(&report.per_episode) {
        assert_eq!(kept.ee_path.len(), record.length + 1);
        assert_eq!(kept.seed, record.seed);
    }
    let out = std::env::temp_dir().join(format!("frmd-plot-test-{}.png", std::process::id()));
    plot_paths(&out, &report).unwrap();
    let bytes = std::fs::read(&out).unwrap();
    std::fs::remove_file(&out).ok();
    assert!(bytes.starts_with(b"\x89PNG"), "not a PNG");
    let json = serde_json::to_value(&report).unwrap();
    assert_eq!(json["episodes"], 4);
    assert!(json["per_episode"].as_array().unwrap().len() == 4);
}
