//! The server loop over one byte stream (stdin/stdout, a socket connection, in-memory pipes).
use super::frame::{FrameReader, ReadOutcome};
use super::reply::{ErrorReply, Reply};
use super::session::{Next, ServedPolicy, Session};
use std::io::{self, Read, Write};

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
