//! `frmd serve`: the policy-server protocol, version 1 (`docs/serve-protocol.md` is the
//! specification), and the server around it.
//!
//! std only, no dependencies in the protocol part. Nothing here panics on any input: every
//! malformed frame becomes a [`ProtocolError`] with the code and text the specification lists.
//!
//! - `frame`: constants, header, frame reader; `error`: error codes;
//! - `request`, `reply`: the messages, each encoded and decoded side by side (`fields`
//!   holds the shared payload helpers);
//! - `session`: order and `executed` rules, timing; `server`: the loop over a byte stream,
//!   stdin/stdout and a Unix socket;
//! - [`load`]: the policy behind the server (checkpoint, baked module, blob) and its HELLO_OK;
//!   [`LocalPolicy`]: the same policy and session rules called in process.
pub(crate) mod error;
mod fields;
mod firmware;
pub(crate) mod frame;
pub(crate) mod load;
mod local;
pub(crate) mod reply;
pub(crate) mod request;
pub(crate) mod server;
pub(crate) mod session;

pub use error::{ErrorCode, ProtocolError};
pub use frame::{
    FloatType, FrameReader, Header, MsgType, ReadOutcome, HEADER_LEN, MAGIC, MAX_NAME, MAX_PAYLOAD,
    MAX_TEXT, VERSION,
};
pub use load::{load, PolicySource, ServeConfig, Served};
pub use local::LocalPolicy;
pub use reply::{decode_reply, Chunk, ErrorReply, ModelInfo, Reply};
pub use request::{decode_request, Request};
#[cfg(unix)]
pub use server::serve_socket;
pub use server::{serve_stdio, serve_stream, StreamEnd};
pub use session::{ActInput, Next, ServedPolicy, Session};

#[cfg(test)]
mod tests;
