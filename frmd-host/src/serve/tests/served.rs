//! Real policies behind the server: a small student checkpoint (float) and its int8 export,
//! served through `serve_stream` on in-memory pipes, with malformed input between valid calls.
use super::*;
use crate::export::EXPORT_INFO_FILE;
use crate::serve::{load, PolicySource, ServeConfig, Served};
use frmd_export::bake::BLOB_FILE;
use std::path::{Path, PathBuf};

/// A random student at the reach shape (M 2, O 6, K 2, N 12) under `dir`, with its int8 blob
/// beside it as `policy.blob` and an `export.json` naming the checkpoint.
fn student_and_blob(dir: &Path) -> PathBuf {
    std::fs::create_dir_all(dir).unwrap();
    crate::bench::fixtures::reach_student(
        dir,
        &frmd_formats::checkpoint::BackboneConfig::preset("mlp").unwrap(),
        3,
    )
    .unwrap();
    let exported = frmd_export::export(dir, &Default::default(), None).unwrap();
    let baked = dir.join("baked");
    std::fs::create_dir_all(&baked).unwrap();
    std::fs::write(baked.join(BLOB_FILE), exported.blob()).unwrap();
    std::fs::write(
        baked.join(EXPORT_INFO_FILE),
        serde_json::json!({ "checkpoint": dir.display().to_string() }).to_string(),
    )
    .unwrap();
    baked
}

const REACH_OBS: [f64; 12] = [
    0.1, -0.2, 0.3, 0.0, 0.5, -0.4, 0.1, -0.2, 0.3, 0.0, 0.5, -0.4,
];

fn act6(executed: u32, obs: &[f64]) -> Request {
    Request::Act {
        executed,
        obs_count: (obs.len() / 6) as u32,
        obs: obs.to_vec(),
    }
}

/// One session: HELLO, RESET 5, ACT, a garbage frame, a NaN observation, a wrong-length ACT,
/// an unknown type, ACT executed 8, RESET 5, ACT, CLOSE; returns the replies.
fn session_replies(served: &mut Served) -> Vec<Reply> {
    let ft = served.info.float_type;
    let mut nan = REACH_OBS;
    nan[7] = f64::NAN;
    let mut input = requests(
        &[
            Request::Hello,
            Request::Reset {
                seed: 5,
                init_action: vec![],
            },
            act6(0, &REACH_OBS),
        ],
        ft,
    );
    input.extend(raw(0x03, &[1, 2, 3]));
    input.extend(act6(0, &nan).encode(ft));
    input.extend(
        Request::Act {
            executed: 0,
            obs_count: 2,
            obs: REACH_OBS[..6].to_vec(),
        }
        .encode(ft),
    );
    input.extend(raw(0x42, b"?"));
    input.extend(requests(
        &[
            act6(8, &REACH_OBS),
            Request::Reset {
                seed: 5,
                init_action: vec![],
            },
            act6(0, &REACH_OBS),
            Request::Close,
        ],
        ft,
    ));
    let mut session = served.session().unwrap();
    let mut out = Vec::new();
    let end = serve_stream(
        Cursor::new(input),
        &mut out,
        &mut session,
        &mut served.policy,
    )
    .unwrap();
    assert_eq!(end, StreamEnd::Closed);
    decode_all_replies(&out, ft)
}

fn check_session(served: &mut Served) {
    let replies = session_replies(served);
    assert_eq!(replies.len(), 11, "{replies:?}");
    let Reply::HelloOk(info) = &replies[0] else {
        panic!("{:?}", replies[0])
    };
    assert_eq!(
        (
            info.obs_dim,
            info.action_dim,
            info.obs_history,
            info.horizon,
            info.exec_steps
        ),
        (6, 2, 2, 12, 8)
    );
    assert_eq!(info.dt, 0.05);
    let first = chunk(&replies[2]).clone();
    assert_eq!(first.actions.len(), 24);
    assert!(first.actions.iter().all(|v| v.is_finite()));
    assert!(first.policy_ns > 0);
    assert_eq!(error_code(&replies[3]), Some(ErrorCode::BadLength));
    assert_eq!(error_code(&replies[4]), Some(ErrorCode::NonFinite));
    let Reply::Error(e) = &replies[4] else {
        unreachable!()
    };
    assert_eq!(e.text, "ACT observation 1 element 1 is NaN");
    assert_eq!(error_code(&replies[5]), Some(ErrorCode::BadLength));
    assert_eq!(error_code(&replies[6]), Some(ErrorCode::UnknownType));
    // Continuing from the executed actions changes the conditioning, hence the chunk.
    assert_ne!(chunk(&replies[7]).actions, first.actions);
    // The same seed and inputs after RESET reproduce the first chunk exactly.
    assert_eq!(chunk(&replies[9]).actions, first.actions);
    assert_eq!(replies[10], Reply::CloseOk);
}

#[test]
fn a_student_checkpoint_and_its_int8_export_serve_and_survive_bad_input() {
    let dir = std::env::temp_dir().join(format!("frmd-serve-test-{}", std::process::id()));
    let baked = student_and_blob(&dir);
    let cfg = ServeConfig::default();
    let mut float = load(
        &PolicySource::Checkpoint {
            dir: dir.clone(),
            steps: None,
            solver: None,
        },
        &cfg,
    )
    .unwrap();
    assert!(
        float.info.name.starts_with("student-1 "),
        "{}",
        float.info.name
    );
    check_session(&mut float);
    let mut int8 = load(&PolicySource::Baked(baked.clone()), &cfg).unwrap();
    check_session(&mut int8);
    // The bare blob finds the control period in the export.json beside it.
    let blob = load(&PolicySource::Blob(baked.join(BLOB_FILE)), &cfg).unwrap();
    assert_eq!(blob.info.dt, 0.05);
    // A relative checkpoint path in export.json is found from the export's own directory,
    // whatever the server's working directory; a missing one announces dt 0 (and warns).
    for (checkpoint, dt) in [("../no-such-checkpoint", 0.0), ("..", 0.05)] {
        std::fs::write(
            baked.join(EXPORT_INFO_FILE),
            serde_json::json!({ "checkpoint": checkpoint }).to_string(),
        )
        .unwrap();
        let served = load(&PolicySource::Baked(baked.clone()), &cfg).unwrap();
        assert_eq!(served.info.dt, dt, "checkpoint {checkpoint}");
    }
    // float and int8 agree to quantization error on the same chunk.
    let (f, q) = (session_replies(&mut float), session_replies(&mut int8));
    let max_diff = chunk(&f[2])
        .actions
        .iter()
        .zip(&chunk(&q[2]).actions)
        .map(|(a, b)| (a - b).abs())
        .fold(0.0, f64::max);
    assert!(max_diff < 0.1, "float vs int8 chunk differ by {max_diff}");
    // f64 on the wire, other exec steps, zeros mode.
    let cfg64 = ServeConfig {
        float_type: FloatType::F64,
        exec_steps: Some(12),
        zeros: true,
        ..ServeConfig::default()
    };
    let mut zeros = load(&PolicySource::Baked(baked.clone()), &cfg64).unwrap();
    assert_eq!(
        (zeros.info.exec_steps, zeros.info.float_type),
        (12, FloatType::F64)
    );
    let replies = session_replies(&mut zeros);
    assert!(chunk(&replies[2]).actions.iter().all(|&v| v == 0.0));
    std::fs::remove_dir_all(&dir).ok();
}

#[test]
fn bad_sources_and_settings_are_errors_naming_the_problem() {
    let dir = std::env::temp_dir().join(format!("frmd-serve-bad-{}", std::process::id()));
    let baked = student_and_blob(&dir);
    let cfg = ServeConfig::default();
    let err = |source: PolicySource, cfg: &ServeConfig| {
        format!("{:#}", load(&source, cfg).err().expect("an error"))
    };
    assert!(err(
        PolicySource::Checkpoint {
            dir: dir.join("missing"),
            steps: None,
            solver: None
        },
        &cfg
    )
    .contains("missing"));
    assert!(err(
        PolicySource::Checkpoint {
            dir: dir.clone(),
            steps: Some(7),
            solver: None
        },
        &cfg
    )
    .contains("--steps 7: expected 1 to 4"));
    assert!(err(PolicySource::Blob(dir.join("frmd.json")), &cfg).contains("frmd.json"));
    let e = err(
        PolicySource::Baked(baked.clone()),
        &ServeConfig {
            exec_steps: Some(13),
            ..ServeConfig::default()
        },
    );
    assert!(e.contains("exec-steps 13"), "{e}");
    let e = err(
        PolicySource::Baked(baked),
        &ServeConfig {
            init_action: Some(vec![0.0]),
            ..ServeConfig::default()
        },
    );
    assert!(e.contains("init-action"), "{e}");
    std::fs::remove_dir_all(&dir).ok();
}
