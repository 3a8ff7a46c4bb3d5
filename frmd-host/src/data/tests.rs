//! Dataset format, reader validation and training-window tests.
use super::collect::collect_demos;
use super::{ActionBeforeStart, Dataset, Normalizer};
use crate::eval::{eval_seed, EVAL_SEED_OFFSET};
use safetensors::tensor::{Dtype, TensorView};
use std::collections::HashMap;
use std::path::PathBuf;

fn temp_path(name: &str) -> PathBuf {
    std::env::temp_dir().join(format!(
        "frmd-data-test-{}-{name}.safetensors",
        std::process::id()
    ))
}

fn small() -> Dataset {
    Dataset {
        obs: vec![0.0, 1.0, 2.0, 3.0, 4.0],
        action: vec![10.0, 20.0, 30.0, 40.0, 50.0],
        episode_ends: vec![3, 5],
        obs_dim: 1,
        action_dim: 1,
        task: "handmade".into(),
        dt: 0.5,
        source: "test".into(),
        action_before_start: Default::default(),
        extra: Default::default(),
    }
}

/// One tensor of a file: name, dtype, shape, little-endian bytes.
type RawTensor = (&'static str, Dtype, Vec<usize>, Vec<u8>);

/// Serializes tensors without any validation, to build corrupt files.
fn raw(tensors: Vec<RawTensor>, meta: &[(&str, &str)]) -> Vec<u8> {
    let views: Vec<(&str, TensorView<'_>)> = tensors
        .iter()
        .map(|(n, d, s, b)| (*n, TensorView::new(*d, s.clone(), b).unwrap()))
        .collect();
    let meta: HashMap<String, String> = meta
        .iter()
        .map(|(k, v)| (k.to_string(), v.to_string()))
        .collect();
    safetensors::serialize(views, Some(meta)).unwrap()
}

fn f32s(v: &[f32]) -> Vec<u8> {
    v.iter().flat_map(|x| x.to_le_bytes()).collect()
}

fn i64s(v: &[i64]) -> Vec<u8> {
    v.iter().flat_map(|x| x.to_le_bytes()).collect()
}

/// The tensors of [`small`].
fn small_tensors() -> Vec<RawTensor> {
    vec![
        (
            "obs",
            Dtype::F32,
            vec![5, 1],
            f32s(&[0.0, 1.0, 2.0, 3.0, 4.0]),
        ),
        (
            "action",
            Dtype::F32,
            vec![5, 1],
            f32s(&[10.0, 20.0, 30.0, 40.0, 50.0]),
        ),
        ("episode_ends", Dtype::I64, vec![2], i64s(&[3, 5])),
    ]
}

/// [`small_tensors`] with `tensor` in place of the one of its name.
fn with(tensor: RawTensor) -> Vec<RawTensor> {
    small_tensors()
        .into_iter()
        .map(|t| if t.0 == tensor.0 { tensor.clone() } else { t })
        .collect()
}

const META: &[(&str, &str)] = &[("task", "handmade"), ("dt", "0.5"), ("source", "test")];

fn error_of(bytes: &[u8]) -> String {
    format!(
        "{:#}",
        Dataset::from_bytes(bytes).expect_err("corrupt file accepted")
    )
}

#[test]
fn collected_dataset_round_trips_through_a_file() {
    let (data, stats) = collect_demos("avoid", 3, 17, None, 0, &mut |_| {}).unwrap();
    assert_eq!(stats.failed, 0);
    assert_eq!(data.num_episodes(), 3);
    assert_eq!(data.obs_dim, 9);
    assert_eq!(data.dt, 0.1);
    let path = temp_path("roundtrip");
    data.save(&path).unwrap();
    let loaded = Dataset::load(&path).unwrap();
    std::fs::remove_file(&path).ok();
    assert_eq!(loaded, data);
    assert_eq!(
        Dataset::from_bytes(&small().to_bytes().unwrap()).unwrap(),
        small()
    );
}

#[test]
fn after_success_extends_each_episode_by_the_settling_steps() {
    let (plain, _) = collect_demos("avoid", 3, 17, None, 0, &mut |_| {}).unwrap();
    let (settled, _) = collect_demos("avoid", 3, 17, None, 15, &mut |_| {}).unwrap();
    let lengths =
        |d: &Dataset| -> Vec<usize> { d.episode_ranges().iter().map(|r| r.len()).collect() };
    let (short, long) = (lengths(&plain), lengths(&settled));
    assert_eq!(long, short.iter().map(|l| l + 15).collect::<Vec<_>>());
    // The shared part is the same expert run; the added rows stay near the goal (observation
    // columns 4 and 5 are goal - ee), closer at the end than at the first success.
    let o = plain.obs_dim;
    for (p, s) in plain.episode_ranges().iter().zip(settled.episode_ranges()) {
        assert_eq!(
            plain.obs[p.start * o..p.end * o],
            settled.obs[s.start * o..(s.start + p.len()) * o]
        );
        let gap = |row: usize| f32::hypot(settled.obs[row * o + 4], settled.obs[row * o + 5]);
        let (at_success, last) = (gap(s.start + p.len() - 1), gap(s.end - 1));
        assert!(
            at_success < 0.03 && last <= at_success,
            "{at_success} -> {last}"
        );
    }
    assert!(
        settled
            .source
            .contains("15 steps recorded after the first success"),
        "{}",
        settled.source
    );
}

#[test]
fn reader_rejects_corrupt_files_with_the_reason() {
    let good = small().to_bytes().unwrap();
    // Truncated.
    let message = error_of(&good[..good.len() - 7]);
    assert!(message.contains("truncated"), "{message}");
    let message = error_of(&good[..5]);
    assert!(message.contains("truncated"), "{message}");
    // Each case: `small`'s tensors with one replaced or dropped, or its metadata changed.
    let obs64: Vec<u8> = [0.0f64, 1.0, 2.0, 3.0, 4.0]
        .iter()
        .flat_map(|x| x.to_le_bytes())
        .collect();
    let ends32: Vec<u8> = [3i32, 5].iter().flat_map(|x| x.to_le_bytes()).collect();
    let nan_obs = f32s(&[0.0, 1.0, 2.0, f32::NAN, 4.0]);
    let (short_obs, last) = (
        f32s(&[0.0, 1.0, 2.0, 3.0]),
        [META, &[("action_before_start", "last")]].concat(),
    );
    let cases: [(Vec<RawTensor>, &[(&str, &str)], &[&str]); 11] = [
        // Wrong dtype.
        (
            with(("obs", Dtype::F64, vec![5, 1], obs64)),
            META,
            &["`obs` has dtype F64, expected F32"],
        ),
        (
            with(("episode_ends", Dtype::I32, vec![2], ends32)),
            META,
            &["`episode_ends` has dtype I32, expected I64"],
        ),
        // Decreasing episode ends; episode ends not covering the data.
        (
            with(("episode_ends", Dtype::I64, vec![3], i64s(&[3, 2, 5]))),
            META,
            &["not strictly increasing: entry 1 is 2 after 3"],
        ),
        (
            with(("episode_ends", Dtype::I64, vec![2], i64s(&[3, 4]))),
            META,
            &["last episode end is 4 but the dataset has 5 steps"],
        ),
        // NaN.
        (
            with(("obs", Dtype::F32, vec![5, 1], nan_obs)),
            META,
            &["`obs` has a non-finite value NaN at row 3, column 0"],
        ),
        // Row mismatch, missing tensor, missing or bad metadata.
        (
            with(("obs", Dtype::F32, vec![4, 1], short_obs)),
            META,
            &["obs has 4 rows but action has 5 rows"],
        ),
        (
            small_tensors()
                .into_iter()
                .filter(|t| t.0 != "action")
                .collect(),
            META,
            &["missing tensor `action`"],
        ),
        (
            small_tensors(),
            &[("task", "t"), ("source", "s")],
            &["missing metadata `dt`"],
        ),
        (small_tensors(), &last, &["action_before_start", "\"zero\""]),
        (
            small_tensors(),
            &[("task", "t"), ("dt", "fast"), ("source", "s")],
            &["metadata `dt` is \"fast\""],
        ),
        (
            small_tensors(),
            &[("task", "t"), ("dt", "-0.1"), ("source", "s")],
            &["dt is -0.1"],
        ),
    ];
    // The unchanged tensors and metadata are `small` itself.
    assert_eq!(
        Dataset::from_bytes(&raw(small_tensors(), META)).unwrap(),
        small()
    );
    for (tensors, meta, needles) in cases {
        let message = error_of(&raw(tensors, meta));
        assert!(needles.iter().all(|n| message.contains(n)), "{message}");
    }
    // Loading a missing file names it.
    let message = format!("{:#}", Dataset::load(&temp_path("missing")).unwrap_err());
    assert!(
        message.contains("cannot read dataset") && message.contains("missing"),
        "{message}"
    );
    // Saving refuses invalid data too.
    let mut bad = small();
    bad.action[1] = f32::INFINITY;
    assert!(bad.to_bytes().is_err());
}

#[test]
fn windows_follow_the_padding_and_rate_conventions() {
    let (set, norm) = small().windows(2, 3).unwrap();
    // obs in [0, 4] -> o/2 - 1; actions in [10, 50] -> (a - 30)/20.
    assert_eq!(norm.obs.min, vec![0.0]);
    assert_eq!(norm.obs.max, vec![4.0]);
    assert_eq!(norm.action.min, vec![10.0]);
    assert_eq!(norm.action.max, vec![50.0]);
    assert_eq!(set.len(), 5);
    assert_eq!((set.history, set.horizon, set.dt), (2, 3, 0.5));
    assert_eq!(
        set.obs,
        vec![-1.0, -1.0, -1.0, -0.5, -0.5, 0.0, 0.5, 0.5, 0.5, 1.0]
    );
    assert_eq!(set.prev_action, vec![-1.0, -1.0, -0.5, 0.5, 0.5]);
    // (a_{t-1} - a_{t-2}) / dt in normalized units: 0.5 / 0.5 s at t = 2 of the first episode.
    assert_eq!(set.prev_rate, vec![0.0, 0.0, 1.0, 0.0, 0.0]);
    assert_eq!(
        set.actions,
        vec![-1.0, -0.5, 0.0, -0.5, 0.0, 0.0, 0.0, 0.0, 0.0, 0.5, 1.0, 1.0, 1.0, 1.0, 1.0]
    );
    assert!(small().windows(0, 3).is_err());
    assert!(small().windows(2, 0).is_err());
}

#[test]
fn zero_action_before_start_pads_with_the_normalized_zero_action() {
    let data = Dataset {
        action_before_start: ActionBeforeStart::Zero,
        extra: Default::default(),
        ..small()
    };
    let (set, _) = data.windows(2, 3).unwrap();
    let (first, _) = small().windows(2, 3).unwrap();
    // Raw 0 is (0 - 30) / 20 = -1.5 normalized; the first episode's actions are -1, -0.5, 0 and
    // the second's 0.5, 1.
    assert_eq!(set.prev_action, vec![-1.5, -1.0, -0.5, -1.5, 0.5]);
    assert_eq!(set.prev_rate, vec![0.0, 1.0, 1.0, 0.0, 4.0]);
    // Only what comes before the start changes.
    assert_eq!((&set.obs, &set.actions), (&first.obs, &first.actions));
    let back = Dataset::from_bytes(&data.to_bytes().unwrap()).unwrap();
    assert_eq!(back.action_before_start, ActionBeforeStart::Zero);
    assert_eq!(
        Dataset::from_bytes(&small().to_bytes().unwrap())
            .unwrap()
            .action_before_start,
        ActionBeforeStart::First
    );
}

#[test]
fn windows_of_collected_demos_are_normalized() {
    let (data, _) = collect_demos("push", 2, 0, None, 0, &mut |_| {}).unwrap();
    let (set, norm) = data.windows(2, 12).unwrap();
    assert_eq!(set.len(), data.len());
    assert_eq!(set.obs.len(), set.len() * 2 * data.obs_dim);
    assert_eq!(set.actions.len(), set.len() * 12 * data.action_dim);
    for v in set.obs.iter().chain(&set.actions).chain(&set.prev_action) {
        assert!((-1.0..=1.0).contains(v), "{v} outside [-1, 1]");
    }
    // Denormalizing a window's first action gives back the raw action.
    let mut first = set.actions[..2].to_vec();
    norm.action.denormalize(&mut first);
    assert!((first[0] - data.action[0]).abs() < 1e-5 && (first[1] - data.action[1]).abs() < 1e-5);
}

#[test]
fn normalizer_round_trips_and_maps_constants_to_zero() {
    let data = [1.0f32, 5.0, -2.0, 5.0, 3.0, 5.0];
    let norm = Normalizer::fit(&data, 2);
    assert_eq!(norm.min, vec![-2.0, 5.0]);
    assert_eq!(norm.max, vec![3.0, 5.0]);
    let mut x = data.to_vec();
    norm.normalize(&mut x);
    for (a, b) in x.iter().zip([0.2, 0.0, -1.0, 0.0, 1.0, 0.0]) {
        assert!((a - b).abs() < 1e-6, "{x:?}");
    }
    norm.denormalize(&mut x);
    for (a, b) in x.iter().zip(&data) {
        assert!((a - b).abs() < 1e-6);
    }
    assert_eq!(norm.scale(), vec![0.4, 0.0]);
}

#[test]
fn perturbed_demonstrations_record_the_experts_clean_actions() {
    use super::perturb::ActionNoise;
    use crate::tasks::make_task;
    use crate::tasks::PolicyInput;
    let noise = ActionNoise {
        std: 0.02,
        correlation_time: 0.5,
    };
    for task in ["avoid", "push", "insert"] {
        let (plain, _) = collect_demos(task, 3, 5, None, 0, &mut |_| {}).unwrap();
        let (noisy, stats) = collect_demos(task, 3, 5, Some(noise), 0, &mut |_| {}).unwrap();
        let (again, _) = collect_demos(task, 3, 5, Some(noise), 0, &mut |_| {}).unwrap();
        assert_eq!(
            noisy, again,
            "{task}: perturbed collection is deterministic"
        );
        assert_ne!(
            noisy.obs, plain.obs,
            "{task}: the noise moved the end effector"
        );
        assert!(noisy.source.contains("perturbed"), "{}", noisy.source);
        // Replaying the recorded observations through a fresh expert gives the recorded
        // actions: the labels are the expert's answers to the perturbed states.
        let mut expert = make_task(task).unwrap().expert();
        assert_eq!(stats.failed, 0, "{task}");
        for (episode, range) in noisy.episode_ranges().into_iter().enumerate() {
            expert.reset(5 + episode as u64);
            for t in range {
                let obs = noisy.obs[t * noisy.obs_dim..][..noisy.obs_dim].to_vec();
                let input = PolicyInput {
                    obs_history: &[obs],
                    prev_action: &[0.0, 0.0],
                    prev_rate: &[0.0, 0.0],
                };
                let action = expert.act(&input).unwrap();
                assert_eq!(action[0], noisy.action[t * 2..][..2], "{task} step {t}");
            }
        }
    }
    let zero = ActionNoise { std: 0.0, ..noise };
    assert_eq!(
        collect_demos("insert", 2, 5, Some(zero), 0, &mut |_| {})
            .unwrap()
            .0,
        collect_demos("insert", 2, 5, None, 0, &mut |_| {})
            .unwrap()
            .0
    );
    let bad = ActionNoise {
        std: f64::NAN,
        ..noise
    };
    let err = collect_demos("reach", 1, 0, Some(bad), 0, &mut |_| {}).unwrap_err();
    assert!(format!("{err:#}").contains("std"), "{err:#}");
}

#[test]
fn nearly_constant_dimensions_get_the_minimum_range_and_constants_stay_constant() {
    use super::windows::MIN_NORM_RANGE;
    // dim 0: range 0.004 (jitter), dim 1: constant, dim 2: range 2.
    let data = [0.5, 3.0, -1.0, 0.504, 3.0, 1.0];
    let norm = Normalizer::fit(&data, 3).with_min_range(MIN_NORM_RANGE);
    assert!((norm.max[0] - norm.min[0] - MIN_NORM_RANGE).abs() < 1e-6);
    assert!((0.5 * (norm.max[0] + norm.min[0]) - 0.502).abs() < 1e-6);
    assert_eq!((norm.min[1], norm.max[1]), (3.0, 3.0));
    assert_eq!((norm.min[2], norm.max[2]), (-1.0, 1.0));
    let mut row = [0.504, 3.0, 1.0];
    norm.normalize(&mut row);
    assert!(
        (row[0] - 0.4).abs() < 1e-4 && row[1] == 0.0 && row[2] == 1.0,
        "{row:?}"
    );
}

#[test]
fn evaluation_seeds_are_disjoint_from_collection_seeds() {
    for index in [0usize, 1, 1000] {
        assert!(eval_seed(0, index) >= EVAL_SEED_OFFSET);
        assert!(eval_seed(12345, index) >= EVAL_SEED_OFFSET);
    }
    // Collection refuses seeds that would reach into the evaluation stream.
    assert!(collect_demos("reach", 1, EVAL_SEED_OFFSET - 3, None, 0, &mut |_| {}).is_err());
    assert!(collect_demos("reach", 1, 0, None, 0, &mut |_| {}).is_ok());
}

#[test]
fn extra_metadata_round_trips_and_cannot_shadow_a_field() {
    let mut d = small();
    d.extra.insert("fps".into(), "30".into());
    d.extra
        .insert("lerobot_dataset".into(), "/data/cube".into());
    let back = Dataset::from_bytes(&d.to_bytes().unwrap()).unwrap();
    assert_eq!(back, d);
    d.extra.insert("dt".into(), "1".into());
    let err = d.to_bytes().unwrap_err().to_string();
    assert!(err.contains("extra metadata `dt`"), "{err}");
}

/// `frmd collect --policy`: a trained student's rollouts, every episode kept with the executed
/// actions, reproducible per seed; a checkpoint of another task and settling steps are refused.
#[test]
fn policy_rollouts_are_recorded_as_a_dataset() {
    use super::collect::{collect_to_file, CollectConfig, PolicySource};
    let ckpt =
        std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("../examples/cortex-m/policy/reach");
    let cfg = |task: &str, out: PathBuf| CollectConfig {
        task: task.into(),
        episodes: 4,
        seed: 1_000_000,
        out,
        policy: Some(PolicySource {
            ckpt: ckpt.clone(),
            steps: None,
        }),
        ..CollectConfig::default()
    };
    let (a, b) = (temp_path("rollouts-a"), temp_path("rollouts-b"));
    let written = collect_to_file(&cfg("reach", a.clone())).unwrap();
    collect_to_file(&cfg("reach", b.clone())).unwrap();
    let (first, again) = (Dataset::load(&a).unwrap(), Dataset::load(&b).unwrap());
    std::fs::remove_file(&a).ok();
    std::fs::remove_file(&b).ok();
    assert_eq!(first, again);
    assert_eq!(first.num_episodes(), 4);
    assert_eq!(written.stats.attempted, 4);
    assert_eq!(first.task, "reach");
    assert!(
        first.source.contains("every episode kept"),
        "{}",
        first.source
    );
    // A student executes 8 actions of each chunk, so its actions are not all equal.
    assert!(first.action.windows(2).any(|w| w[0] != w[1]));

    let err = collect_to_file(&cfg("avoid", temp_path("rollouts-c")))
        .unwrap_err()
        .to_string();
    assert!(
        err.contains("trained on task `reach`, not `avoid`"),
        "{err}"
    );
    let settle = CollectConfig {
        after_success: 5,
        ..cfg("reach", temp_path("rollouts-d"))
    };
    let err = collect_to_file(&settle).unwrap_err().to_string();
    assert!(err.contains("after-success"), "{err}");
}
