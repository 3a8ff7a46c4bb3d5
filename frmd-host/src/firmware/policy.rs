//! The `pil` image as a closed-loop policy: every chunk is computed by the emulated MCU.
//!
//! The exchange mirrors the host int8 policy ([`crate::policy::int8::Int8Policy`]) step for step:
//! `reset(seed)` reseeds the image's noise stream (`RESET`), every `act` sends the observation
//! history, the last commanded action and its rate (`ACT`), and the image runs frmd-core's
//! `Policy::reset`, `observe`, `set_previous_action` and `act` on them, so both give the same bits.
use super::link::{QemuLink, Reply};
use super::FirmwareImage;
use crate::tasks::{Policy, PolicyInput};
use anyhow::{bail, Context};
use frmd_firmware_support::cpuid::core_name;
use frmd_firmware_support::pil::{self, MsgType, CHUNK_PREFIX, INFO_LEN};
use serde::Serialize;

/// What the image reports in `INFO`.
#[derive(Clone, Debug, Serialize)]
pub struct FirmwareInfo {
    pub board: String,
    pub core: &'static str,
    pub history: usize,
    pub obs_dim: usize,
    pub action_dim: usize,
    pub horizon: usize,
    /// Flash image of the `pil` image (policy, server and runtime), bytes.
    pub flash_bytes: u32,
    /// Static RAM of the image, bytes (the stack comes on top).
    pub ram_static_bytes: u32,
    /// Instructions per SysTick tick as the image calibrated it (40 under QEMU's mps2 boards).
    pub instructions_per_tick: f64,
}

/// Instructions the image counted, over the chunks so far.
#[derive(Clone, Debug, Default, Serialize)]
pub struct InstructionStats {
    pub chunks: usize,
    /// `Policy::act` alone (the bench images' `instructions:`).
    pub act_min: u64,
    pub act_max: u64,
    pub act_mean: f64,
    /// The whole request: policy reset, observations, previous action and act.
    pub request_min: u64,
    pub request_max: u64,
    pub request_mean: f64,
}

fn summary(values: &[u32]) -> (u64, u64, f64) {
    let min = values.iter().copied().min().unwrap_or(0);
    let max = values.iter().copied().max().unwrap_or(0);
    let mean = values.iter().map(|&v| f64::from(v)).sum::<f64>() / values.len().max(1) as f64;
    (u64::from(min), u64::from(max), mean)
}

/// A policy answered by the `pil` image under QEMU.
pub struct FirmwarePolicy {
    link: QemuLink,
    info: FirmwareInfo,
    label: String,
    act_instructions: Vec<u32>,
    request_instructions: Vec<u32>,
    /// A failed `RESET` (the evaluator's `reset` cannot return it), raised by the next `act`.
    pending: Option<anyhow::Error>,
}

impl FirmwarePolicy {
    /// Boots `image` and asks for its sizes (`HELLO`).
    pub fn start(image: &FirmwareImage) -> anyhow::Result<Self> {
        let mut link = QemuLink::start(image)?;
        let reply = expect(link.request(MsgType::Hello, &[])?, MsgType::Info, "HELLO")?;
        if reply.len() != INFO_LEN {
            bail!(
                "INFO payload has {} bytes, expected {INFO_LEN}",
                reply.len()
            );
        }
        let half = |i: usize| usize::from(u16::from_le_bytes([reply[2 * i], reply[2 * i + 1]]));
        let word = |i: usize| {
            u32::from_le_bytes([
                reply[8 + 4 * i],
                reply[9 + 4 * i],
                reply[10 + 4 * i],
                reply[11 + 4 * i],
            ])
        };
        let info = FirmwareInfo {
            board: image.board.clone(),
            core: core_name(word(0)),
            history: half(0),
            obs_dim: half(1),
            action_dim: half(2),
            horizon: half(3),
            flash_bytes: word(1),
            ram_static_bytes: word(2),
            instructions_per_tick: f64::from(word(3)) / 1000.0,
        };
        let label = format!("firmware-{}", image.board);
        Ok(FirmwarePolicy {
            link,
            info,
            label,
            act_instructions: Vec::new(),
            request_instructions: Vec::new(),
            pending: None,
        })
    }

    pub fn info(&self) -> &FirmwareInfo {
        &self.info
    }

    /// Observation history the image's policy needs.
    pub fn history(&self) -> usize {
        self.info.history
    }

    /// Instruction counts of the chunks so far.
    pub fn stats(&self) -> InstructionStats {
        let (act_min, act_max, act_mean) = summary(&self.act_instructions);
        let (request_min, request_max, request_mean) = summary(&self.request_instructions);
        InstructionStats {
            chunks: self.act_instructions.len(),
            act_min,
            act_max,
            act_mean,
            request_min,
            request_max,
            request_mean,
        }
    }

    /// Reseeds the image's noise stream.
    pub fn reseed(&mut self, seed: u64) -> anyhow::Result<()> {
        expect(
            self.link.request(MsgType::Reset, &seed.to_le_bytes())?,
            MsgType::ResetOk,
            "RESET",
        )
        .map(drop)
    }

    /// One chunk: `obs` (`history x obs_dim`, oldest first), the last commanded action and its
    /// rate in; the positions (`horizon x action_dim`, step-major) out.
    /// A `RESET` that failed before (see [`Policy::reset`]) is raised here.
    pub fn chunk(
        &mut self,
        obs: &[f32],
        prev_action: &[f32],
        prev_rate: &[f32],
    ) -> anyhow::Result<Vec<f32>> {
        if let Some(error) = self.pending.take() {
            return Err(error.context("RESET of the firmware policy"));
        }
        let info = &self.info;
        let k = info.action_dim;
        if obs.len() != info.history * info.obs_dim
            || prev_action.len() != k
            || prev_rate.len() != k
        {
            bail!(
                "firmware policy expects {} x {} observation values and {k}-value action and rate, got {}, {} and {}",
                info.history,
                info.obs_dim,
                obs.len(),
                prev_action.len(),
                prev_rate.len()
            );
        }
        let mut payload = vec![0u8; pil::act_len(info.history, info.obs_dim, k)];
        let values = obs
            .iter()
            .chain(prev_action)
            .chain(prev_rate)
            .copied()
            .collect::<Vec<f32>>();
        pil::write_f32s(&values, &mut payload);
        let reply = expect(
            self.link.request(MsgType::Act, &payload)?,
            MsgType::Chunk,
            "ACT",
        )?;
        let expected = pil::chunk_len(info.horizon, k);
        if reply.len() != expected {
            bail!(
                "CHUNK payload has {} bytes, expected {expected} (horizon {} x action {k})",
                reply.len(),
                info.horizon
            );
        }
        self.act_instructions
            .push(u32::from_le_bytes([reply[0], reply[1], reply[2], reply[3]]));
        self.request_instructions
            .push(u32::from_le_bytes([reply[4], reply[5], reply[6], reply[7]]));
        let mut positions = vec![0f32; info.horizon * k];
        pil::read_f32s(&reply[CHUNK_PREFIX..], &mut positions);
        Ok(positions)
    }

    /// The link, for raw exchanges (tests of the frame checks).
    pub fn link(&mut self) -> &mut QemuLink {
        &mut self.link
    }

    /// Ends the image (`EXIT`) and QEMU.
    pub fn close(self) -> anyhow::Result<()> {
        self.link.close()
    }
}

/// The payload of `reply` if it has type `want`; an `ERROR` reply becomes an error naming it.
fn expect(reply: Reply, want: MsgType, request: &str) -> anyhow::Result<Vec<u8>> {
    if let Some(error) = reply.as_error() {
        let code = error.code.map_or("unknown error code", |c| c.name());
        bail!("firmware rejected {request}: {code}: {}", error.text);
    }
    if reply.msg_type != want {
        bail!(
            "firmware answered {request} with {}, expected {}",
            reply.msg_type.name(),
            want.name()
        );
    }
    Ok(reply.payload)
}

impl Policy for FirmwarePolicy {
    fn name(&self) -> String {
        self.label.clone()
    }

    fn reset(&mut self, seed: u64) {
        if let Err(error) = self.reseed(seed) {
            self.pending = Some(error);
        }
    }

    fn act(&mut self, input: &PolicyInput<'_>) -> anyhow::Result<Vec<Vec<f32>>> {
        if input.obs_history.len() != self.info.history {
            bail!(
                "firmware policy expects an observation history of {}, got {}",
                self.info.history,
                input.obs_history.len()
            );
        }
        let obs: Vec<f32> = input.obs_history.concat();
        let positions = self
            .chunk(&obs, input.prev_action, input.prev_rate)
            .context("firmware chunk")?;
        Ok(positions
            .chunks(self.info.action_dim.max(1))
            .map(<[f32]>::to_vec)
            .collect())
    }
}
