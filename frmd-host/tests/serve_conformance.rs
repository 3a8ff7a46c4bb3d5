//! `frmd serve` (the binary) against the answers docs/serve-protocol.md gives beyond its message
//! tables (sections 5 and 9): header errors before the payload, payload errors after it; no reply
//! after CLOSE; the exit statuses 0, 1 and 2; a stale socket file replaced, any other file
//! refused; a second socket client queued until the first leaves; `dt` an f32 widened to f64;
//! `--float f64` values finite in f64 but not in f32 fail as POLICY_FAILED.
#![cfg(unix)]
mod cli_support;

use cli_support::{fixture, rejects, scratch};
use frmd_host::serve::{
    decode_reply, ErrorCode, FloatType, FrameReader, Header, MsgType, ReadOutcome, Reply, Request,
};
use std::io::{Read, Write};
use std::os::unix::net::{UnixListener, UnixStream};
use std::path::Path;
use std::process::{Child, ChildStdin, Command, ExitStatus, Stdio};
use std::sync::mpsc::{channel, Receiver, RecvTimeoutError};
use std::time::{Duration, Instant};

/// How long a reply may take on a loaded machine before the test gives up.
const PATIENCE: Duration = Duration::from_secs(60);
/// How long "no reply yet" is waited for.
const QUIET: Duration = Duration::from_millis(300);

fn serve_command(args: &[&str]) -> Command {
    let mut command = Command::new(env!("CARGO_BIN_EXE_frmd"));
    command
        .arg("serve")
        .args(args)
        .current_dir(fixture())
        .env("RAYON_NUM_THREADS", "1")
        .stderr(Stdio::null());
    command
}

/// A server on stdio whose replies a thread reads as they come.
struct Stdio1 {
    child: Child,
    stdin: Option<ChildStdin>,
    replies: Receiver<Option<Reply>>,
    float_type: FloatType,
}

impl Stdio1 {
    fn start(args: &[&str], float_type: FloatType) -> Self {
        Self::spawn(&mut serve_command(args), float_type)
    }

    fn spawn(command: &mut Command, float_type: FloatType) -> Self {
        let mut child = command
            .stdin(Stdio::piped())
            .stdout(Stdio::piped())
            .spawn()
            .expect("frmd serve starts");
        let stdin = child.stdin.take();
        let stdout = child.stdout.take().unwrap();
        let (send, replies) = channel();
        std::thread::spawn(move || {
            let mut reader = FrameReader::new(stdout, false);
            loop {
                let reply = match reader.next_frame() {
                    Ok(ReadOutcome::Frame { msg_type, payload }) => {
                        decode_reply(msg_type, &payload, Some(float_type)).ok()
                    }
                    _ => None,
                };
                let done = reply.is_none();
                if send.send(reply).is_err() || done {
                    return;
                }
            }
        });
        Stdio1 {
            child,
            stdin,
            replies,
            float_type,
        }
    }

    fn send(&mut self, bytes: &[u8]) {
        let stdin = self.stdin.as_mut().unwrap();
        stdin.write_all(bytes).unwrap();
        stdin.flush().unwrap();
    }

    fn request(&mut self, request: &Request) -> Reply {
        self.send(&request.encode(self.float_type));
        self.reply()
    }

    fn reply(&self) -> Reply {
        match self.replies.recv_timeout(PATIENCE) {
            Ok(Some(reply)) => reply,
            other => panic!("no reply: {other:?}"),
        }
    }

    fn nothing_yet(&self) -> bool {
        matches!(
            self.replies.recv_timeout(QUIET),
            Err(RecvTimeoutError::Timeout)
        )
    }

    fn close_input_and_wait(mut self) -> ExitStatus {
        drop(self.stdin.take());
        self.child.wait().unwrap()
    }
}

fn error_of(reply: &Reply) -> (Option<ErrorCode>, u8) {
    match reply {
        Reply::Error(e) => (e.kind(), e.request_type),
        other => panic!("expected ERROR, got {other:?}"),
    }
}

fn header(payload_len: u32, version: u8, msg_type: u8, reserved: u16) -> Vec<u8> {
    Header {
        payload_len,
        version,
        msg_type,
        reserved,
    }
    .encode()
    .to_vec()
}

fn reset(seed: u64) -> Request {
    Request::Reset {
        seed,
        init_action: vec![],
    }
}

/// The fixture's student observes 2 x 6 values.
fn act(executed: u32, value: f64) -> Request {
    Request::Act {
        executed,
        obs_count: 2,
        obs: vec![value; 12],
    }
}

#[test]
fn header_errors_come_before_the_payload_and_payload_errors_after_it() {
    let mut server = Stdio1::start(&["--blob", "s.blob"], FloatType::F32);
    for (head, code) in [
        (header(8, 2, 0x01, 0), ErrorCode::UnsupportedVersion),
        (header(8, 1, 0x42, 0), ErrorCode::UnknownType),
        (header(8, 1, 0x81, 0), ErrorCode::UnknownType),
        (header(8, 1, 0x01, 1), ErrorCode::BadValue),
    ] {
        server.send(&head);
        // Answered while the 8 announced payload bytes have not been sent.
        assert_eq!(error_of(&server.reply()), (Some(code), head[5]));
        server.send(&[0xAB; 8]);
    }
    // The rejected payloads were skipped: the stream is in step.
    assert!(matches!(server.request(&Request::Hello), Reply::HelloOk(_)));
    // A payload error (ACT before RESET) waits for the whole payload.
    let frame = act(0, 0.5).encode(FloatType::F32);
    server.send(&frame[..20]);
    assert!(server.nothing_yet(), "answered before the payload arrived");
    server.send(&frame[20..]);
    assert_eq!(
        error_of(&server.reply()),
        (Some(ErrorCode::OutOfOrder), MsgType::Act as u8)
    );
    assert_eq!(server.request(&Request::Close), Reply::CloseOk);
    assert_eq!(server.close_input_and_wait().code(), Some(0));
}

/// Runs `frmd serve --blob s.blob` on `input` and returns (exit code, stdout).
fn serve_input(input: &[u8]) -> (Option<i32>, Vec<u8>) {
    let mut child = serve_command(&["--blob", "s.blob"])
        .stdin(Stdio::piped())
        .stdout(Stdio::piped())
        .spawn()
        .unwrap();
    // The server may exit before reading everything (after CLOSE): a failed write is fine.
    let _ = child.stdin.take().unwrap().write_all(input);
    let out = child.wait_with_output().unwrap();
    (out.status.code(), out.stdout)
}

fn frames(list: &[Request]) -> Vec<u8> {
    list.iter().flat_map(|r| r.encode(FloatType::F32)).collect()
}

fn replies(bytes: &[u8]) -> Vec<Reply> {
    let mut reader = FrameReader::new(bytes, false);
    let mut out = Vec::new();
    while let ReadOutcome::Frame { msg_type, payload } = reader.next_frame().unwrap() {
        out.push(decode_reply(msg_type, &payload, Some(FloatType::F32)).unwrap());
    }
    out
}

#[test]
fn no_reply_after_close_and_the_stdio_exit_statuses() {
    // CLOSE: its CLOSE_OK is the last byte written, whatever follows; status 0.
    let (code, out) = serve_input(&frames(&[Request::Hello, Request::Close, Request::Hello]));
    let got = replies(&out);
    assert_eq!(code, Some(0));
    assert_eq!(got.len(), 2, "{got:?}");
    assert_eq!(got[1], Reply::CloseOk);
    // End of input at a frame boundary: status 0, no reply to it.
    let (code, out) = serve_input(&frames(&[Request::Hello]));
    assert_eq!((code, replies(&out).len()), (Some(0), 1));
    // End of input inside a payload: TRUNCATED (fatal, the frame's type), status 1.
    let hello = frames(&[Request::Hello]);
    let (code, out) = serve_input(&hello[..10]);
    assert_eq!(code, Some(1));
    match &replies(&out)[..] {
        [Reply::Error(e)] => assert_eq!(
            (e.kind(), e.fatal, e.request_type),
            (Some(ErrorCode::Truncated), true, MsgType::Hello as u8)
        ),
        other => panic!("{other:?}"),
    }
    // A reply that cannot be written (the client closed its read end): status 1.
    let mut child = serve_command(&["--blob", "s.blob"])
        .stdin(Stdio::piped())
        .stdout(Stdio::piped())
        .spawn()
        .unwrap();
    drop(child.stdout.take());
    let _ = child.stdin.take().unwrap().write_all(&hello);
    assert_eq!(child.wait().unwrap().code(), Some(1));
}

#[test]
fn a_server_that_cannot_start_exits_with_status_2() {
    let dir = scratch("serve-start");
    std::fs::write(dir.join("not-a-socket"), "keep me").unwrap();
    std::fs::create_dir_all(dir.join("bad-export")).unwrap();
    std::fs::copy(
        fixture().join("baked/policy.blob"),
        dir.join("bad-export/policy.blob"),
    )
    .unwrap();
    std::fs::write(dir.join("bad-export/export.json"), "{ not json").unwrap();
    let blob = fixture().join("s.blob");
    let blob = blob.to_str().unwrap();
    // The policy loads (a line on stderr says so) before the socket path is refused.
    let out = cli_support::frmd(&dir, &["serve", "--blob", blob, "--socket", "not-a-socket"]);
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert_eq!(out.status.code(), Some(2), "{stderr}");
    assert!(
        stderr.contains("error: not-a-socket: exists and is not a socket"),
        "{stderr}"
    );
    assert_eq!(
        std::fs::read_to_string(dir.join("not-a-socket")).unwrap(),
        "keep me"
    );
    rejects(
        &dir,
        &["serve", "--blob", "missing.blob"],
        &["missing.blob"],
    );
    rejects(&dir, &["serve", "--baked", "bad-export"], &["export.json"]);
    rejects(
        &dir,
        &["serve", "--blob", blob, "--exec-steps", "0"],
        &["exec-steps"],
    );
}

fn connect(path: &Path) -> UnixStream {
    let started = Instant::now();
    loop {
        match UnixStream::connect(path) {
            Ok(stream) => return stream,
            Err(e) if started.elapsed() > PATIENCE => panic!("cannot connect: {e}"),
            Err(_) => std::thread::sleep(Duration::from_millis(50)),
        }
    }
}

/// One reply from a socket, or None at the end of the connection or after `wait`.
fn socket_reply(stream: &mut UnixStream, wait: Duration) -> Option<Reply> {
    stream.set_read_timeout(Some(wait)).unwrap();
    let mut head = [0u8; 8];
    let mut got = 0;
    while got < head.len() {
        match stream.read(&mut head[got..]) {
            Ok(0) | Err(_) => return None,
            Ok(n) => got += n,
        }
    }
    let header = Header::decode(&head);
    let mut payload = vec![0; header.payload_len as usize];
    stream.set_read_timeout(Some(PATIENCE)).unwrap();
    stream.read_exact(&mut payload).unwrap();
    let msg_type = MsgType::from_u8(header.msg_type).unwrap();
    Some(decode_reply(msg_type, &payload, Some(FloatType::F32)).unwrap())
}

#[test]
fn socket_files_and_a_queued_second_client() {
    let dir = scratch("serve-socket");
    let path = dir.join("policy.sock");
    // A stale socket file (its listener is gone) is replaced.
    drop(UnixListener::bind(&path).unwrap());
    assert!(path.exists());
    let blob = fixture().join("s.blob");
    let mut server = serve_command(&[
        "--blob",
        blob.to_str().unwrap(),
        "--socket",
        path.to_str().unwrap(),
        "--connections",
        "2",
    ])
    .spawn()
    .unwrap();
    let mut first = connect(&path);
    first
        .write_all(&Request::Hello.encode(FloatType::F32))
        .unwrap();
    assert!(matches!(
        socket_reply(&mut first, PATIENCE),
        Some(Reply::HelloOk(_))
    ));
    // The second client's connect succeeds, but it is not served while the first is.
    let mut second = UnixStream::connect(&path).expect("the second connect is queued");
    second
        .write_all(&Request::Hello.encode(FloatType::F32))
        .unwrap();
    assert_eq!(socket_reply(&mut second, QUIET), None);
    // After CLOSE the first connection gets nothing more: it is closed.
    let after_close = frames(&[Request::Close, Request::Hello]);
    first.write_all(&after_close).unwrap();
    assert_eq!(socket_reply(&mut first, PATIENCE), Some(Reply::CloseOk));
    assert_eq!(socket_reply(&mut first, PATIENCE), None);
    // Then the queued client is served, in a fresh session.
    assert!(matches!(
        socket_reply(&mut second, PATIENCE),
        Some(Reply::HelloOk(_))
    ));
    second.write_all(&frames(&[Request::Close])).unwrap();
    assert_eq!(socket_reply(&mut second, PATIENCE), Some(Reply::CloseOk));
    assert_eq!(server.wait().unwrap().code(), Some(0));
    assert!(!path.exists(), "the socket file is removed at exit");
}

#[test]
fn dt_is_an_f32_widened_and_f64_values_beyond_f32_are_policy_failures() {
    for policy in [["--ckpt", "s"], ["--baked", "baked"]] {
        let mut server =
            Stdio1::start(&[&policy[..], &["--float", "f64"]].concat(), FloatType::F64);
        let Reply::HelloOk(info) = server.request(&Request::Hello) else {
            panic!("no HELLO_OK")
        };
        // The checkpoint stores the control period as f32; HELLO_OK carries it widened, exactly.
        assert!(info.dt > 0.0, "{policy:?}");
        assert_eq!(f64::from(info.dt as f32), info.dt);
        assert_ne!(info.dt, 0.1, "0.1 as f32, widened, is not the f64 0.1");
        assert_eq!(server.request(&reset(1)), Reply::ResetOk { seed: 1 });
        // Finite in f64, infinite as f32: passes the NON_FINITE check, fails in the policy.
        assert_eq!(
            error_of(&server.request(&act(0, 1e300))).0,
            Some(ErrorCode::PolicyFailed),
            "{policy:?}"
        );
        assert_eq!(
            error_of(&server.request(&act(0, f64::INFINITY))).0,
            Some(ErrorCode::NonFinite)
        );
        assert!(matches!(server.request(&act(0, 0.5)), Reply::Chunk(_)));
        assert_eq!(server.request(&Request::Close), Reply::CloseOk);
        assert_eq!(server.close_input_and_wait().code(), Some(0));
    }
}

#[test]
fn an_export_finds_its_checkpoint_from_any_working_directory() {
    // The fixture ran `frmd export --ckpt s --out baked` in its directory: export.json names the
    // checkpoint relative to baked/, so a server started elsewhere still announces its dt.
    let info: serde_json::Value = serde_json::from_str(
        &std::fs::read_to_string(fixture().join("baked/export.json")).unwrap(),
    )
    .unwrap();
    assert_eq!(info["checkpoint"], "../s");
    let baked = fixture().join("baked");
    let mut command = serve_command(&["--baked", baked.to_str().unwrap()]);
    let mut server = Stdio1::spawn(
        command.current_dir(scratch("serve-elsewhere")),
        FloatType::F32,
    );
    let Reply::HelloOk(hello) = server.request(&Request::Hello) else {
        panic!("no HELLO_OK")
    };
    assert!(hello.dt > 0.0, "{hello:?}");
    assert_eq!(server.request(&Request::Close), Reply::CloseOk);
    assert_eq!(server.close_input_and_wait().code(), Some(0));
}
