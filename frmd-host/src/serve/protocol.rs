//! The `frmd serve` wire protocol, version 1 (`docs/serve-protocol.md` is the specification):
//! frame header, message codec (both directions), a stream reader that answers bad headers before
//! their payload arrives, and the server-side session rules (message order, `executed`
//! bookkeeping of the last commanded action and its rate, timing of the policy call).
//!
//! std only, no dependencies. Nothing here panics on any input: every malformed frame becomes a
//! [`ProtocolError`] with the code and text the specification lists.
use std::fmt;
use std::io::{self, Read, Write};
use std::time::Instant;

/// Protocol version of this module.
pub const VERSION: u8 = 1;
/// Bytes in a frame header.
pub const HEADER_LEN: usize = 8;
/// Largest payload a frame may carry, bytes.
pub const MAX_PAYLOAD: u32 = 1 << 20;
/// HELLO payload.
pub const MAGIC: [u8; 4] = *b"FRMD";
/// Longest policy name in HELLO_OK, bytes.
pub const MAX_NAME: usize = 256;
/// Longest ERROR text, bytes.
pub const MAX_TEXT: usize = 1024;

/// Message types (the header's `type` byte).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum MsgType {
    Hello = 0x01,
    Reset = 0x02,
    Act = 0x03,
    Close = 0x04,
    HelloOk = 0x81,
    ResetOk = 0x82,
    Chunk = 0x83,
    CloseOk = 0x84,
    Error = 0xFF,
}

impl MsgType {
    pub fn from_u8(byte: u8) -> Option<MsgType> {
        Some(match byte {
            0x01 => MsgType::Hello,
            0x02 => MsgType::Reset,
            0x03 => MsgType::Act,
            0x04 => MsgType::Close,
            0x81 => MsgType::HelloOk,
            0x82 => MsgType::ResetOk,
            0x83 => MsgType::Chunk,
            0x84 => MsgType::CloseOk,
            0xFF => MsgType::Error,
            _ => return None,
        })
    }

    /// Client -> server types.
    pub fn is_request(self) -> bool {
        (self as u8) < 0x80
    }

    pub fn name(self) -> &'static str {
        match self {
            MsgType::Hello => "HELLO",
            MsgType::Reset => "RESET",
            MsgType::Act => "ACT",
            MsgType::Close => "CLOSE",
            MsgType::HelloOk => "HELLO_OK",
            MsgType::ResetOk => "RESET_OK",
            MsgType::Chunk => "CHUNK",
            MsgType::CloseOk => "CLOSE_OK",
            MsgType::Error => "ERROR",
        }
    }
}

/// ERROR codes of the specification (section 4, ERROR).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum ErrorCode {
    UnsupportedVersion = 1,
    UnknownType = 2,
    FrameTooLarge = 3,
    BadLength = 4,
    BadValue = 5,
    NonFinite = 6,
    OutOfOrder = 7,
    PolicyFailed = 8,
    Truncated = 9,
}

impl ErrorCode {
    pub const ALL: [ErrorCode; 9] = [
        ErrorCode::UnsupportedVersion,
        ErrorCode::UnknownType,
        ErrorCode::FrameTooLarge,
        ErrorCode::BadLength,
        ErrorCode::BadValue,
        ErrorCode::NonFinite,
        ErrorCode::OutOfOrder,
        ErrorCode::PolicyFailed,
        ErrorCode::Truncated,
    ];

    pub fn code(self) -> u16 {
        self as u16
    }

    pub fn from_u16(code: u16) -> Option<ErrorCode> {
        Self::ALL.into_iter().find(|c| c.code() == code)
    }

    pub fn name(self) -> &'static str {
        match self {
            ErrorCode::UnsupportedVersion => "UNSUPPORTED_VERSION",
            ErrorCode::UnknownType => "UNKNOWN_TYPE",
            ErrorCode::FrameTooLarge => "FRAME_TOO_LARGE",
            ErrorCode::BadLength => "BAD_LENGTH",
            ErrorCode::BadValue => "BAD_VALUE",
            ErrorCode::NonFinite => "NON_FINITE",
            ErrorCode::OutOfOrder => "OUT_OF_ORDER",
            ErrorCode::PolicyFailed => "POLICY_FAILED",
            ErrorCode::Truncated => "TRUNCATED",
        }
    }
}

/// A protocol violation: the code sent in the ERROR frame and its text.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct ProtocolError {
    pub code: ErrorCode,
    pub text: String,
}

impl ProtocolError {
    fn new(code: ErrorCode, text: impl Into<String>) -> Self {
        ProtocolError {
            code,
            text: text.into(),
        }
    }
}

impl fmt::Display for ProtocolError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "{}: {}", self.code.name(), self.text)
    }
}

impl std::error::Error for ProtocolError {}

type Result<T> = std::result::Result<T, ProtocolError>;

fn bad_length(what: &str, got: usize, expected: impl fmt::Display) -> ProtocolError {
    ProtocolError::new(
        ErrorCode::BadLength,
        format!("{what} payload is {got} bytes, expected {expected}"),
    )
}

fn bad_value(text: impl Into<String>) -> ProtocolError {
    ProtocolError::new(ErrorCode::BadValue, text)
}

/// The value type of observations and actions, announced in HELLO_OK.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum FloatType {
    F32 = 1,
    F64 = 2,
}

impl FloatType {
    pub fn from_u8(byte: u8) -> Option<FloatType> {
        match byte {
            1 => Some(FloatType::F32),
            2 => Some(FloatType::F64),
            _ => None,
        }
    }

    /// Bytes per value.
    pub fn width(self) -> usize {
        match self {
            FloatType::F32 => 4,
            FloatType::F64 => 8,
        }
    }
}

/// The 8-byte frame header.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Header {
    pub payload_len: u32,
    pub version: u8,
    pub msg_type: u8,
    pub reserved: u16,
}

impl Header {
    pub fn new(msg_type: MsgType, payload_len: usize) -> Header {
        Header {
            payload_len: u32::try_from(payload_len).unwrap_or(u32::MAX),
            version: VERSION,
            msg_type: msg_type as u8,
            reserved: 0,
        }
    }

    pub fn encode(&self) -> [u8; HEADER_LEN] {
        let mut out = [0u8; HEADER_LEN];
        out[..4].copy_from_slice(&self.payload_len.to_le_bytes());
        out[4] = self.version;
        out[5] = self.msg_type;
        out[6..].copy_from_slice(&self.reserved.to_le_bytes());
        out
    }

    pub fn decode(bytes: &[u8; HEADER_LEN]) -> Header {
        Header {
            payload_len: u32::from_le_bytes([bytes[0], bytes[1], bytes[2], bytes[3]]),
            version: bytes[4],
            msg_type: bytes[5],
            reserved: u16::from_le_bytes([bytes[6], bytes[7]]),
        }
    }

    /// The header checks of the specification, in its order (version, length, reserved, type),
    /// for frames travelling to a server (`requests`) or to a client.
    pub fn check(&self, requests: bool) -> Result<MsgType> {
        if self.version != VERSION {
            return Err(ProtocolError::new(
                ErrorCode::UnsupportedVersion,
                format!(
                    "protocol version {} is not supported; this server speaks version {VERSION}",
                    self.version
                ),
            ));
        }
        if self.payload_len > MAX_PAYLOAD {
            return Err(ProtocolError::new(
                ErrorCode::FrameTooLarge,
                format!(
                    "payload of {} bytes exceeds the limit of {MAX_PAYLOAD}",
                    self.payload_len
                ),
            ));
        }
        if self.reserved != 0 {
            return Err(bad_value(format!(
                "header reserved field is {:#06x}, must be 0",
                self.reserved
            )));
        }
        match MsgType::from_u8(self.msg_type) {
            Some(t) if t.is_request() == requests => Ok(t),
            Some(t) => Err(ProtocolError::new(
                ErrorCode::UnknownType,
                format!(
                    "type {:#04x} ({}) is not a {} type",
                    self.msg_type,
                    t.name(),
                    if requests { "request" } else { "reply" }
                ),
            )),
            None => Err(ProtocolError::new(
                ErrorCode::UnknownType,
                format!(
                    "unknown {} type {:#04x}",
                    if requests { "request" } else { "reply" },
                    self.msg_type
                ),
            )),
        }
    }
}

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

fn truncate_utf8(text: &str, max: usize) -> &str {
    if text.len() <= max {
        return text;
    }
    let mut end = max;
    while !text.is_char_boundary(end) {
        end -= 1;
    }
    &text[..end]
}

fn put_values(out: &mut Vec<u8>, values: &[f64], float_type: FloatType) {
    for &v in values {
        match float_type {
            FloatType::F32 => out.extend_from_slice(&(v as f32).to_le_bytes()),
            FloatType::F64 => out.extend_from_slice(&v.to_le_bytes()),
        }
    }
}

fn frame(msg_type: MsgType, payload: Vec<u8>) -> Vec<u8> {
    let mut out = Header::new(msg_type, payload.len()).encode().to_vec();
    out.extend_from_slice(&payload);
    out
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

/// Little-endian field reader over a payload whose length was checked first.
struct Fields<'a> {
    bytes: &'a [u8],
    at: usize,
}

impl<'a> Fields<'a> {
    fn new(bytes: &'a [u8]) -> Self {
        Fields { bytes, at: 0 }
    }

    fn take<const L: usize>(&mut self) -> [u8; L] {
        let mut out = [0u8; L];
        if let Some(src) = self.bytes.get(self.at..self.at + L) {
            out.copy_from_slice(src);
        }
        self.at += L;
        out
    }

    fn u8(&mut self) -> u8 {
        self.take::<1>()[0]
    }
    fn u16(&mut self) -> u16 {
        u16::from_le_bytes(self.take())
    }
    fn u32(&mut self) -> u32 {
        u32::from_le_bytes(self.take())
    }
    fn u64(&mut self) -> u64 {
        u64::from_le_bytes(self.take())
    }
    fn f64(&mut self) -> f64 {
        f64::from_le_bytes(self.take())
    }

    fn values(&mut self, count: usize, float_type: FloatType) -> Vec<f64> {
        (0..count)
            .map(|_| match float_type {
                FloatType::F32 => f64::from(f32::from_le_bytes(self.take())),
                FloatType::F64 => self.f64(),
            })
            .collect()
    }

    fn rest(&self) -> &'a [u8] {
        self.bytes.get(self.at..).unwrap_or(&[])
    }
}

fn expect_len(what: &str, payload: &[u8], expected: u64, formula: impl fmt::Display) -> Result<()> {
    if payload.len() as u64 == expected {
        Ok(())
    } else {
        Err(bad_length(what, payload.len(), formula))
    }
}

fn expect_at_least(what: &str, payload: &[u8], min: usize) -> Result<()> {
    if payload.len() >= min {
        Ok(())
    } else {
        Err(bad_length(what, payload.len(), format!("at least {min}")))
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

fn utf8(what: &str, bytes: &[u8]) -> Result<String> {
    String::from_utf8(bytes.to_vec()).map_err(|_| bad_value(format!("{what} is not valid UTF-8")))
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

/// The first non-finite value of `values` (rows of `row_len`), as an error naming its place.
fn check_finite(what: &str, values: &[f64], row_len: usize) -> Result<()> {
    match values.iter().position(|v| !v.is_finite()) {
        None => Ok(()),
        Some(i) => {
            let v = values[i];
            let kind = if v.is_nan() {
                "NaN".to_string()
            } else {
                format!("{v}")
            };
            let place = match (i.checked_div(row_len), i.checked_rem(row_len)) {
                (Some(row), Some(col)) => format!("{what} {row} element {col}"),
                _ => format!("{what} element {i}"),
            };
            Err(ProtocolError::new(
                ErrorCode::NonFinite,
                format!("{place} is {kind}"),
            ))
        }
    }
}

/// One outcome of [`FrameReader::next_frame`].
#[derive(Debug)]
pub enum ReadOutcome {
    /// A frame whose header passed [`Header::check`].
    Frame { msg_type: MsgType, payload: Vec<u8> },
    /// A header that failed its checks; answered at once, its payload is skipped by the next call.
    Rejected {
        header: Header,
        error: ProtocolError,
    },
    /// End of input at a frame boundary.
    Eof,
    /// End of input inside a header, payload or skipped payload.
    Truncated(ProtocolError),
}

/// Reads frames from a byte stream (the server side reads requests, a client replies).
pub struct FrameReader<R> {
    inner: R,
    requests: bool,
    skip: u64,
}

/// Reads until `buf` is full or end of input; returns the bytes read.
fn read_full<R: Read>(reader: &mut R, buf: &mut [u8]) -> io::Result<usize> {
    let mut filled = 0;
    while filled < buf.len() {
        match reader.read(&mut buf[filled..]) {
            Ok(0) => break,
            Ok(n) => filled += n,
            Err(e) if e.kind() == io::ErrorKind::Interrupted => {}
            Err(e) => return Err(e),
        }
    }
    Ok(filled)
}

impl<R: Read> FrameReader<R> {
    /// `requests`: true on the server (frames must be requests), false on a client.
    pub fn new(inner: R, requests: bool) -> Self {
        FrameReader {
            inner,
            requests,
            skip: 0,
        }
    }

    pub fn next_frame(&mut self) -> io::Result<ReadOutcome> {
        if self.skip > 0 {
            let wanted = std::mem::take(&mut self.skip);
            let skipped = io::copy(&mut (&mut self.inner).take(wanted), &mut io::sink())?;
            if skipped < wanted {
                return Ok(ReadOutcome::Truncated(ProtocolError::new(
                    ErrorCode::Truncated,
                    format!("end of input after {skipped} of {wanted} bytes of a rejected frame's payload"),
                )));
            }
        }
        let mut head = [0u8; HEADER_LEN];
        let got = read_full(&mut self.inner, &mut head)?;
        if got == 0 {
            return Ok(ReadOutcome::Eof);
        }
        if got < HEADER_LEN {
            return Ok(ReadOutcome::Truncated(ProtocolError::new(
                ErrorCode::Truncated,
                format!("end of input after {got} of {HEADER_LEN} header bytes"),
            )));
        }
        let header = Header::decode(&head);
        let msg_type = match header.check(self.requests) {
            Ok(t) => t,
            Err(error) => {
                self.skip = u64::from(header.payload_len);
                return Ok(ReadOutcome::Rejected { header, error });
            }
        };
        let mut payload = vec![0u8; header.payload_len as usize];
        let got = read_full(&mut self.inner, &mut payload)?;
        if got < payload.len() {
            return Ok(ReadOutcome::Truncated(ProtocolError::new(
                ErrorCode::Truncated,
                format!(
                    "end of input after {got} of {} payload bytes of a {} frame",
                    payload.len(),
                    msg_type.name()
                ),
            )));
        }
        Ok(ReadOutcome::Frame { msg_type, payload })
    }
}

/// What a served policy is asked for one chunk (raw units; see [`Session`]).
pub struct ActInput<'a> {
    /// `obs_history` observations of `obs_dim` values, oldest first.
    pub obs: &'a [f64],
    /// The last commanded action (ProDMP `y0`).
    pub prev_action: &'a [f64],
    /// Its finite-difference rate, units per second (ProDMP `v0`).
    pub prev_rate: &'a [f64],
}

/// The model behind a server.
pub trait ServedPolicy {
    /// Starts an episode: reseed the noise stream.
    fn reset(&mut self, seed: u64);
    /// `horizon * action_dim` values, step-major; an `Err` is sent as `POLICY_FAILED`.
    fn act(&mut self, input: &ActInput<'_>) -> std::result::Result<Vec<f64>, String>;
}

/// The running episode: the last chunk and the two last commanded actions.
#[derive(Clone, Debug)]
struct Episode {
    chunk: Option<Vec<f64>>,
    prev: Vec<f64>,
    prev2: Vec<f64>,
}

/// Server-side session rules: order (HELLO first, RESET before ACT), `executed` bookkeeping of
/// the commanded actions, finiteness checks, timing, and "a rejected request changes nothing".
pub struct Session {
    info: ModelInfo,
    default_init: Vec<f64>,
    hello: bool,
    episode: Option<Episode>,
}

/// What the server loop does after a reply.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Next {
    Continue,
    Close,
}

impl Session {
    /// `default_init`: the action before an episode when RESET gives none (`action_dim` values).
    pub fn new(info: ModelInfo, default_init: Vec<f64>) -> std::result::Result<Session, String> {
        info.validate()?;
        if default_init.len() != usize::from(info.action_dim) {
            return Err(format!(
                "default initial action has {} values, action_dim is {}",
                default_init.len(),
                info.action_dim
            ));
        }
        Ok(Session {
            info,
            default_init,
            hello: false,
            episode: None,
        })
    }

    pub fn info(&self) -> &ModelInfo {
        &self.info
    }

    /// Answers one request frame whose header passed its checks.
    pub fn handle(
        &mut self,
        msg_type: MsgType,
        payload: &[u8],
        policy: &mut dyn ServedPolicy,
    ) -> (Reply, Next) {
        match self.try_handle(msg_type, payload, policy) {
            Ok(reply) => {
                let next = if reply == Reply::CloseOk {
                    Next::Close
                } else {
                    Next::Continue
                };
                (reply, next)
            }
            Err(e) => (
                Reply::Error(ErrorReply::from_error(&e, msg_type as u8)),
                Next::Continue,
            ),
        }
    }

    fn try_handle(
        &mut self,
        msg_type: MsgType,
        payload: &[u8],
        policy: &mut dyn ServedPolicy,
    ) -> Result<Reply> {
        let out_of_order = |text: &str| Err(ProtocolError::new(ErrorCode::OutOfOrder, text));
        match msg_type {
            MsgType::Hello | MsgType::Close => {}
            _ if !self.hello => return out_of_order(&format!("{} before HELLO", msg_type.name())),
            MsgType::Act if self.episode.is_none() => {
                return out_of_order("ACT before RESET: no episode has been started")
            }
            _ => {}
        }
        let k = usize::from(self.info.action_dim);
        match decode_request(msg_type, payload, &self.info)? {
            Request::Hello => {
                self.hello = true;
                Ok(Reply::HelloOk(self.info.clone()))
            }
            Request::Close => Ok(Reply::CloseOk),
            Request::Reset { seed, init_action } => {
                check_finite("RESET init_action", &init_action, 0)?;
                let init = if init_action.is_empty() {
                    self.default_init.clone()
                } else {
                    init_action
                };
                policy.reset(seed);
                self.episode = Some(Episode {
                    chunk: None,
                    prev: init.clone(),
                    prev2: init,
                });
                Ok(Reply::ResetOk { seed })
            }
            Request::Act { executed, obs, .. } => {
                let Some(episode) = self.episode.as_ref() else {
                    return out_of_order("ACT before RESET: no episode has been started");
                };
                let (mut prev, mut prev2) = (episode.prev.clone(), episode.prev2.clone());
                if executed > 0 {
                    let chunk = episode.chunk.as_ref().ok_or_else(|| {
                        bad_value(format!(
                            "ACT executed is {executed} but no chunk has been sent in this episode"
                        ))
                    })?;
                    let available = chunk.len() / k.max(1);
                    if executed as usize > available {
                        return Err(bad_value(format!(
                            "ACT executed is {executed} but the previous chunk has {available} actions"
                        )));
                    }
                    for action in chunk.chunks_exact(k).take(executed as usize) {
                        prev2 = std::mem::replace(&mut prev, action.to_vec());
                    }
                }
                check_finite("ACT observation", &obs, usize::from(self.info.obs_dim))?;
                let dt = self.info.dt;
                let rate: Vec<f64> = prev
                    .iter()
                    .zip(&prev2)
                    .map(|(a, b)| if dt > 0.0 { (a - b) / dt } else { 0.0 })
                    .collect();
                let started = Instant::now();
                let actions = policy
                    .act(&ActInput {
                        obs: &obs,
                        prev_action: &prev,
                        prev_rate: &rate,
                    })
                    .map_err(|e| {
                        ProtocolError::new(ErrorCode::PolicyFailed, format!("policy: {e}"))
                    })?;
                let policy_ns = u64::try_from(started.elapsed().as_nanos()).unwrap_or(u64::MAX);
                let expected = usize::from(self.info.horizon) * k;
                if actions.len() != expected {
                    return Err(ProtocolError::new(
                        ErrorCode::PolicyFailed,
                        format!(
                            "policy returned {} values, expected horizon x action_dim = {expected}",
                            actions.len()
                        ),
                    ));
                }
                check_finite("policy action", &actions, k)
                    .map_err(|e| ProtocolError::new(ErrorCode::PolicyFailed, e.text))?;
                self.episode = Some(Episode {
                    chunk: Some(actions.clone()),
                    prev,
                    prev2,
                });
                Ok(Reply::Chunk(Chunk {
                    policy_ns,
                    horizon: self.info.horizon,
                    action_dim: self.info.action_dim,
                    exec_steps: self.info.exec_steps,
                    actions,
                }))
            }
        }
    }
}

/// How a served stream ended.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum StreamEnd {
    /// CLOSE answered (stdio exit status 0).
    Closed,
    /// End of input at a frame boundary (status 0).
    Eof,
    /// End of input inside a frame, TRUNCATED sent (status 1).
    Truncated,
}

/// Serves one session over a byte stream until CLOSE or end of input. Errors are I/O errors of
/// the output (the client went away).
pub fn serve_stream<R: Read, W: Write>(
    input: R,
    mut output: W,
    session: &mut Session,
    policy: &mut dyn ServedPolicy,
) -> io::Result<StreamEnd> {
    let mut reader = FrameReader::new(input, true);
    let float_type = session.info().float_type;
    loop {
        let (reply, next) = match reader.next_frame()? {
            ReadOutcome::Eof => return Ok(StreamEnd::Eof),
            ReadOutcome::Truncated(error) => {
                let reply = Reply::Error(ErrorReply::from_error(&error, 0));
                // Best effort: the client may already be gone.
                let _ = output
                    .write_all(&reply.encode(float_type))
                    .and_then(|()| output.flush());
                return Ok(StreamEnd::Truncated);
            }
            ReadOutcome::Rejected { header, error } => (
                Reply::Error(ErrorReply::from_error(&error, header.msg_type)),
                Next::Continue,
            ),
            ReadOutcome::Frame { msg_type, payload } => session.handle(msg_type, &payload, policy),
        };
        output.write_all(&reply.encode(float_type))?;
        output.flush()?;
        if next == Next::Close {
            return Ok(StreamEnd::Closed);
        }
    }
}

#[cfg(test)]
mod tests {
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
    fn run_server(
        input: &[u8],
        session: &mut Session,
        policy: &mut Echo,
    ) -> (Vec<Reply>, StreamEnd) {
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
        let doc = include_str!("../../../docs/serve-protocol.md");
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
            let (replies, _) =
                run_server(&requests(&list, ft), &mut session(ft), &mut Echo::default());
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
        for (input, expect_errors, text) in [
            (hello[..5].to_vec(), 1, "after 5 of 8 header bytes"),
            (
                [hello.clone(), hello[..10].to_vec()].concat(),
                1,
                "after 2 of 4 payload bytes of a HELLO frame",
            ),
            (
                big,
                2,
                "after 100 of 1048586 bytes of a rejected frame's payload",
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
                (Some(ErrorCode::Truncated), true, 0)
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

    /// xorshift64*: a small deterministic generator for the fuzz loops.
    struct Rng(u64);
    impl Rng {
        fn next(&mut self) -> u64 {
            self.0 ^= self.0 >> 12;
            self.0 ^= self.0 << 25;
            self.0 ^= self.0 >> 27;
            self.0.wrapping_mul(0x2545_f491_4f6c_dd1d)
        }
        fn below(&mut self, n: usize) -> usize {
            (self.next() % n as u64) as usize
        }
    }

    /// Random byte streams, and valid sessions with random byte flips, insertions and cuts: the
    /// server always ends, every reply it writes is a valid frame, and it answers each complete
    /// frame it read.
    #[test]
    fn fuzz_the_server_with_arbitrary_and_mutated_streams() {
        let mut rng = Rng(0x9e37_79b9_7f4a_7c15);
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
                    let mut bytes: Vec<u8> = (0..len).map(|_| rng.next() as u8).collect();
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
                            1 => bytes[at] = rng.next() as u8,
                            2 => bytes.insert(at, rng.next() as u8),
                            _ => bytes.truncate(at),
                        }
                    }
                    bytes
                };
                let mut s = session(ft);
                let mut out = Vec::new();
                let end = serve_stream(Cursor::new(&input), &mut out, &mut s, &mut Echo::default())
                    .unwrap();
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
        let mut rng = Rng(77);
        let info = toy_info(FloatType::F32);
        for _ in 0..20_000 {
            let len = rng.below(64);
            let payload: Vec<u8> = (0..len).map(|_| rng.next() as u8).collect();
            for t in [0x01, 0x02, 0x03, 0x04, 0x81, 0x82, 0x83, 0x84, 0xff] {
                let t = MsgType::from_u8(t).unwrap();
                let _ = decode_request(t, &payload, &info);
                let _ = decode_reply(t, &payload, Some(FloatType::F64));
            }
        }
    }
}
