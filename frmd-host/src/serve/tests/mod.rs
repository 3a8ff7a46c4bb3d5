//! Protocol tests: codec round trips and the specification's worked example (`codec`), session
//! rules and error replies (`session`), end of input and fuzzing of whole streams (`stream`).
use super::*;
use std::io::Cursor;

/// The toy policy of the specification's worked example.
fn toy_info(float_type: FloatType) -> ModelInfo {
    ModelInfo {
        obs_dim: 3,
        action_dim: 2,
        obs_history: 2,
        horizon: 3,
        exec_steps: 2,
        float_type,
        max_payload: MAX_PAYLOAD,
        dt: 0.0125,
        name: "toy".into(),
    }
}

/// Answers with a chunk that encodes its inputs: action t = (y0[0] + t, v0[0] + obs[0]),
/// counts resets and calls, fails on request.
#[derive(Default)]
struct Echo {
    seed: u64,
    calls: usize,
    fail: Option<&'static str>,
    wrong_len: bool,
    emit_nan: bool,
}

impl ServedPolicy for Echo {
    fn reset(&mut self, seed: u64) {
        self.seed = seed;
    }

    fn act(&mut self, input: &ActInput<'_>) -> std::result::Result<Vec<f64>, String> {
        self.calls += 1;
        if let Some(text) = self.fail {
            return Err(text.to_string());
        }
        let mut out: Vec<f64> = (0..3)
            .flat_map(|t| {
                [
                    input.prev_action[0] + t as f64,
                    input.prev_rate[0] + input.obs[0],
                ]
            })
            .collect();
        if self.wrong_len {
            out.pop();
        }
        if self.emit_nan {
            out[1] = f64::NAN;
        }
        Ok(out)
    }
}

fn session(float_type: FloatType) -> Session {
    Session::new(toy_info(float_type), vec![0.0, 0.0]).unwrap()
}

fn act(executed: u32, obs: &[f64]) -> Request {
    Request::Act {
        executed,
        obs_count: (obs.len() / 3) as u32,
        obs: obs.to_vec(),
    }
}

/// Runs `input` through a server and decodes every reply frame (which must all be valid).
fn run_server(input: &[u8], session: &mut Session, policy: &mut Echo) -> (Vec<Reply>, StreamEnd) {
    let mut out = Vec::new();
    let end = serve_stream(Cursor::new(input), &mut out, session, policy).unwrap();
    (decode_all_replies(&out, session.info().float_type), end)
}

fn decode_all_replies(bytes: &[u8], float_type: FloatType) -> Vec<Reply> {
    let mut reader = FrameReader::new(Cursor::new(bytes), false);
    let mut replies = Vec::new();
    loop {
        match reader.next_frame().unwrap() {
            ReadOutcome::Frame { msg_type, payload } => {
                replies.push(decode_reply(msg_type, &payload, Some(float_type)).unwrap())
            }
            ReadOutcome::Eof => return replies,
            other => panic!("server wrote a bad frame: {other:?}"),
        }
    }
}

fn requests(list: &[Request], float_type: FloatType) -> Vec<u8> {
    list.iter().flat_map(|r| r.encode(float_type)).collect()
}

fn error_code(reply: &Reply) -> Option<ErrorCode> {
    match reply {
        Reply::Error(e) => e.kind(),
        _ => None,
    }
}

fn chunk(reply: &Reply) -> &Chunk {
    match reply {
        Reply::Chunk(c) => c,
        other => panic!("expected CHUNK, got {other:?}"),
    }
}

/// Frame with an arbitrary header and payload.
fn raw(msg_type: u8, payload: &[u8]) -> Vec<u8> {
    let mut out = Header {
        payload_len: payload.len() as u32,
        version: VERSION,
        msg_type,
        reserved: 0,
    }
    .encode()
    .to_vec();
    out.extend_from_slice(payload);
    out
}

const OBS: [f64; 6] = [0.5, -1.0, 2.0, 0.5, -1.0, 2.0];

mod codec;
mod served;
mod session;
mod stream;
