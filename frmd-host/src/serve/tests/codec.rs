//! Encoding and decoding of every message, the worked example of the specification, client-side
//! reply checks and model description validation.
use super::*;

#[test]
fn every_message_round_trips_in_both_float_types() {
    for ft in [FloatType::F32, FloatType::F64] {
        let info = toy_info(ft);
        for request in [
            Request::Hello,
            Request::Reset {
                seed: u64::MAX,
                init_action: vec![],
            },
            Request::Reset {
                seed: 3,
                init_action: vec![0.25, -1.5],
            },
            act(7, &OBS),
            Request::Close,
        ] {
            let bytes = request.encode(ft);
            let header = Header::decode(bytes[..HEADER_LEN].try_into().unwrap());
            assert_eq!(header.payload_len as usize, bytes.len() - HEADER_LEN);
            let t = header.check(true).unwrap();
            assert_eq!(
                decode_request(t, &bytes[HEADER_LEN..], &info).unwrap(),
                request
            );
        }
        let replies = [
            Reply::HelloOk(info.clone()),
            Reply::ResetOk { seed: 9 },
            Reply::Chunk(Chunk {
                policy_ns: 123_456_789,
                horizon: 3,
                action_dim: 2,
                exec_steps: 2,
                actions: vec![0.0, 0.25, 0.5, 0.75, 1.0, -1.0],
            }),
            Reply::CloseOk,
            Reply::Error(ErrorReply {
                code: 6,
                request_type: 3,
                fatal: false,
                text: "x é".into(),
            }),
            Reply::Error(ErrorReply {
                code: 999,
                request_type: 0,
                fatal: true,
                text: String::new(),
            }),
        ];
        for reply in replies {
            let bytes = reply.encode(ft);
            let header = Header::decode(bytes[..HEADER_LEN].try_into().unwrap());
            let t = header.check(false).unwrap();
            assert_eq!(
                decode_reply(t, &bytes[HEADER_LEN..], Some(ft)).unwrap(),
                reply
            );
        }
    }
}

#[test]
fn f64_values_survive_exactly_and_f32_values_round_to_f32() {
    let v = [0.1f64, -1e-300, 1e300];
    let info = toy_info(FloatType::F64);
    let bytes = Request::Reset {
        seed: 0,
        init_action: v[..2].to_vec(),
    }
    .encode(FloatType::F64);
    match decode_request(MsgType::Reset, &bytes[HEADER_LEN..], &info).unwrap() {
        Request::Reset { init_action, .. } => assert_eq!(init_action, v[..2]),
        other => panic!("{other:?}"),
    }
    let bytes = Request::Reset {
        seed: 0,
        init_action: vec![0.1, 0.2],
    }
    .encode(FloatType::F32);
    match decode_request(
        MsgType::Reset,
        &bytes[HEADER_LEN..],
        &toy_info(FloatType::F32),
    )
    .unwrap()
    {
        Request::Reset { init_action, .. } => {
            assert_eq!(init_action, vec![f64::from(0.1f32), f64::from(0.2f32)])
        }
        other => panic!("{other:?}"),
    }
}

/// Every ```hex block of docs/serve-protocol.md section 7, in order: decoded with the toy
/// policy's shapes, re-encoded to the same bytes, and the values the prose states.
#[test]
fn worked_examples_of_the_specification_decode() {
    let doc = include_str!("../../../../docs/serve-protocol.md");
    let blocks: Vec<Vec<u8>> = doc
        .split("```hex\n")
        .skip(1)
        .map(|rest| {
            let block = rest.split("```").next().unwrap_or("");
            let digits: String = block.chars().filter(|c| c.is_ascii_hexdigit()).collect();
            (0..digits.len() / 2)
                .map(|i| u8::from_str_radix(&digits[2 * i..2 * i + 2], 16).unwrap())
                .collect()
        })
        .collect();
    assert_eq!(blocks.len(), 11, "worked examples in the specification");
    let info = toy_info(FloatType::F32);
    let mut decoded = Vec::new();
    for bytes in &blocks {
        let header = Header::decode(bytes[..HEADER_LEN].try_into().unwrap());
        assert_eq!(
            header.payload_len as usize,
            bytes.len() - HEADER_LEN,
            "{bytes:02x?}"
        );
        let t = MsgType::from_u8(header.msg_type).unwrap();
        let payload = &bytes[HEADER_LEN..];
        let (reencoded, text) = if t.is_request() {
            let r = decode_request(t, payload, &info).unwrap();
            (r.encode(FloatType::F32), format!("{r:?}"))
        } else {
            let r = decode_reply(t, payload, Some(FloatType::F32)).unwrap();
            (r.encode(FloatType::F32), format!("{r:?}"))
        };
        assert_eq!(&reencoded, bytes, "{text}");
        decoded.push(text);
    }
    assert_eq!(decoded[0], "Hello");
    assert_eq!(decoded[1], format!("{:?}", Reply::HelloOk(info.clone())));
    assert_eq!(decoded[2], "Reset { seed: 7, init_action: [] }");
    assert_eq!(decoded[3], "Reset { seed: 7, init_action: [0.0, 0.5] }");
    assert_eq!(decoded[4], "ResetOk { seed: 7 }");
    assert_eq!(decoded[5], format!("{:?}", act(0, &OBS)));
    assert!(
        decoded[6].contains("policy_ns: 15000")
            && decoded[6].contains("[0.0, 0.25, 0.5, 0.75, 1.0, -1.0]")
    );
    assert!(decoded[7].contains("executed: 2") && decoded[7].contains("NaN"));
    assert!(
        decoded[8].contains("code: 6")
            && decoded[8].contains("\"ACT observation 1 element 0 is NaN\"")
    );
    assert_eq!(decoded[9], "Close");
    assert_eq!(decoded[10], "CloseOk");
    // The example session, replayed against the server: the ERROR text is the server's.
    let mut s = session(FloatType::F32);
    let input: Vec<u8> = [0usize, 2, 5, 7]
        .iter()
        .flat_map(|&i| blocks[i].clone())
        .collect();
    let (replies, _) = run_server(&input, &mut s, &mut Echo::default());
    assert_eq!(replies.last().unwrap().encode(FloatType::F32), blocks[8]);
}

#[test]
fn client_side_reply_checks() {
    let ft = Some(FloatType::F32);
    let chunk_bytes = Reply::Chunk(Chunk {
        policy_ns: 1,
        horizon: 3,
        action_dim: 2,
        exec_steps: 2,
        actions: vec![0.0; 6],
    })
    .encode(FloatType::F32);
    let payload = &chunk_bytes[HEADER_LEN..];
    assert_eq!(
        decode_reply(MsgType::Chunk, payload, None)
            .unwrap_err()
            .code,
        ErrorCode::OutOfOrder
    );
    assert_eq!(
        decode_reply(MsgType::Chunk, &payload[..20], ft)
            .unwrap_err()
            .code,
        ErrorCode::BadLength
    );
    let mut bad_info = toy_info(FloatType::F32);
    bad_info.exec_steps = 4;
    let hello_ok = Reply::HelloOk(bad_info).encode(FloatType::F32);
    let err = decode_reply(MsgType::HelloOk, &hello_ok[HEADER_LEN..], None).unwrap_err();
    assert!(err.text.contains("exec_steps 4 is outside 1..=3"), "{err}");
    let mut hello_ok = Reply::HelloOk(toy_info(FloatType::F32)).encode(FloatType::F32);
    hello_ok[HEADER_LEN + 10] = 3;
    let err = decode_reply(MsgType::HelloOk, &hello_ok[HEADER_LEN..], None).unwrap_err();
    assert!(err.text.contains("float_type is 3"), "{err}");
    let error = [6u8, 0, 3, 0, 2, 0, 0xff, 0xfe];
    assert!(decode_reply(MsgType::Error, &error, ft)
        .unwrap_err()
        .text
        .contains("UTF-8"));
    assert_eq!(
        Header::decode(
            &Request::Hello.encode(FloatType::F32)[..8]
                .try_into()
                .unwrap()
        )
        .check(false)
        .unwrap_err()
        .code,
        ErrorCode::UnknownType
    );
    // Long texts and names are cut at a character boundary.
    let long = "é".repeat(MAX_TEXT);
    let e = ErrorReply::from_error(&ProtocolError::new(ErrorCode::PolicyFailed, long), 3);
    assert!(e.text.len() <= MAX_TEXT && e.text.len() >= MAX_TEXT - 1);
}

#[test]
fn model_info_validation() {
    assert!(Session::new(toy_info(FloatType::F32), vec![0.0]).is_err());
    let mut info = toy_info(FloatType::F64);
    info.obs_dim = 60_000;
    info.obs_history = 3;
    assert!(info.validate().unwrap_err().contains("ACT payloads"));
    let mut info = toy_info(FloatType::F64);
    info.name = "n".repeat(MAX_NAME + 1);
    assert!(info.validate().is_err());
    let mut info = toy_info(FloatType::F64);
    info.dt = f64::NAN;
    assert!(info.validate().is_err());
}
