//! QEMU running the `pil` image, and the frame exchange with it (`frmd_firmware_support::pil`).
//!
//! QEMU gets no display, monitor or serial port (nothing but the image writes to its standard
//! output, and nothing but the image reads its standard input) and `-icount shift=0` (one
//! instruction per virtual nanosecond, so the image's SysTick counts instructions). A reader
//! thread turns QEMU's standard output into frames, so every request waits at most
//! [`QemuLink::timeout`] and a dead or stuck QEMU is an error, never a hang.
use super::FirmwareImage;
use anyhow::{bail, Context};
use frmd_firmware_support::pil::{self, ErrorCode, MsgType, HEADER_LEN, TRAILER_LEN};
use std::io::{Read, Write};
use std::process::{Child, ChildStdin, Command, Stdio};
use std::sync::mpsc::{self, Receiver, RecvTimeoutError};
use std::sync::{Arc, Mutex};
use std::time::Duration;

/// Default wait for one reply (the first one includes QEMU's start and the SysTick calibration).
pub const DEFAULT_TIMEOUT: Duration = Duration::from_secs(60);

/// What the reader thread saw on QEMU's standard output.
enum Incoming {
    Frame {
        type_byte: u8,
        payload: Vec<u8>,
    },
    /// Bytes that are not a frame (e.g. a panic message of the image), up to the end of output.
    Text(String),
    Closed,
}

/// A reply frame.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct Reply {
    pub msg_type: MsgType,
    pub payload: Vec<u8>,
}

/// An `ERROR` reply, decoded.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct ErrorReply {
    pub code: Option<ErrorCode>,
    pub request_type: u8,
    pub text: String,
}

impl Reply {
    /// The `ERROR` payload, if this is one.
    pub fn as_error(&self) -> Option<ErrorReply> {
        if self.msg_type != MsgType::Error || self.payload.len() < 2 {
            return None;
        }
        Some(ErrorReply {
            code: ErrorCode::from_u8(self.payload[0]),
            request_type: self.payload[1],
            text: String::from_utf8_lossy(&self.payload[2..]).into_owned(),
        })
    }
}

/// A running QEMU with the `pil` image.
pub struct QemuLink {
    child: Child,
    stdin: Option<ChildStdin>,
    incoming: Receiver<Incoming>,
    stderr: Arc<Mutex<String>>,
    /// Longest wait for one reply.
    pub timeout: Duration,
    board: String,
}

impl QemuLink {
    /// Boots `image` under QEMU.
    pub fn start(image: &FirmwareImage) -> anyhow::Result<Self> {
        let mut child = Command::new(&image.qemu)
            .args(["-machine", &image.machine, "-cpu", &image.cpu])
            .args([
                "-nodefaults",
                "-display",
                "none",
                "-monitor",
                "none",
                "-serial",
                "null",
            ])
            .args([
                "-semihosting-config",
                "enable=on,target=native",
                "-icount",
                "shift=0",
            ])
            .arg("-kernel")
            .arg(&image.elf)
            .stdin(Stdio::piped())
            .stdout(Stdio::piped())
            .stderr(Stdio::piped())
            .spawn()
            .with_context(|| {
                format!(
                    "starting {} for {}",
                    image.qemu.display(),
                    image.elf.display()
                )
            })?;
        let stdout = child.stdout.take().context("QEMU standard output")?;
        let mut stderr_pipe = child.stderr.take().context("QEMU standard error")?;
        let (sender, incoming) = mpsc::channel();
        std::thread::spawn(move || read_frames(stdout, sender));
        let stderr = Arc::new(Mutex::new(String::new()));
        let sink = Arc::clone(&stderr);
        std::thread::spawn(move || {
            let mut text = String::new();
            let _ = stderr_pipe.read_to_string(&mut text);
            if let Ok(mut all) = sink.lock() {
                all.push_str(&text);
            }
        });
        Ok(QemuLink {
            stdin: child.stdin.take(),
            child,
            incoming,
            stderr,
            timeout: DEFAULT_TIMEOUT,
            board: image.board.clone(),
        })
    }

    /// Sends a request and waits for its reply (an `ERROR` reply is returned, not raised).
    pub fn request(&mut self, msg_type: MsgType, payload: &[u8]) -> anyhow::Result<Reply> {
        self.send_raw(&frame(msg_type as u8, payload)?)?;
        self.receive(msg_type.name())
    }

    /// Writes raw bytes (well-formed or not) to the image.
    pub fn send_raw(&mut self, bytes: &[u8]) -> anyhow::Result<()> {
        let stdin = self
            .stdin
            .as_mut()
            .context("the link to the firmware is closed")?;
        stdin
            .write_all(bytes)
            .and_then(|()| stdin.flush())
            .map_err(|e| self.failure(&format!("writing to QEMU: {e}")))
    }

    /// Waits for the next reply frame.
    pub fn receive(&mut self, what: &str) -> anyhow::Result<Reply> {
        match self.incoming.recv_timeout(self.timeout) {
            Ok(Incoming::Frame { type_byte, payload }) => match MsgType::from_u8(type_byte) {
                Some(msg_type) => Ok(Reply { msg_type, payload }),
                None => Err(self.failure(&format!(
                    "reply to {what} has unknown type 0x{type_byte:02x}"
                ))),
            },
            Ok(Incoming::Text(text)) => Err(self.failure(&format!(
                "the firmware wrote text instead of a reply to {what}: {text}"
            ))),
            Ok(Incoming::Closed) | Err(RecvTimeoutError::Disconnected) => {
                Err(self.failure(&format!("QEMU closed its output before replying to {what}")))
            }
            Err(RecvTimeoutError::Timeout) => {
                Err(self.failure(&format!("no reply to {what} within {:?}", self.timeout)))
            }
        }
    }

    /// Sends `EXIT`, closes the input and waits for QEMU to end.
    pub fn close(mut self) -> anyhow::Result<()> {
        let reply = self.request(MsgType::Exit, &[])?;
        if reply.msg_type != MsgType::ExitOk {
            bail!("EXIT answered with {}", reply.msg_type.name());
        }
        self.stdin = None;
        let status = self.child.wait().context("waiting for QEMU")?;
        if !status.success() {
            bail!("QEMU ({}) ended with {status}", self.board);
        }
        Ok(())
    }

    /// An error with what QEMU wrote to its standard error.
    fn failure(&mut self, what: &str) -> anyhow::Error {
        let status = self.child.try_wait().ok().flatten();
        let stderr = self
            .stderr
            .lock()
            .map(|s| s.trim().to_owned())
            .unwrap_or_default();
        let status = status.map_or_else(|| "running".to_owned(), |s| s.to_string());
        anyhow::anyhow!(
            "firmware on {}: {what} (QEMU {status}; stderr: {stderr:?})",
            self.board
        )
    }
}

impl Drop for QemuLink {
    fn drop(&mut self) {
        self.stdin = None;
        if let Ok(None) = self.child.try_wait() {
            let _ = self.child.kill();
        }
        let _ = self.child.wait();
    }
}

/// A whole frame of `type_byte` around `payload`.
pub fn frame(type_byte: u8, payload: &[u8]) -> anyhow::Result<Vec<u8>> {
    let mut out = vec![0u8; HEADER_LEN + payload.len() + TRAILER_LEN];
    let len = pil::encode(type_byte, payload, &mut out).with_context(|| {
        format!(
            "payload of {} bytes exceeds the frame limit of {}",
            payload.len(),
            pil::MAX_PAYLOAD
        )
    })?;
    out.truncate(len);
    Ok(out)
}

/// Reads frames from QEMU's standard output until it closes; anything that is not a frame with a
/// good CRC is passed on as text with the rest of the output.
fn read_frames(mut stdout: impl Read, sender: mpsc::Sender<Incoming>) {
    loop {
        let mut head = [0u8; HEADER_LEN];
        let got = read_full(&mut stdout, &mut head);
        if got == 0 {
            let _ = sender.send(Incoming::Closed);
            return;
        }
        let header = match (got, pil::parse_header(&head)) {
            (HEADER_LEN, Ok(header)) => header,
            _ => {
                let _ = sender.send(Incoming::Text(rest_as_text(&head[..got], &mut stdout)));
                return;
            }
        };
        let mut body = vec![0u8; header.payload_len + TRAILER_LEN];
        if read_full(&mut stdout, &mut body) < body.len() {
            let _ = sender.send(Incoming::Text(format!("truncated frame {head:02x?}")));
            return;
        }
        let crc = u32::from_le_bytes([
            body[header.payload_len],
            body[header.payload_len + 1],
            body[header.payload_len + 2],
            body[header.payload_len + 3],
        ]);
        body.truncate(header.payload_len);
        if crc != pil::frame_crc(&head, &body) {
            let _ = sender.send(Incoming::Text(format!(
                "reply with a bad CRC, header {head:02x?}"
            )));
            return;
        }
        if sender
            .send(Incoming::Frame {
                type_byte: header.type_byte,
                payload: body,
            })
            .is_err()
        {
            return;
        }
    }
}

/// `start` and the rest of the stream (at most 4 KiB) as lossy UTF-8.
fn rest_as_text(start: &[u8], stdout: &mut impl Read) -> String {
    let mut bytes = start.to_vec();
    let _ = stdout.take(4096).read_to_end(&mut bytes);
    String::from_utf8_lossy(&bytes).trim().to_owned()
}

/// Reads until `buf` is full or the stream ends; returns the bytes read.
fn read_full(stream: &mut impl Read, buf: &mut [u8]) -> usize {
    let mut done = 0;
    while done < buf.len() {
        match stream.read(&mut buf[done..]) {
            Ok(0) | Err(_) => break,
            Ok(n) => done += n,
        }
    }
    done
}
