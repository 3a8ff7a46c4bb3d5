//! ERROR codes and the protocol error every malformed frame becomes (specification section 4,
//! ERROR).
use std::fmt;

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
    pub fn new(code: ErrorCode, text: impl Into<String>) -> Self {
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

pub(super) type Result<T> = std::result::Result<T, ProtocolError>;

pub(super) fn bad_length(what: &str, got: usize, expected: impl fmt::Display) -> ProtocolError {
    ProtocolError::new(
        ErrorCode::BadLength,
        format!("{what} payload is {got} bytes, expected {expected}"),
    )
}

pub(super) fn bad_value(text: impl Into<String>) -> ProtocolError {
    ProtocolError::new(ErrorCode::BadValue, text)
}
