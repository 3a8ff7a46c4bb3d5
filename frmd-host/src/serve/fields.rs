//! Payload field helpers shared by the request and reply codecs: little-endian reading of
//! length-checked payloads, value writing in either float type, length and finiteness checks.
use super::error::{bad_length, bad_value, ErrorCode, ProtocolError, Result};
use super::frame::FloatType;
use std::fmt;

pub(super) fn truncate_utf8(text: &str, max: usize) -> &str {
    if text.len() <= max {
        return text;
    }
    let mut end = max;
    while !text.is_char_boundary(end) {
        end -= 1;
    }
    &text[..end]
}

pub(super) fn put_values(out: &mut Vec<u8>, values: &[f64], float_type: FloatType) {
    for &v in values {
        match float_type {
            FloatType::F32 => out.extend_from_slice(&(v as f32).to_le_bytes()),
            FloatType::F64 => out.extend_from_slice(&v.to_le_bytes()),
        }
    }
}

/// Little-endian field reader over a payload whose length was checked first.
pub(super) struct Fields<'a> {
    bytes: &'a [u8],
    at: usize,
}

impl<'a> Fields<'a> {
    pub(super) fn new(bytes: &'a [u8]) -> Self {
        Fields { bytes, at: 0 }
    }

    pub(super) fn take<const L: usize>(&mut self) -> [u8; L] {
        let mut out = [0u8; L];
        if let Some(src) = self.bytes.get(self.at..self.at + L) {
            out.copy_from_slice(src);
        }
        self.at += L;
        out
    }

    pub(super) fn u8(&mut self) -> u8 {
        self.take::<1>()[0]
    }
    pub(super) fn u16(&mut self) -> u16 {
        u16::from_le_bytes(self.take())
    }
    pub(super) fn u32(&mut self) -> u32 {
        u32::from_le_bytes(self.take())
    }
    pub(super) fn u64(&mut self) -> u64 {
        u64::from_le_bytes(self.take())
    }
    pub(super) fn f64(&mut self) -> f64 {
        f64::from_le_bytes(self.take())
    }

    pub(super) fn values(&mut self, count: usize, float_type: FloatType) -> Vec<f64> {
        (0..count)
            .map(|_| match float_type {
                FloatType::F32 => f64::from(f32::from_le_bytes(self.take())),
                FloatType::F64 => self.f64(),
            })
            .collect()
    }

    pub(super) fn rest(&self) -> &'a [u8] {
        self.bytes.get(self.at..).unwrap_or(&[])
    }
}

pub(super) fn expect_len(
    what: &str,
    payload: &[u8],
    expected: u64,
    formula: impl fmt::Display,
) -> Result<()> {
    if payload.len() as u64 == expected {
        Ok(())
    } else {
        Err(bad_length(what, payload.len(), formula))
    }
}

pub(super) fn expect_at_least(what: &str, payload: &[u8], min: usize) -> Result<()> {
    if payload.len() >= min {
        Ok(())
    } else {
        Err(bad_length(what, payload.len(), format!("at least {min}")))
    }
}

pub(super) fn utf8(what: &str, bytes: &[u8]) -> Result<String> {
    String::from_utf8(bytes.to_vec()).map_err(|_| bad_value(format!("{what} is not valid UTF-8")))
}

/// The first non-finite value of `values` (rows of `row_len`), as an error naming its place.
pub(super) fn check_finite(what: &str, values: &[f64], row_len: usize) -> Result<()> {
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
