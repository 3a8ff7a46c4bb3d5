//! Whole streams: end of input, early answers to oversized frames, fuzzing.
use super::*;
use crate::rng::HostRng;
use std::io::{self, Read};

#[test]
fn end_of_input() {
    let ft = FloatType::F32;
    let hello = Request::Hello.encode(ft);
    // At a frame boundary: quiet end.
    let (replies, end) = run_server(&hello, &mut session(ft), &mut Echo::default());
    assert_eq!((replies.len(), end), (1, StreamEnd::Eof));
    let (replies, end) = run_server(&[], &mut session(ft), &mut Echo::default());
    assert_eq!((replies.len(), end), (0, StreamEnd::Eof));
    // Inside a header, a payload and a skipped payload: TRUNCATED, fatal.
    let mut big = Header {
        payload_len: MAX_PAYLOAD + 10,
        version: 1,
        msg_type: 1,
        reserved: 0,
    }
    .encode()
    .to_vec();
    big.extend_from_slice(&[0; 100]);
    // The ERROR's request_type is the type byte of the frame whose header was read (0 inside a
    // header), as docs/serve-protocol.md says.
    let hello_type = MsgType::Hello as u8;
    for (input, expect_errors, text, request_type) in [
        (hello[..5].to_vec(), 1, "after 5 of 8 header bytes", 0),
        (
            [hello.clone(), hello[..10].to_vec()].concat(),
            1,
            "after 2 of 4 payload bytes of a HELLO frame",
            hello_type,
        ),
        (
            big,
            2,
            "after 100 of 1048586 bytes of a rejected frame's payload",
            1,
        ),
    ] {
        let (replies, end) = run_server(&input, &mut session(ft), &mut Echo::default());
        assert_eq!(end, StreamEnd::Truncated);
        let errors: Vec<_> = replies
            .iter()
            .filter_map(|r| match r {
                Reply::Error(e) => Some(e),
                _ => None,
            })
            .collect();
        assert_eq!(errors.len(), expect_errors, "{replies:?}");
        let last = errors.last().unwrap();
        assert_eq!(
            (last.kind(), last.fatal, last.request_type),
            (Some(ErrorCode::Truncated), true, request_type)
        );
        assert!(last.text.contains(text), "{last:?}");
    }
}

#[test]
fn a_too_large_frame_is_answered_before_its_payload_arrives() {
    // A reader that would fail the test if the server read past the header before answering.
    struct HeaderOnly(Vec<u8>);
    impl Read for HeaderOnly {
        fn read(&mut self, buf: &mut [u8]) -> io::Result<usize> {
            if self.0.is_empty() {
                return Err(io::Error::other("payload requested before the reply"));
            }
            let n = buf.len().min(self.0.len());
            buf[..n].copy_from_slice(&self.0[..n]);
            self.0.drain(..n);
            Ok(n)
        }
    }
    let head = Header {
        payload_len: u32::MAX,
        version: 1,
        msg_type: 3,
        reserved: 0,
    }
    .encode()
    .to_vec();
    let mut reader = FrameReader::new(HeaderOnly(head), true);
    match reader.next_frame().unwrap() {
        ReadOutcome::Rejected { error, .. } => assert_eq!(error.code, ErrorCode::FrameTooLarge),
        other => panic!("{other:?}"),
    }
}

/// Random byte streams, and valid sessions with random byte flips, insertions and cuts: the
/// server always ends, every reply it writes is a valid frame, and it answers each complete
/// frame it read.
#[test]
fn fuzz_the_server_with_arbitrary_and_mutated_streams() {
    let mut rng = HostRng::new(0x9e37_79b9_7f4a_7c15);
    for ft in [FloatType::F32, FloatType::F64] {
        let valid = requests(
            &[
                Request::Hello,
                Request::Reset {
                    seed: 3,
                    init_action: vec![0.5, 0.5],
                },
                act(0, &OBS),
                act(2, &OBS),
                act(3, &OBS),
                Request::Reset {
                    seed: 4,
                    init_action: vec![],
                },
                act(0, &OBS),
                Request::Close,
            ],
            ft,
        );
        for round in 0..1500 {
            let input: Vec<u8> = if round % 3 == 0 {
                // Random bytes, with small lengths and valid versions/types made likely.
                let len = rng.below(200);
                let mut bytes: Vec<u8> = (0..len).map(|_| rng.next_u64() as u8).collect();
                let mut at = 0;
                while at + 8 <= bytes.len() {
                    if rng.below(2) == 0 {
                        let payload = rng.below(40) as u32;
                        bytes[at..at + 4].copy_from_slice(&payload.to_le_bytes());
                        bytes[at + 4] = 1;
                        bytes[at + 5] = [1, 2, 3, 4, 0x81, 0xff][rng.below(6)];
                        bytes[at + 6] = 0;
                        bytes[at + 7] = 0;
                    }
                    at += 8 + rng.below(40);
                }
                bytes
            } else {
                let mut bytes = valid.clone();
                for _ in 0..1 + rng.below(4) {
                    if bytes.is_empty() {
                        break;
                    }
                    let at = rng.below(bytes.len());
                    match rng.below(4) {
                        0 => bytes[at] ^= 1 << rng.below(8),
                        1 => bytes[at] = rng.next_u64() as u8,
                        2 => bytes.insert(at, rng.next_u64() as u8),
                        _ => bytes.truncate(at),
                    }
                }
                bytes
            };
            let mut s = session(ft);
            let mut out = Vec::new();
            let end =
                serve_stream(Cursor::new(&input), &mut out, &mut s, &mut Echo::default()).unwrap();
            let replies = decode_all_replies(&out, ft);
            if end == StreamEnd::Truncated {
                let Some(Reply::Error(e)) = replies.last() else {
                    panic!("no TRUNCATED reply")
                };
                assert!(e.fatal);
            }
            for reply in &replies {
                if let Reply::Chunk(c) = reply {
                    assert!(c.actions.iter().all(|v| v.is_finite()));
                }
            }
        }
    }
}

/// The decoders on random payloads of every type: errors, never panics.
#[test]
fn fuzz_the_decoders() {
    let mut rng = HostRng::new(77);
    let info = toy_info(FloatType::F32);
    for _ in 0..20_000 {
        let len = rng.below(64);
        let payload: Vec<u8> = (0..len).map(|_| rng.next_u64() as u8).collect();
        for t in [0x01, 0x02, 0x03, 0x04, 0x81, 0x82, 0x83, 0x84, 0xff] {
            let t = MsgType::from_u8(t).unwrap();
            let _ = decode_request(t, &payload, &info);
            let _ = decode_reply(t, &payload, Some(FloatType::F64));
        }
    }
}
