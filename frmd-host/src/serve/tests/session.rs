//! Session rules through the server loop: executed bookkeeping, one malformed request per error
//! code, order, rejected requests, policy failures.
use super::*;

#[test]
fn a_session_follows_the_executed_actions() {
    let mut s = session(FloatType::F64);
    let mut p = Echo::default();
    let input = requests(
        &[
            Request::Hello,
            Request::Reset {
                seed: 42,
                init_action: vec![],
            },
            act(0, &OBS),
            act(2, &OBS),
            act(1, &OBS),
            act(0, &OBS),
            Request::Reset {
                seed: 43,
                init_action: vec![10.0, 0.0],
            },
            act(0, &OBS),
            Request::Close,
            Request::Hello, // after CLOSE: never read
        ],
        FloatType::F64,
    );
    let (replies, end) = run_server(&input, &mut s, &mut p);
    assert_eq!(end, StreamEnd::Closed);
    assert_eq!(replies.len(), 9);
    assert_eq!(replies[0], Reply::HelloOk(toy_info(FloatType::F64)));
    assert_eq!(replies[1], Reply::ResetOk { seed: 42 });
    // First chunk: y0 = default 0, rate 0: actions (t, obs[0]).
    assert_eq!(
        chunk(&replies[2]).actions,
        vec![0.0, 0.5, 1.0, 0.5, 2.0, 0.5]
    );
    // Executed 2 of [0, 1, 2] (first component): y0 = 1, rate (1 - 0) / dt = 80.
    let c = chunk(&replies[3]);
    assert_eq!(c.actions[0], 1.0);
    assert!(
        (c.actions[1] - (80.0 + 0.5)).abs() < 1e-9,
        "{:?}",
        c.actions
    );
    // Executed 1 of [1, 2, 3]: y0 = 1 again, rate 0.
    assert_eq!(chunk(&replies[4]).actions[..2], [1.0, 0.5]);
    // Executed 0: the previous chunk was discarded, nothing changes.
    assert_eq!(chunk(&replies[5]).actions[..2], [1.0, 0.5]);
    assert_eq!(replies[6], Reply::ResetOk { seed: 43 });
    assert_eq!(chunk(&replies[7]).actions[..2], [10.0, 0.5]);
    assert_eq!(replies[8], Reply::CloseOk);
    assert_eq!((p.seed, p.calls), (43, 5));
}

/// One malformed request per error code, each followed by a valid request that must still be
/// answered normally (the server keeps serving).
#[test]
fn every_malformed_frame_gets_its_named_error_and_the_server_keeps_serving() {
    let ft = FloatType::F32;
    let hello = Request::Hello.encode(ft);
    let reset = Request::Reset {
        seed: 1,
        init_action: vec![],
    }
    .encode(ft);
    let good_act = act(0, &OBS).encode(ft);
    let mut with_version = hello.clone();
    with_version[4] = 2;
    let mut reserved = hello.clone();
    reserved[6] = 1;
    let mut nan = OBS;
    nan[4] = f64::NAN;
    let mut inf = OBS;
    inf[0] = f64::INFINITY;
    let mut huge = Header {
        payload_len: MAX_PAYLOAD + 1,
        version: 1,
        msg_type: 3,
        reserved: 0,
    }
    .encode()
    .to_vec();
    huge.extend(std::iter::repeat_n(0xAB, MAX_PAYLOAD as usize + 1));
    let mut act_payload = act(0, &OBS).encode(ft)[HEADER_LEN..].to_vec();
    act_payload.push(0);
    let cases: Vec<(&str, Vec<u8>, ErrorCode, &str)> = vec![
        (
            "version 2",
            with_version,
            ErrorCode::UnsupportedVersion,
            "version 2 is not supported",
        ),
        (
            "unknown type",
            raw(0x05, &[1, 2, 3]),
            ErrorCode::UnknownType,
            "unknown request type 0x05",
        ),
        (
            "reply type sent to the server",
            raw(0x83, &[]),
            ErrorCode::UnknownType,
            "CHUNK",
        ),
        (
            "too large",
            huge,
            ErrorCode::FrameTooLarge,
            "exceeds the limit of 1048576",
        ),
        ("reserved header", reserved, ErrorCode::BadValue, "reserved"),
        (
            "short HELLO",
            raw(0x01, b"FRM"),
            ErrorCode::BadLength,
            "HELLO payload is 3 bytes",
        ),
        (
            "bad magic",
            raw(0x01, b"frmd"),
            ErrorCode::BadValue,
            "magic",
        ),
        (
            "short RESET",
            raw(0x02, &[0; 11]),
            ErrorCode::BadLength,
            "at least 12",
        ),
        (
            "RESET count/length",
            raw(0x02, &[0, 0, 0, 0, 0, 0, 0, 0, 2, 0, 0, 0]),
            ErrorCode::BadLength,
            "12 + 2 x 4 = 20",
        ),
        (
            "RESET init_count",
            Request::Reset {
                seed: 0,
                init_action: vec![1.0],
            }
            .encode(ft),
            ErrorCode::BadValue,
            "init_count is 1",
        ),
        (
            "RESET NaN",
            Request::Reset {
                seed: 0,
                init_action: vec![0.0, f64::NAN],
            }
            .encode(ft),
            ErrorCode::NonFinite,
            "init_action element 1 is NaN",
        ),
        (
            "short ACT",
            raw(0x03, &[0; 7]),
            ErrorCode::BadLength,
            "at least 8",
        ),
        (
            "ACT length",
            raw(0x03, &act_payload),
            ErrorCode::BadLength,
            "ACT payload is 33 bytes, expected 8 + 2 x 3 x 4 = 32",
        ),
        (
            "ACT obs_count",
            act(0, &OBS[..3]).encode(ft),
            ErrorCode::BadValue,
            "obs_count is 1",
        ),
        (
            "ACT executed without chunk",
            act(1, &OBS).encode(ft),
            ErrorCode::BadValue,
            "no chunk",
        ),
        (
            "ACT NaN",
            act(0, &nan).encode(ft),
            ErrorCode::NonFinite,
            "observation 1 element 1 is NaN",
        ),
        (
            "ACT inf",
            act(0, &inf).encode(ft),
            ErrorCode::NonFinite,
            "observation 0 element 0 is inf",
        ),
        (
            "CLOSE with payload",
            raw(0x04, &[0]),
            ErrorCode::BadLength,
            "CLOSE payload is 1 bytes",
        ),
    ];
    for (what, bad, code, text) in cases {
        let mut s = session(ft);
        let input: Vec<u8> = [hello.clone(), reset.clone(), bad, good_act.clone()].concat();
        let (replies, end) = run_server(&input, &mut s, &mut Echo::default());
        assert_eq!(end, StreamEnd::Eof, "{what}");
        assert_eq!(replies.len(), 4, "{what}: {replies:?}");
        let Reply::Error(e) = &replies[2] else {
            panic!("{what}: expected ERROR, got {:?}", replies[2])
        };
        assert_eq!(e.kind(), Some(code), "{what}: {e:?}");
        assert!(
            e.text.contains(text),
            "{what}: text {:?} lacks {text:?}",
            e.text
        );
        assert!(!e.fatal, "{what}");
        assert!(
            matches!(replies[3], Reply::Chunk(_)),
            "{what}: {:?}",
            replies[3]
        );
    }
}

#[test]
fn order_rules() {
    let ft = FloatType::F32;
    let mut s = session(ft);
    let input = requests(
        &[
            Request::Reset {
                seed: 1,
                init_action: vec![],
            },
            act(0, &OBS),
            Request::Hello,
            act(0, &OBS),
            Request::Reset {
                seed: 1,
                init_action: vec![],
            },
            act(0, &OBS),
            Request::Hello,
            act(2, &OBS),
        ],
        ft,
    );
    let (replies, _) = run_server(&input, &mut s, &mut Echo::default());
    let codes: Vec<_> = replies.iter().map(error_code).collect();
    assert_eq!(
        codes,
        [
            Some(ErrorCode::OutOfOrder),
            Some(ErrorCode::OutOfOrder),
            None,
            Some(ErrorCode::OutOfOrder),
            None,
            None,
            None,
            None
        ]
    );
    // Order is checked before length: a short ACT before HELLO is OUT_OF_ORDER.
    let (replies, _) = run_server(&raw(0x03, &[]), &mut session(ft), &mut Echo::default());
    assert_eq!(error_code(&replies[0]), Some(ErrorCode::OutOfOrder));
    // CLOSE is accepted before HELLO.
    let (replies, end) = run_server(
        &Request::Close.encode(ft),
        &mut session(ft),
        &mut Echo::default(),
    );
    assert_eq!((replies, end), (vec![Reply::CloseOk], StreamEnd::Closed));
}

#[test]
fn a_rejected_request_changes_nothing() {
    let ft = FloatType::F64;
    let mut nan = OBS;
    nan[2] = f64::NAN;
    let run = |extra: &[Request]| {
        let mut list = vec![
            Request::Hello,
            Request::Reset {
                seed: 5,
                init_action: vec![],
            },
            act(0, &OBS),
        ];
        list.extend_from_slice(extra);
        list.push(act(2, &OBS));
        let (replies, _) = run_server(&requests(&list, ft), &mut session(ft), &mut Echo::default());
        chunk(replies.last().unwrap()).actions.clone()
    };
    let clean = run(&[]);
    let after_errors = run(&[
        act(2, &nan),
        act(4, &OBS),
        Request::Reset {
            seed: 6,
            init_action: vec![f64::NAN, 0.0],
        },
        Request::Reset {
            seed: 6,
            init_action: vec![1.0],
        },
    ]);
    assert_eq!(clean, after_errors);
}

#[test]
fn policy_failures_are_reported_and_the_session_goes_on() {
    let ft = FloatType::F32;
    let input = requests(
        &[
            Request::Hello,
            Request::Reset {
                seed: 1,
                init_action: vec![],
            },
            act(0, &OBS),
            act(0, &OBS),
        ],
        ft,
    );
    for (policy, text) in [
        (
            Echo {
                fail: Some("model exploded"),
                ..Echo::default()
            },
            "policy: model exploded",
        ),
        (
            Echo {
                wrong_len: true,
                ..Echo::default()
            },
            "returned 5 values, expected horizon x action_dim = 6",
        ),
        (
            Echo {
                emit_nan: true,
                ..Echo::default()
            },
            "policy action 0 element 1 is NaN",
        ),
    ] {
        let mut policy = policy;
        let (replies, _) = run_server(&input, &mut session(ft), &mut policy);
        for reply in &replies[2..] {
            let Reply::Error(e) = reply else {
                panic!("{reply:?}")
            };
            assert_eq!(
                (e.kind(), e.request_type),
                (Some(ErrorCode::PolicyFailed), 3)
            );
            assert!(e.text.contains(text), "{e:?}");
        }
        assert_eq!(policy.calls, 2);
    }
}
