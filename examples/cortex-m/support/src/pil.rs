//! The processor-in-the-loop frame format: what the `pil` firmware image
//! (`src/bin/frmd-cortex-m-pil.rs`) and the host driver (`frmd-host/src/firmware/`) exchange over
//! semihosting (the image's standard input and output under QEMU).
//!
//! `core` + frmd-core only, so both sides use this one definition.
//!
//! # Frame
//!
//! | bytes        | field                                                             |
//! |--------------|-------------------------------------------------------------------|
//! | 0..2         | magic `"FP"` (0x46 0x50)                                          |
//! | 2            | message type ([`MsgType`])                                        |
//! | 3            | reserved, 0                                                       |
//! | 4..6         | payload length `n`, u16 little-endian, at most [`MAX_PAYLOAD`]    |
//! | 6..6+n       | payload                                                           |
//! | 6+n..10+n    | CRC-32 (IEEE, [`frmd_core::blob::crc32`]) of bytes 2..6+n, LE     |
//!
//! All numbers are little-endian; floats are IEEE f32 bit patterns.
//!
//! # Messages (host -> image, image -> host)
//!
//! - `HELLO` (0x01, empty) -> `INFO` (0x81): u16 history, obs_dim, action_dim, horizon; u32 CPUID,
//!   flash bytes, static RAM bytes, instructions per 1000 SysTick ticks (the calibration).
//! - `RESET` (0x02, u64 seed) -> `RESET_OK` (0x82, empty): reseeds the noise stream
//!   (`frmd_core::rng::Rng::new(seed)`); every `ACT` draws its noise from it, in order.
//! - `ACT` (0x03): f32 observations (`history x obs_dim`, oldest first), f32 previous action `y0`
//!   (`action_dim`), f32 its rate `v0` (`action_dim`) -> `CHUNK` (0x83): u32 instructions of
//!   `Policy::act` (the chunk), u32 instructions of the whole request (policy reset, observe,
//!   previous action and act), then the chunk's f32 positions (`horizon x action_dim`, step-major).
//! - `EXIT` (0x04, empty) -> `EXIT_OK` (0x84, empty), then the image ends QEMU with status 0.
//! - Any request the image cannot answer -> `ERROR` (0xFF): u8 [`ErrorCode`], u8 the request's
//!   type byte (0 if unknown), then UTF-8 text.
//!
//! A frame with a bad magic or an oversized length is answered with `ERROR` at once; the image
//! then drops input until the next `"FP"`. A bad CRC, an unknown type or a payload of the wrong
//! size is answered with `ERROR` after its payload, and nothing changes. The end of the input ends
//! the image with status 0.

use frmd_core::blob::crc32::Crc32;

/// First two bytes of every frame.
pub const MAGIC: [u8; 2] = *b"FP";
/// Bytes before the payload.
pub const HEADER_LEN: usize = 6;
/// Bytes after the payload (the CRC).
pub const TRAILER_LEN: usize = 4;
/// Largest payload either side sends or accepts.
pub const MAX_PAYLOAD: usize = 4096;
/// Bytes of an `INFO` payload.
pub const INFO_LEN: usize = 8 + 16;
/// Bytes before the positions of a `CHUNK` payload (the two instruction counts).
pub const CHUNK_PREFIX: usize = 8;
/// Bytes of a `RESET` payload.
pub const RESET_LEN: usize = 8;

/// Message types (the header's type byte); requests below 0x80, replies above.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum MsgType {
    Hello = 0x01,
    Reset = 0x02,
    Act = 0x03,
    Exit = 0x04,
    Info = 0x81,
    ResetOk = 0x82,
    Chunk = 0x83,
    ExitOk = 0x84,
    Error = 0xFF,
}

impl MsgType {
    pub fn from_u8(byte: u8) -> Option<Self> {
        Some(match byte {
            0x01 => Self::Hello,
            0x02 => Self::Reset,
            0x03 => Self::Act,
            0x04 => Self::Exit,
            0x81 => Self::Info,
            0x82 => Self::ResetOk,
            0x83 => Self::Chunk,
            0x84 => Self::ExitOk,
            0xFF => Self::Error,
            _ => return None,
        })
    }

    pub fn name(self) -> &'static str {
        match self {
            Self::Hello => "HELLO",
            Self::Reset => "RESET",
            Self::Act => "ACT",
            Self::Exit => "EXIT",
            Self::Info => "INFO",
            Self::ResetOk => "RESET_OK",
            Self::Chunk => "CHUNK",
            Self::ExitOk => "EXIT_OK",
            Self::Error => "ERROR",
        }
    }
}

/// Why the image rejected a request (first byte of an `ERROR` payload).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum ErrorCode {
    BadMagic = 1,
    TooLong = 2,
    BadCrc = 3,
    UnknownType = 4,
    BadLength = 5,
    PolicyFailed = 6,
}

impl ErrorCode {
    pub fn from_u8(byte: u8) -> Option<Self> {
        Some(match byte {
            1 => Self::BadMagic,
            2 => Self::TooLong,
            3 => Self::BadCrc,
            4 => Self::UnknownType,
            5 => Self::BadLength,
            6 => Self::PolicyFailed,
            _ => return None,
        })
    }

    pub fn name(self) -> &'static str {
        match self {
            Self::BadMagic => "bad magic",
            Self::TooLong => "payload too long",
            Self::BadCrc => "bad CRC",
            Self::UnknownType => "unknown message type",
            Self::BadLength => "wrong payload length",
            Self::PolicyFailed => "policy failed",
        }
    }
}

/// A checked frame header.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Header {
    /// The raw type byte (checked against [`MsgType`] after the CRC).
    pub type_byte: u8,
    pub payload_len: usize,
}

/// Parses a header: the magic and the length bound are checked here, the type after the CRC.
pub fn parse_header(bytes: &[u8; HEADER_LEN]) -> Result<Header, ErrorCode> {
    if bytes[..2] != MAGIC {
        return Err(ErrorCode::BadMagic);
    }
    let payload_len = usize::from(u16::from_le_bytes([bytes[4], bytes[5]]));
    if payload_len > MAX_PAYLOAD {
        return Err(ErrorCode::TooLong);
    }
    Ok(Header {
        type_byte: bytes[2],
        payload_len,
    })
}

/// The CRC a frame carries: over its type, reserved and length bytes and its payload.
pub fn frame_crc(header: &[u8; HEADER_LEN], payload: &[u8]) -> u32 {
    let mut crc = Crc32::new();
    crc.update(&header[2..]);
    crc.update(payload);
    crc.finish()
}

/// The header of a frame of `type_byte` with `payload_len` bytes (`None` above [`MAX_PAYLOAD`]).
pub fn header(type_byte: u8, payload_len: usize) -> Option<[u8; HEADER_LEN]> {
    if payload_len > MAX_PAYLOAD {
        return None;
    }
    let len = (payload_len as u16).to_le_bytes();
    Some([MAGIC[0], MAGIC[1], type_byte, 0, len[0], len[1]])
}

/// Writes a whole frame into `out` and returns its length (`None` if `out` is too small or the
/// payload too long).
pub fn encode(type_byte: u8, payload: &[u8], out: &mut [u8]) -> Option<usize> {
    let head = header(type_byte, payload.len())?;
    let total = HEADER_LEN + payload.len() + TRAILER_LEN;
    let frame = out.get_mut(..total)?;
    frame[..HEADER_LEN].copy_from_slice(&head);
    frame[HEADER_LEN..HEADER_LEN + payload.len()].copy_from_slice(payload);
    frame[HEADER_LEN + payload.len()..].copy_from_slice(&frame_crc(&head, payload).to_le_bytes());
    Some(total)
}

/// Bytes of an `ACT` payload for a policy of these sizes.
pub const fn act_len(history: usize, obs_dim: usize, action_dim: usize) -> usize {
    4 * (history * obs_dim + 2 * action_dim)
}

/// Bytes of a `CHUNK` payload for a policy of these sizes.
pub const fn chunk_len(horizon: usize, action_dim: usize) -> usize {
    CHUNK_PREFIX + 4 * horizon * action_dim
}

/// Reads little-endian f32 values from `bytes` into `out` (`bytes.len() == 4 * out.len()`).
pub fn read_f32s(bytes: &[u8], out: &mut [f32]) {
    for (value, word) in out.iter_mut().zip(bytes.chunks_exact(4)) {
        *value = f32::from_le_bytes([word[0], word[1], word[2], word[3]]);
    }
}

/// Writes `values` as little-endian f32 into `out` (`out.len() == 4 * values.len()`).
pub fn write_f32s(values: &[f32], out: &mut [u8]) {
    for (value, word) in values.iter().zip(out.chunks_exact_mut(4)) {
        word.copy_from_slice(&value.to_le_bytes());
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn frame_round_trip_and_checks() {
        let mut out = [0u8; 64];
        let n = encode(MsgType::Reset as u8, &7u64.to_le_bytes(), &mut out).unwrap();
        assert_eq!(n, HEADER_LEN + RESET_LEN + TRAILER_LEN);
        let head: [u8; HEADER_LEN] = out[..HEADER_LEN].try_into().unwrap();
        let parsed = parse_header(&head).unwrap();
        assert_eq!(
            parsed,
            Header {
                type_byte: 0x02,
                payload_len: 8
            }
        );
        let payload = &out[HEADER_LEN..HEADER_LEN + 8];
        let crc = u32::from_le_bytes(out[n - 4..n].try_into().unwrap());
        assert_eq!(frame_crc(&head, payload), crc);
        let mut bad = head;
        bad[0] = b'X';
        assert_eq!(parse_header(&bad), Err(ErrorCode::BadMagic));
        let mut long = head;
        long[4..6].copy_from_slice(&((MAX_PAYLOAD + 1) as u16).to_le_bytes());
        assert_eq!(parse_header(&long), Err(ErrorCode::TooLong));
        assert!(encode(1, &[0; 60], &mut out).is_none());
    }
}
