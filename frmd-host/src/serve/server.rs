//! The server loop over one byte stream (stdin/stdout, a socket connection, in-memory pipes).
use super::frame::{FrameReader, ReadOutcome};
use super::load::Served;
use super::reply::{ErrorReply, Reply};
use super::session::{Next, ServedPolicy, Session};
use anyhow::Context;
use std::io::{self, Read, Write};
use std::path::Path;

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
            ReadOutcome::Truncated {
                error,
                request_type,
            } => {
                let reply = Reply::Error(ErrorReply::from_error(&error, request_type));
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

/// Serves one session on stdin/stdout (the default transport). Diagnostics go to stderr only.
pub fn serve_stdio(served: &mut Served) -> anyhow::Result<StreamEnd> {
    let mut session = served.session()?;
    let stdin = io::stdin().lock();
    let stdout = io::BufWriter::new(io::stdout().lock());
    // An error here is a failed write of a reply (the client closed its end).
    serve_stream(stdin, stdout, &mut session, &mut served.policy)
        .context("writing a reply to stdout")
}

/// Serves clients on a Unix socket at `path`, one connection at a time, each with a fresh session
/// (the policy's noise stream is reseeded by RESET), until `max_connections` have been served
/// (`None`: forever). A stale socket file at `path` is replaced; any other file is an error.
#[cfg(unix)]
pub fn serve_socket(
    served: &mut Served,
    path: &Path,
    max_connections: Option<usize>,
) -> anyhow::Result<()> {
    use std::os::unix::fs::FileTypeExt;
    use std::os::unix::net::UnixListener;
    if let Ok(meta) = std::fs::symlink_metadata(path) {
        if !meta.file_type().is_socket() {
            anyhow::bail!(
                "{}: exists and is not a socket; refusing to replace it",
                path.display()
            );
        }
        std::fs::remove_file(path)
            .with_context(|| format!("removing the stale socket {}", path.display()))?;
    }
    let listener = UnixListener::bind(path)
        .with_context(|| format!("binding the Unix socket {}", path.display()))?;
    eprintln!("frmd serve: listening on {}", path.display());
    let mut served_count = 0;
    for stream in listener.incoming() {
        let stream = match stream {
            Ok(s) => s,
            Err(e) => {
                eprintln!("frmd serve: accept failed: {e}");
                continue;
            }
        };
        let mut session = served.session()?;
        let reader = stream
            .try_clone()
            .with_context(|| format!("{}: cloning the connection", path.display()))?;
        match serve_stream(
            io::BufReader::new(reader),
            io::BufWriter::new(&stream),
            &mut session,
            &mut served.policy,
        ) {
            Ok(end) => eprintln!("frmd serve: connection ended ({end:?})"),
            Err(e) => eprintln!("frmd serve: connection lost: {e}"),
        }
        served_count += 1;
        if max_connections.is_some_and(|m| served_count >= m) {
            break;
        }
    }
    std::fs::remove_file(path).ok();
    Ok(())
}
