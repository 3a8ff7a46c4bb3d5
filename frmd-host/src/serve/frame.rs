//! Frames (specification section 3): constants, message types, float types, the 8-byte header
//! and its checks, and a stream reader that answers bad headers before their payload arrives.
use super::error::{bad_value, ErrorCode, ProtocolError, Result};
use std::io::{self, Read};

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

/// The value type of observations and actions, announced in HELLO_OK.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum FloatType {
    F32 = 1,
    F64 = 2,
}

/// `f32` or `f64`, as `frmd serve --float` takes it.
impl std::fmt::Display for FloatType {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(match self {
            FloatType::F32 => "f32",
            FloatType::F64 => "f64",
        })
    }
}

impl std::str::FromStr for FloatType {
    type Err = String;

    fn from_str(text: &str) -> std::result::Result<Self, String> {
        match text {
            "f32" => Ok(FloatType::F32),
            "f64" => Ok(FloatType::F64),
            other => Err(format!("`{other}`: expected f32 or f64")),
        }
    }
}

impl FloatType {
    /// The type of wire code `byte` (1: f32, 2: f64).
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

/// A whole frame: header and payload.
pub(super) fn frame(msg_type: MsgType, payload: Vec<u8>) -> Vec<u8> {
    let mut out = Header::new(msg_type, payload.len()).encode().to_vec();
    out.extend_from_slice(&payload);
    out
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
    /// End of input inside a header, payload or skipped payload; `request_type` is the type
    /// byte of the frame whose header was read (0 inside a header).
    Truncated {
        error: ProtocolError,
        request_type: u8,
    },
}

/// Reads frames from a byte stream (the server side reads requests, a client replies).
pub struct FrameReader<R> {
    inner: R,
    requests: bool,
    skip: u64,
    /// Type byte of the rejected frame whose payload `skip` counts.
    skip_type: u8,
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
            skip_type: 0,
        }
    }

    pub fn next_frame(&mut self) -> io::Result<ReadOutcome> {
        if self.skip > 0 {
            let wanted = std::mem::take(&mut self.skip);
            let skipped = io::copy(&mut (&mut self.inner).take(wanted), &mut io::sink())?;
            if skipped < wanted {
                return Ok(ReadOutcome::Truncated {
                    error: ProtocolError::new(
                        ErrorCode::Truncated,
                        format!("end of input after {skipped} of {wanted} bytes of a rejected frame's payload"),
                    ),
                    request_type: self.skip_type,
                });
            }
        }
        let mut head = [0u8; HEADER_LEN];
        let got = read_full(&mut self.inner, &mut head)?;
        if got == 0 {
            return Ok(ReadOutcome::Eof);
        }
        if got < HEADER_LEN {
            return Ok(ReadOutcome::Truncated {
                error: ProtocolError::new(
                    ErrorCode::Truncated,
                    format!("end of input after {got} of {HEADER_LEN} header bytes"),
                ),
                request_type: 0,
            });
        }
        let header = Header::decode(&head);
        let msg_type = match header.check(self.requests) {
            Ok(t) => t,
            Err(error) => {
                self.skip = u64::from(header.payload_len);
                self.skip_type = header.msg_type;
                return Ok(ReadOutcome::Rejected { header, error });
            }
        };
        let mut payload = vec![0u8; header.payload_len as usize];
        let got = read_full(&mut self.inner, &mut payload)?;
        if got < payload.len() {
            return Ok(ReadOutcome::Truncated {
                error: ProtocolError::new(
                    ErrorCode::Truncated,
                    format!(
                        "end of input after {got} of {} payload bytes of a {} frame",
                        payload.len(),
                        msg_type.name()
                    ),
                ),
                request_type: header.msg_type,
            });
        }
        Ok(ReadOutcome::Frame { msg_type, payload })
    }
}
