//! The processor-in-the-loop server of the `pil` image: answers the frames of
//! `frmd_firmware_support::pil` (HELLO, RESET, ACT, EXIT) over semihosting, with a baked policy
//! and SysTick instruction counts around each chunk.
//!
//! Transport: semihosting `SYS_READ` / `SYS_WRITE` on the host's standard input and output (`:tt`
//! opened for reading and for writing). Under QEMU a blocked `SYS_READ` stops the guest (no
//! polling loop, no virtual time spent while the host simulates), and the same code runs on every
//! board (a UART would need one driver per board: CMSDK on the MPS2/MPS3 boards, nRF51 on the
//! microbit).

use frmd_core::policy::{Network, Noise, Policy, PolicyError};
use frmd_core::rng::Rng;
use frmd_firmware_support::pil::{
    self, encode, frame_crc, parse_header, ErrorCode, MsgType, CHUNK_PREFIX, HEADER_LEN, INFO_LEN,
    RESET_LEN, TRAILER_LEN,
};

use crate::memory::ImageSizes;
use crate::report::exit_failure;
use crate::timer::{calibrate, Calibration, TickCounter};

/// Longest text of an `ERROR` reply.
const MAX_TEXT: usize = 120;

/// The host's standard input and output through semihosting.
pub struct HostLink {
    input: usize,
    output: usize,
}

impl HostLink {
    /// Opens `:tt` for reading (standard input) and for writing (standard output).
    pub fn open() -> Option<Self> {
        let open = |mode: usize| {
            let name = b":tt\0";
            // SAFETY: SYS_OPEN reads `name.len() - 1` bytes of a live, NUL-terminated buffer.
            let fd = unsafe {
                cortex_m_semihosting::syscall!(OPEN, name.as_ptr(), mode, name.len() - 1)
            };
            (fd as isize >= 0).then_some(fd)
        };
        Some(Self {
            input: open(cortex_m_semihosting::nr::open::R)?,
            output: open(cortex_m_semihosting::nr::open::W_TRUNC)?,
        })
    }

    /// Fills `buf` from standard input; `false` at the end of the input (or a host error).
    pub fn read_exact(&mut self, buf: &mut [u8]) -> bool {
        let mut done = 0;
        while done < buf.len() {
            let rest = &mut buf[done..];
            // SAFETY: SYS_READ writes at most `rest.len()` bytes into the live buffer `rest`.
            let missing = unsafe {
                cortex_m_semihosting::syscall!(READ, self.input, rest.as_mut_ptr(), rest.len())
            };
            if missing >= rest.len() {
                return false; // nothing read: end of input (or an error, reported as more than asked)
            }
            done += rest.len() - missing;
        }
        true
    }

    /// Writes all of `bytes` to standard output (ends the run if the host refuses).
    pub fn write_all(&mut self, mut bytes: &[u8]) {
        while !bytes.is_empty() {
            // SAFETY: SYS_WRITE reads `bytes.len()` bytes of the live buffer `bytes`.
            let missing = unsafe {
                cortex_m_semihosting::syscall!(WRITE, self.output, bytes.as_ptr(), bytes.len())
            };
            if missing >= bytes.len() {
                exit_failure(&"pil: the host stopped taking output");
            }
            bytes = &bytes[bytes.len() - missing..];
        }
    }
}

/// A short text in a fixed buffer (for `ERROR` replies).
struct Text {
    bytes: [u8; MAX_TEXT],
    len: usize,
}

impl core::fmt::Write for Text {
    fn write_str(&mut self, s: &str) -> core::fmt::Result {
        for &byte in s.as_bytes() {
            if self.len < MAX_TEXT {
                self.bytes[self.len] = byte;
                self.len += 1;
            }
        }
        Ok(())
    }
}

/// The server state: link, policy, noise stream, counters and frame buffers.
/// `REQ` and `REP` are the payload capacities (at least the `ACT` and `CHUNK` sizes of the policy).
pub struct Server<
    'a,
    Net,
    const M: usize,
    const O: usize,
    const K: usize,
    const N: usize,
    const P: usize,
    const I: usize,
    const REQ: usize,
    const REP: usize,
> {
    link: HostLink,
    policy: Policy<'a, Net, M, O, K, N, P, I>,
    rng: Rng,
    ticks: TickCounter,
    calibration: Calibration,
    cpuid: u32,
    request: [u8; REQ],
    reply: [u8; REP],
    frame: [u8; REP],
}

/// What a handled request asks of the loop.
enum Next {
    Continue,
    Exit,
}

impl<
        'a,
        Net: Network,
        const M: usize,
        const O: usize,
        const K: usize,
        const N: usize,
        const P: usize,
        const I: usize,
        const REQ: usize,
        const REP: usize,
    > Server<'a, Net, M, O, K, N, P, I, REQ, REP>
{
    /// Takes the core peripherals, starts and calibrates SysTick and opens the link.
    pub fn new(policy: Policy<'a, Net, M, O, K, N, P, I>) -> Self {
        let Some(peripherals) = cortex_m::Peripherals::take() else {
            exit_failure(&"core peripherals already taken");
        };
        let cpuid = peripherals.CPUID.base.read();
        let ticks = TickCounter::start(peripherals.SYST);
        let calibration = calibrate(&ticks);
        if calibration.ticks == 0 {
            exit_failure(&"SysTick calibration failed (under QEMU, pass -icount shift=0)");
        }
        let Some(link) = HostLink::open() else {
            exit_failure(&"pil: semihosting cannot open :tt");
        };
        let capacity_ok = REQ >= pil::act_len(M, O, K)
            && REQ >= RESET_LEN
            && REP
                >= pil::chunk_len(N, K).max(INFO_LEN).max(2 + MAX_TEXT) + HEADER_LEN + TRAILER_LEN;
        if !capacity_ok {
            exit_failure(&"pil: frame buffers smaller than the policy's ACT and CHUNK payloads");
        }
        Self {
            link,
            policy,
            rng: Rng::new(0),
            ticks,
            calibration,
            cpuid,
            request: [0; REQ],
            reply: [0; REP],
            frame: [0; REP],
        }
    }

    /// Answers requests until `EXIT` or the end of the input, then ends QEMU with status 0.
    pub fn run(mut self) -> ! {
        let mut synced = true;
        loop {
            let mut head = [0u8; HEADER_LEN];
            let read = if synced {
                self.link.read_exact(&mut head)
            } else {
                head[..2].copy_from_slice(&pil::MAGIC);
                self.skip_to_magic() && self.link.read_exact(&mut head[2..])
            };
            if !read {
                break;
            }
            synced = true;
            let header = match parse_header(&head) {
                Ok(header) if header.payload_len <= REQ => header,
                Ok(header) => {
                    self.error(
                        ErrorCode::TooLong,
                        head[2],
                        format_args!(
                            "payload of {} bytes, this image takes at most {REQ}",
                            header.payload_len
                        ),
                    );
                    synced = false;
                    continue;
                }
                Err(code) => {
                    self.error(code, head[2], format_args!("header {head:02x?}"));
                    synced = false;
                    continue;
                }
            };
            let mut crc = [0u8; TRAILER_LEN];
            let len = header.payload_len;
            if !self.link.read_exact(&mut self.request[..len]) || !self.link.read_exact(&mut crc) {
                break;
            }
            let expected = frame_crc(&head, &self.request[..len]);
            if u32::from_le_bytes(crc) != expected {
                self.error(
                    ErrorCode::BadCrc,
                    head[2],
                    format_args!(
                        "CRC {:08x}, computed {expected:08x}",
                        u32::from_le_bytes(crc)
                    ),
                );
                continue;
            }
            if let Next::Exit = self.handle(header.type_byte, len) {
                break;
            }
        }
        crate::report::exit_success()
    }

    /// Drops input up to and including the next magic (`false` at the end of the input).
    fn skip_to_magic(&mut self) -> bool {
        let mut last = 0u8;
        loop {
            let mut byte = [0u8; 1];
            if !self.link.read_exact(&mut byte) {
                return false;
            }
            if [last, byte[0]] == pil::MAGIC {
                return true;
            }
            last = byte[0];
        }
    }

    /// Answers one request whose frame passed its checks.
    fn handle(&mut self, type_byte: u8, len: usize) -> Next {
        let expected = match MsgType::from_u8(type_byte) {
            Some(MsgType::Hello | MsgType::Exit) => 0,
            Some(MsgType::Reset) => RESET_LEN,
            Some(MsgType::Act) => pil::act_len(M, O, K),
            _ => {
                self.error(
                    ErrorCode::UnknownType,
                    type_byte,
                    format_args!("type 0x{type_byte:02x} is not a request"),
                );
                return Next::Continue;
            }
        };
        if len != expected {
            self.error(
                ErrorCode::BadLength,
                type_byte,
                format_args!("payload of {len} bytes, expected {expected}"),
            );
            return Next::Continue;
        }
        match MsgType::from_u8(type_byte) {
            Some(MsgType::Hello) => self.info(),
            Some(MsgType::Reset) => {
                let mut seed = [0u8; 8];
                seed.copy_from_slice(&self.request[..RESET_LEN]);
                self.rng = Rng::new(u64::from_le_bytes(seed));
                self.send(MsgType::ResetOk as u8, 0);
            }
            Some(MsgType::Exit) => {
                self.send(MsgType::ExitOk as u8, 0);
                return Next::Exit;
            }
            _ => match self.act() {
                Ok(()) => self.send(MsgType::Chunk as u8, pil::chunk_len(N, K)),
                Err(error) => {
                    self.error(ErrorCode::PolicyFailed, type_byte, format_args!("{error}"))
                }
            },
        }
        Next::Continue
    }

    /// `INFO`: sizes, CPUID, flash, static RAM and the SysTick calibration.
    fn info(&mut self) {
        let sizes = ImageSizes::of_this_image();
        let dims = [M as u16, O as u16, K as u16, N as u16];
        for (slot, value) in self.reply.chunks_exact_mut(2).zip(dims) {
            slot.copy_from_slice(&value.to_le_bytes());
        }
        let words = [
            self.cpuid,
            sizes.flash as u32,
            sizes.ram_static as u32,
            self.calibration.milli_instructions_per_tick() as u32,
        ];
        for (slot, value) in self.reply[8..INFO_LEN].chunks_exact_mut(4).zip(words) {
            slot.copy_from_slice(&value.to_le_bytes());
        }
        self.send(MsgType::Info as u8, INFO_LEN);
    }

    /// One chunk from the `ACT` payload into the reply buffer.
    fn act(&mut self) -> Result<(), PolicyError> {
        let request_start = self.ticks.now();
        let mut values = [0f32; K];
        let (obs_bytes, rest) = self.request.split_at(4 * M * O);
        pil::read_f32s(&rest[..4 * K], &mut values);
        let y0 = values;
        pil::read_f32s(&rest[4 * K..8 * K], &mut values);
        let v0 = values;
        self.policy.reset(&y0)?;
        for row in obs_bytes.chunks_exact(4 * O) {
            let mut observation = [0f32; O];
            pil::read_f32s(row, &mut observation);
            self.policy.observe(&observation)?;
        }
        self.policy.set_previous_action(&y0, &v0)?;
        let act_start = self.ticks.now();
        let chunk = self.policy.act(Noise::Rng(&mut self.rng))?;
        let act_end = self.ticks.now();
        pil::write_f32s(
            chunk.positions.as_flattened(),
            &mut self.reply[CHUNK_PREFIX..pil::chunk_len(N, K)],
        );
        let request_end = self.ticks.now();
        let act = self
            .calibration
            .instructions(u64::from(TickCounter::elapsed(act_start, act_end)));
        let request = self
            .calibration
            .instructions(u64::from(TickCounter::elapsed(request_start, request_end)));
        self.reply[..4].copy_from_slice(&(act as u32).to_le_bytes());
        self.reply[4..8].copy_from_slice(&(request as u32).to_le_bytes());
        Ok(())
    }

    /// `ERROR` with `code`, the request's type byte and a text.
    fn error(&mut self, code: ErrorCode, type_byte: u8, text: core::fmt::Arguments<'_>) {
        let mut message = Text {
            bytes: [0; MAX_TEXT],
            len: 0,
        };
        let _ = core::fmt::write(&mut message, text);
        self.reply[0] = code as u8;
        self.reply[1] = type_byte;
        self.reply[2..2 + message.len].copy_from_slice(&message.bytes[..message.len]);
        self.send(MsgType::Error as u8, 2 + message.len);
    }

    /// Frames the first `len` bytes of the reply buffer and writes them out.
    fn send(&mut self, type_byte: u8, len: usize) {
        match encode(type_byte, &self.reply[..len], &mut self.frame) {
            Some(total) => self.link.write_all(&self.frame[..total]),
            None => exit_failure(&"pil: reply frame larger than its buffer"),
        }
    }
}
