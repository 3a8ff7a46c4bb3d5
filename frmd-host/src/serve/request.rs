//! Client -> server messages (HELLO, RESET, ACT, CLOSE): encoding and decoding side by side.
use super::error::{bad_value, ErrorCode, ProtocolError, Result};
use super::fields::{expect_at_least, expect_len, put_values, Fields};
use super::frame::{frame, FloatType, MsgType, MAGIC};
use super::reply::ModelInfo;

/// A client -> server message.
#[derive(Clone, Debug, PartialEq)]
pub enum Request {
    Hello,
    Reset {
        seed: u64,
        /// Empty (server default) or `action_dim` values.
        init_action: Vec<f64>,
    },
    Act {
        executed: u32,
        /// Observations in `obs` (the policy's `obs_history`).
        obs_count: u32,
        /// `obs_count` observations of `obs_dim` values, oldest first.
        obs: Vec<f64>,
    },
    Close,
}

impl Request {
    pub fn msg_type(&self) -> MsgType {
        match self {
            Request::Hello => MsgType::Hello,
            Request::Reset { .. } => MsgType::Reset,
            Request::Act { .. } => MsgType::Act,
            Request::Close => MsgType::Close,
        }
    }

    /// The whole frame, values in `float_type` (ignored by HELLO and CLOSE).
    pub fn encode(&self, float_type: FloatType) -> Vec<u8> {
        let mut p = Vec::new();
        match self {
            Request::Hello => p.extend_from_slice(&MAGIC),
            Request::Reset { seed, init_action } => {
                p.extend_from_slice(&seed.to_le_bytes());
                p.extend_from_slice(&(init_action.len() as u32).to_le_bytes());
                put_values(&mut p, init_action, float_type);
            }
            Request::Act {
                executed,
                obs_count,
                obs,
            } => {
                p.extend_from_slice(&executed.to_le_bytes());
                p.extend_from_slice(&obs_count.to_le_bytes());
                put_values(&mut p, obs, float_type);
            }
            Request::Close => {}
        }
        frame(self.msg_type(), p)
    }
}

/// Decodes a request payload for a server announcing `info` (length and value checks of the
/// message itself; order, `executed` and finiteness are the session's).
pub fn decode_request(msg_type: MsgType, payload: &[u8], info: &ModelInfo) -> Result<Request> {
    let w = info.float_type.width();
    let mut f = Fields::new(payload);
    match msg_type {
        MsgType::Hello => {
            expect_len("HELLO", payload, 4, 4)?;
            let magic = f.take::<4>();
            if magic != MAGIC {
                return Err(bad_value(format!(
                    "HELLO magic is {:02x?}, expected \"FRMD\" (46 52 4d 44)",
                    magic
                )));
            }
            Ok(Request::Hello)
        }
        MsgType::Reset => {
            expect_at_least("RESET", payload, 12)?;
            let seed = f.u64();
            let count = f.u32();
            expect_len(
                "RESET",
                payload,
                12 + u64::from(count) * w as u64,
                format_args!("12 + {count} x {w} = {}", 12 + u64::from(count) * w as u64),
            )?;
            if count != 0 && count != u32::from(info.action_dim) {
                return Err(bad_value(format!(
                    "RESET init_count is {count}, expected 0 or action_dim {}",
                    info.action_dim
                )));
            }
            Ok(Request::Reset {
                seed,
                init_action: f.values(count as usize, info.float_type),
            })
        }
        MsgType::Act => {
            expect_at_least("ACT", payload, 8)?;
            let executed = f.u32();
            let count = f.u32();
            let expected = 8 + u64::from(count) * u64::from(info.obs_dim) * w as u64;
            expect_len(
                "ACT",
                payload,
                expected,
                format_args!("8 + {count} x {} x {w} = {expected}", info.obs_dim),
            )?;
            if count != u32::from(info.obs_history) {
                return Err(bad_value(format!(
                    "ACT obs_count is {count}, the policy takes {} observations",
                    info.obs_history
                )));
            }
            let values = count as usize * usize::from(info.obs_dim);
            Ok(Request::Act {
                executed,
                obs_count: count,
                obs: f.values(values, info.float_type),
            })
        }
        MsgType::Close => {
            expect_len("CLOSE", payload, 0, 0)?;
            Ok(Request::Close)
        }
        other => Err(ProtocolError::new(
            ErrorCode::UnknownType,
            format!("{} is not a request", other.name()),
        )),
    }
}
