//! Server -> client messages (HELLO_OK with the model description, RESET_OK, CHUNK, CLOSE_OK,
//! ERROR): encoding and decoding side by side.
use super::error::{bad_value, ErrorCode, ProtocolError, Result};
use super::fields::{expect_at_least, expect_len, put_values, truncate_utf8, utf8, Fields};
use super::frame::{frame, FloatType, MsgType, MAX_NAME, MAX_PAYLOAD, MAX_TEXT, VERSION};

/// What HELLO_OK announces: the policy's shapes, value type and control period.
#[derive(Clone, Debug, PartialEq)]
pub struct ModelInfo {
    pub obs_dim: u16,
    pub action_dim: u16,
    pub obs_history: u16,
    pub horizon: u16,
    pub exec_steps: u16,
    pub float_type: FloatType,
    pub max_payload: u32,
    /// Control period the policy was trained for, seconds (0 if unknown).
    pub dt: f64,
    pub name: String,
}

impl ModelInfo {
    /// Bytes of an ACT payload for this model.
    pub fn act_payload_len(&self) -> usize {
        8 + usize::from(self.obs_history) * usize::from(self.obs_dim) * self.float_type.width()
    }

    /// Bytes of a CHUNK payload for this model.
    pub fn chunk_payload_len(&self) -> usize {
        16 + usize::from(self.horizon) * usize::from(self.action_dim) * self.float_type.width()
    }

    /// The ranges HELLO_OK promises; a server must not announce anything else.
    pub fn validate(&self) -> std::result::Result<(), String> {
        for (name, value) in [
            ("obs_dim", self.obs_dim),
            ("action_dim", self.action_dim),
            ("obs_history", self.obs_history),
            ("horizon", self.horizon),
        ] {
            if value == 0 {
                return Err(format!("{name} is 0"));
            }
        }
        if self.exec_steps == 0 || self.exec_steps > self.horizon {
            return Err(format!(
                "exec_steps {} is outside 1..={}",
                self.exec_steps, self.horizon
            ));
        }
        if self.max_payload != MAX_PAYLOAD {
            return Err(format!(
                "max_payload is {}, version {VERSION} uses {MAX_PAYLOAD}",
                self.max_payload
            ));
        }
        if !self.dt.is_finite() || self.dt < 0.0 {
            return Err(format!("dt is {}, expected seconds >= 0", self.dt));
        }
        if self.name.len() > MAX_NAME {
            return Err(format!(
                "name is {} bytes, at most {MAX_NAME}",
                self.name.len()
            ));
        }
        for (what, len) in [
            ("ACT", self.act_payload_len()),
            ("CHUNK", self.chunk_payload_len()),
        ] {
            if len > MAX_PAYLOAD as usize {
                return Err(format!(
                    "{what} payloads of this model would be {len} bytes, over {MAX_PAYLOAD}"
                ));
            }
        }
        Ok(())
    }
}

/// A CHUNK reply.
#[derive(Clone, Debug, PartialEq)]
pub struct Chunk {
    /// Server-side wall time of the policy call, nanoseconds.
    pub policy_ns: u64,
    pub horizon: u16,
    pub action_dim: u16,
    pub exec_steps: u16,
    /// `horizon` actions of `action_dim` values, step-major.
    pub actions: Vec<f64>,
}

/// An ERROR reply as received (the code is kept raw so codes of later versions survive).
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct ErrorReply {
    pub code: u16,
    pub request_type: u8,
    pub fatal: bool,
    pub text: String,
}

impl ErrorReply {
    /// The reply to a request of type `request_type` (0: no header read) that failed with `error`.
    pub fn from_error(error: &ProtocolError, request_type: u8) -> ErrorReply {
        ErrorReply {
            code: error.code.code(),
            request_type,
            fatal: error.code == ErrorCode::Truncated,
            text: truncate_utf8(&error.text, MAX_TEXT).to_string(),
        }
    }

    pub fn kind(&self) -> Option<ErrorCode> {
        ErrorCode::from_u16(self.code)
    }
}

/// A server -> client message.
#[derive(Clone, Debug, PartialEq)]
pub enum Reply {
    HelloOk(ModelInfo),
    ResetOk { seed: u64 },
    Chunk(Chunk),
    CloseOk,
    Error(ErrorReply),
}

impl Reply {
    pub fn msg_type(&self) -> MsgType {
        match self {
            Reply::HelloOk(_) => MsgType::HelloOk,
            Reply::ResetOk { .. } => MsgType::ResetOk,
            Reply::Chunk(_) => MsgType::Chunk,
            Reply::CloseOk => MsgType::CloseOk,
            Reply::Error(_) => MsgType::Error,
        }
    }

    /// The whole frame; CHUNK values in `float_type` (HELLO_OK uses its own `float_type`).
    pub fn encode(&self, float_type: FloatType) -> Vec<u8> {
        let mut p = Vec::new();
        match self {
            Reply::HelloOk(info) => {
                for v in [
                    info.obs_dim,
                    info.action_dim,
                    info.obs_history,
                    info.horizon,
                    info.exec_steps,
                ] {
                    p.extend_from_slice(&v.to_le_bytes());
                }
                p.push(info.float_type as u8);
                p.push(0);
                p.extend_from_slice(&info.max_payload.to_le_bytes());
                p.extend_from_slice(&info.dt.to_le_bytes());
                let name = truncate_utf8(&info.name, MAX_NAME);
                p.extend_from_slice(&(name.len() as u16).to_le_bytes());
                p.extend_from_slice(name.as_bytes());
            }
            Reply::ResetOk { seed } => p.extend_from_slice(&seed.to_le_bytes()),
            Reply::Chunk(c) => {
                p.extend_from_slice(&c.policy_ns.to_le_bytes());
                for v in [c.horizon, c.action_dim, c.exec_steps, 0] {
                    p.extend_from_slice(&v.to_le_bytes());
                }
                put_values(&mut p, &c.actions, float_type);
            }
            Reply::CloseOk => {}
            Reply::Error(e) => {
                let text = truncate_utf8(&e.text, MAX_TEXT);
                p.extend_from_slice(&e.code.to_le_bytes());
                p.push(e.request_type);
                p.push(u8::from(e.fatal));
                p.extend_from_slice(&(text.len() as u16).to_le_bytes());
                p.extend_from_slice(text.as_bytes());
            }
        }
        frame(self.msg_type(), p)
    }
}

/// Decodes a reply payload (client side). CHUNK needs the float type HELLO_OK announced.
pub fn decode_reply(
    msg_type: MsgType,
    payload: &[u8],
    float_type: Option<FloatType>,
) -> Result<Reply> {
    let mut f = Fields::new(payload);
    match msg_type {
        MsgType::HelloOk => {
            expect_at_least("HELLO_OK", payload, 26)?;
            let dims: Vec<u16> = (0..5).map(|_| f.u16()).collect();
            let float_byte = f.u8();
            let reserved = f.u8();
            let max_payload = f.u32();
            let dt = f.f64();
            let name_len = f.u16();
            expect_len(
                "HELLO_OK",
                payload,
                26 + u64::from(name_len),
                format_args!("26 + {name_len}"),
            )?;
            if reserved != 0 {
                return Err(bad_value(format!(
                    "HELLO_OK reserved byte is {reserved}, must be 0"
                )));
            }
            let float_type = FloatType::from_u8(float_byte).ok_or_else(|| {
                bad_value(format!(
                    "HELLO_OK float_type is {float_byte}, expected 1 or 2"
                ))
            })?;
            let info = ModelInfo {
                obs_dim: dims[0],
                action_dim: dims[1],
                obs_history: dims[2],
                horizon: dims[3],
                exec_steps: dims[4],
                float_type,
                max_payload,
                dt,
                name: utf8("HELLO_OK name", f.rest())?,
            };
            info.validate()
                .map_err(|e| bad_value(format!("HELLO_OK: {e}")))?;
            Ok(Reply::HelloOk(info))
        }
        MsgType::ResetOk => {
            expect_len("RESET_OK", payload, 8, 8)?;
            Ok(Reply::ResetOk { seed: f.u64() })
        }
        MsgType::Chunk => {
            let float_type = float_type.ok_or_else(|| {
                ProtocolError::new(
                    ErrorCode::OutOfOrder,
                    "CHUNK before HELLO_OK: value type unknown",
                )
            })?;
            expect_at_least("CHUNK", payload, 16)?;
            let policy_ns = f.u64();
            let (horizon, action_dim, exec_steps, reserved) = (f.u16(), f.u16(), f.u16(), f.u16());
            let w = float_type.width();
            let expected = 16 + u64::from(horizon) * u64::from(action_dim) * w as u64;
            expect_len(
                "CHUNK",
                payload,
                expected,
                format_args!("16 + {horizon} x {action_dim} x {w} = {expected}"),
            )?;
            if reserved != 0 {
                return Err(bad_value(format!(
                    "CHUNK reserved field is {reserved}, must be 0"
                )));
            }
            let actions = f.values(usize::from(horizon) * usize::from(action_dim), float_type);
            Ok(Reply::Chunk(Chunk {
                policy_ns,
                horizon,
                action_dim,
                exec_steps,
                actions,
            }))
        }
        MsgType::CloseOk => {
            expect_len("CLOSE_OK", payload, 0, 0)?;
            Ok(Reply::CloseOk)
        }
        MsgType::Error => {
            expect_at_least("ERROR", payload, 6)?;
            let (code, request_type, fatal, text_len) = (f.u16(), f.u8(), f.u8(), f.u16());
            expect_len(
                "ERROR",
                payload,
                6 + u64::from(text_len),
                format_args!("6 + {text_len}"),
            )?;
            if fatal > 1 {
                return Err(bad_value(format!(
                    "ERROR fatal flag is {fatal}, expected 0 or 1"
                )));
            }
            Ok(Reply::Error(ErrorReply {
                code,
                request_type,
                fatal: fatal == 1,
                text: utf8("ERROR text", f.rest())?,
            }))
        }
        other => Err(ProtocolError::new(
            ErrorCode::UnknownType,
            format!("{} is not a reply", other.name()),
        )),
    }
}
