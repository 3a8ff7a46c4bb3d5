//! `frmd import lerobot` on datasets written by a real parquet writer (the `parquet` crate, in
//! LeRobot's file shapes; `frmd-host/python/tests` does the same with pyarrow): both layouts
//! import exactly, every validation names its problem, and an imported dataset trains a policy
//! that `frmd eval` evaluates.
#[path = "../cli_support/mod.rs"]
mod cli_support;
mod writer;

use cli_support::{frmd_ok, rejects, scratch, words, TINY};
use frmd_host::data::lerobot::{import, ImportConfig, ImportError, Layout};
use frmd_host::data::Dataset;
use std::path::Path;
use writer::Lerobot;

const STATE: &str = "observation.state";
const ACTION: &str = "action";

fn sample(layout: Layout) -> Lerobot {
    Lerobot::synthetic(
        layout,
        30.0,
        &[5, 7, 4],
        &[
            (STATE, 6),
            (ACTION, 2),
            ("observation.environment_state", 3),
        ],
    )
}

#[test]
fn both_layouts_import_every_frame_exactly() {
    for layout in [Layout::V2, Layout::V3] {
        let dir = scratch(&format!("lerobot-{layout:?}"));
        let data = sample(layout);
        data.write(&dir, None);
        let imported = import(&dir, &ImportConfig::default()).unwrap();
        let d = &imported.dataset;
        assert_eq!((d.obs_dim, d.action_dim, d.len()), (6, 2, 16), "{layout:?}");
        assert_eq!(d.episode_ends, [5, 12, 16]);
        let column = |c: usize| {
            data.rows
                .iter()
                .flat_map(|r| r.vectors[c].clone())
                .collect::<Vec<f32>>()
        };
        assert_eq!(d.obs, column(0));
        assert_eq!(d.action, column(1));
        assert_eq!(d.dt, (1.0f64 / 30.0) as f32);
        assert_eq!(imported.files, if layout == Layout::V2 { 3 } else { 2 });
        assert!(imported.episodes_checked);
        assert!(
            imported
                .ignored
                .iter()
                .any(|i| i == "observation.images.top (video)"),
            "{:?}",
            imported.ignored
        );
        for (key, value) in [
            ("fps", "30"),
            ("episodes", "3"),
            ("state_key", STATE),
            ("action_key", ACTION),
        ] {
            assert_eq!(d.extra.get(key).map(String::as_str), Some(value), "{key}");
        }
        assert!(d.extra["lerobot_dataset"].ends_with(&format!("lerobot-{layout:?}")));
        // The metadata survives the file format.
        let file = dir.join("out.safetensors");
        d.save(&file).unwrap();
        assert_eq!(&Dataset::load(&file).unwrap(), d);
        // Other columns by flag.
        let cfg = ImportConfig {
            state_key: "observation.environment_state".into(),
            task: Some("cube".into()),
            ..ImportConfig::default()
        };
        let other = import(&dir, &cfg).unwrap().dataset;
        assert_eq!(
            (other.obs_dim, other.obs, other.task.as_str()),
            (3, column(2), "cube")
        );
    }
}

/// Imports `data` (with info.json edited by `edit`) and returns the error.
fn error_of(
    data: &Lerobot,
    edit: impl FnOnce(&mut serde_json::Value),
    cfg: &ImportConfig,
) -> ImportError {
    let dir = scratch("lerobot-bad");
    let mut info = data.info();
    edit(&mut info);
    data.write(&dir, Some(info));
    let err = import(&dir, cfg).expect_err("an invalid dataset");
    let text = err.to_string();
    assert!(
        text.contains(&dir.display().to_string()),
        "the message names the file: {text}"
    );
    err
}

#[test]
fn every_invalid_dataset_is_a_named_error() {
    let cfg = ImportConfig::default();
    for layout in [Layout::V2, Layout::V3] {
        let good = sample(layout);
        let with = |change: &dyn Fn(&mut Lerobot)| {
            let mut d = good.clone();
            change(&mut d);
            d
        };
        let keep = |_: &mut serde_json::Value| {};
        // A key that info.json does not list, and a listed column missing from the files.
        let e = error_of(
            &good,
            keep,
            &ImportConfig {
                action_key: "action.joints".into(),
                ..cfg.clone()
            },
        );
        assert!(
            matches!(&e, ImportError::MissingKey { key, path, .. } if key == "action.joints" && path.ends_with("meta/info.json")),
            "{e}"
        );
        let e = error_of(
            &good,
            |i| i["features"]["effort"] = serde_json::json!({"dtype": "float32", "shape": [2]}),
            &ImportConfig {
                action_key: "effort".into(),
                ..cfg.clone()
            },
        );
        assert!(
            matches!(&e, ImportError::MissingKey { key, path, found } if key == "effort" && path.extension().unwrap() == "parquet" && found.iter().any(|f| f == ACTION)),
            "{e}"
        );
        // Ragged episodes: a missing frame, a repeated one, a short vector, a wrong length in the
        // episodes metadata.
        let cases: [(&dyn Fn(&mut Lerobot), &str); 3] = [
            (
                &|d| {
                    d.rows.remove(2);
                },
                "frame_index 3 follows 1",
            ),
            (&|d| d.rows[3].frame = 2, "frame_index 2 appears twice"),
            (
                &|d| {
                    d.rows[6].vectors[0].pop();
                },
                "`observation.state` has 5 values, info.json's shape has 6",
            ),
        ];
        for (change, text) in cases {
            let e = error_of(
                &with(change),
                |i| i["total_frames"] = serde_json::json!(null),
                &cfg,
            );
            assert!(
                matches!(e, ImportError::RaggedEpisode { .. }) && e.to_string().contains(text),
                "{layout:?}: {e}"
            );
        }
        // The episodes metadata disagrees with data/.
        let e = error_of(
            &with(&|d| d.listed_lengths = Some(vec![5, 8, 4])),
            keep,
            &cfg,
        );
        assert!(
            matches!(e, ImportError::RaggedEpisode { episode: 1, .. })
                && e.to_string()
                    .contains("7 frames in data/, the episodes metadata lists 8"),
            "{e}"
        );
        // Non-finite values.
        let e = error_of(
            &with(&|d| d.rows[8].vectors[1][1] = f32::INFINITY),
            keep,
            &cfg,
        );
        assert!(
            matches!(&e, ImportError::NonFinite { key, episode: 1, frame: 3, element: 1, .. } if key == ACTION),
            "{e}"
        );
        let e = error_of(&with(&|d| d.rows[0].vectors[0][4] = f32::NAN), keep, &cfg);
        assert!(
            matches!(&e, ImportError::NonFinite { key, episode: 0, frame: 0, element: 4, .. } if key == STATE),
            "{e}"
        );
        // fps that the timestamps contradict (recorded at 15 frames per second).
        let e = error_of(&good, |i| i["fps"] = serde_json::json!(15), &cfg);
        assert!(
            matches!(
                e,
                ImportError::FpsMismatch {
                    episode: 0,
                    frame: 1,
                    ..
                }
            ),
            "{e}"
        );
        let e = error_of(&with(&|d| d.rows[9].timestamp += 0.01), keep, &cfg);
        assert!(
            matches!(
                e,
                ImportError::FpsMismatch {
                    episode: 1,
                    frame: 4,
                    ..
                }
            ),
            "{e}"
        );
        // Metadata: a version, fps, totals.
        for (field, edit) in [
            (
                "codebase_version",
                &(|i: &mut serde_json::Value| i["codebase_version"] = "v1.6".into())
                    as &dyn Fn(&mut serde_json::Value),
            ),
            ("fps", &|i| i["fps"] = serde_json::json!(0)),
            ("total_episodes", &|i| {
                i["total_episodes"] = serde_json::json!(4)
            }),
            ("total_frames", &|i| {
                i["total_frames"] = serde_json::json!(15)
            }),
        ] {
            let e = error_of(&good, edit, &cfg);
            assert!(
                matches!(&e, ImportError::Metadata { field: f, .. } if f == field),
                "{field}: {e}"
            );
        }
    }
    let e = import(&scratch("lerobot-empty"), &cfg).unwrap_err();
    assert!(
        matches!(&e, ImportError::File { path, .. } if path.ends_with("meta/info.json")),
        "{e}"
    );
}

/// Collects `reach` demonstrations, writes them as a LeRobot v3.0 dataset, imports it with the
/// CLI, trains a tiny teacher and student on it and evaluates the student on `reach`.
#[test]
fn an_imported_dataset_trains_and_evaluates_through_the_cli() {
    let dir = scratch("lerobot-e2e");
    frmd_ok(
        &dir,
        &words("collect --task reach --episodes 4 --out demos.safetensors"),
    );
    let demos = Dataset::load(&dir.join("demos.safetensors")).unwrap();
    let mut data = Lerobot::synthetic(
        Layout::V3,
        f64::from(1.0 / demos.dt),
        &[],
        &[(STATE, 0), (ACTION, 0)],
    );
    let mut start = 0;
    for (e, &end) in demos.episode_ends.iter().enumerate() {
        for (f, t) in (start..end as usize).enumerate() {
            data.rows.push(writer::Row {
                episode: e as i64,
                frame: f as i64,
                timestamp: (f as f64 * f64::from(demos.dt)) as f32,
                vectors: vec![
                    demos.obs[t * demos.obs_dim..(t + 1) * demos.obs_dim].to_vec(),
                    demos.action[t * demos.action_dim..(t + 1) * demos.action_dim].to_vec(),
                ],
            });
        }
        start = end as usize;
    }
    data.write(&dir.join("reach-lerobot"), None);
    let out = frmd_ok(
        &dir,
        &words("import lerobot reach-lerobot --out imported.safetensors --task reach"),
    );
    assert!(
        out.contains("4 episodes") && out.contains("observation.images.top"),
        "{out}"
    );
    let imported = Dataset::load(&dir.join("imported.safetensors")).unwrap();
    assert_eq!(
        (&imported.obs, &imported.action, &imported.episode_ends),
        (&demos.obs, &demos.action, &demos.episode_ends)
    );
    // An existing output is kept unless --force.
    rejects(
        &dir,
        &words("import lerobot reach-lerobot --out imported.safetensors"),
        &["--out", "exists", "--force"],
    );
    rejects(
        &dir,
        &words("import lerobot no-such-dir --out other.safetensors"),
        &["no-such-dir", "info.json"],
    );
    for line in [
        format!("train teacher --data imported.safetensors --out t --steps 5 --backbone mlp:16 {TINY}"),
        "train student --data imported.safetensors --out s --teacher t --steps 5 --batch 8 --warmup 1 --eval-episodes 0".into(),
        "export --ckpt s --out baked".into(),
    ] {
        frmd_ok(&dir, &words(&line));
    }
    let report = frmd_ok(
        &dir,
        &words("eval --task reach --ckpt s --episodes 2 --json eval.json"),
    );
    assert!(report.contains("success"), "{report}");
    let json: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(dir.join("eval.json")).unwrap()).unwrap();
    assert_eq!(json["episodes"], 2);
    let _ = std::fs::remove_dir_all(Path::new(&dir));
}

/// The datasets of frmd-host/tests/data/lerobot/ were written by pyarrow (LeRobot's own writer)
/// with frmd-host/python/tests/lerobot_writer.py from `frmd collect --task reach --episodes 3
/// --seed 5`: both layouts import to exactly those demonstrations.
#[test]
fn datasets_written_by_pyarrow_import_exactly() {
    let dir = scratch("lerobot-pyarrow");
    frmd_ok(
        &dir,
        &words("collect --task reach --episodes 3 --seed 5 --out demos.safetensors"),
    );
    let demos = Dataset::load(&dir.join("demos.safetensors")).unwrap();
    let data = Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/data/lerobot");
    for (version, layout) in [("v2.1", Layout::V2), ("v3.0", Layout::V3)] {
        let cfg = ImportConfig {
            task: Some("reach".into()),
            ..ImportConfig::default()
        };
        let imported = import(&data.join(format!("reach-{version}")), &cfg).unwrap();
        let d = &imported.dataset;
        assert_eq!(
            (imported.layout, imported.version.as_str()),
            (layout, version)
        );
        assert_eq!(
            (&d.obs, &d.action, &d.episode_ends),
            (&demos.obs, &demos.action, &demos.episode_ends)
        );
        assert_eq!((d.dt, d.task.as_str()), (demos.dt, "reach"));
        assert_eq!(imported.ignored, ["observation.images.front (video)"]);
    }
}
