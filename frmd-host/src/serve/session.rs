//! Server-side session rules: message order, `executed` bookkeeping of the last commanded action
//! and its rate, finiteness checks, timing of the policy call.
use super::error::{bad_value, ErrorCode, ProtocolError, Result};
use super::fields::check_finite;
use super::frame::MsgType;
use super::reply::{Chunk, ErrorReply, ModelInfo, Reply};
use super::request::{decode_request, Request};
use std::time::Instant;

/// What a served policy is asked for one chunk (raw units; see [`Session`]).
pub struct ActInput<'a> {
    /// `obs_history` observations of `obs_dim` values, oldest first.
    pub obs: &'a [f64],
    /// The last commanded action (ProDMP `y0`).
    pub prev_action: &'a [f64],
    /// Its finite-difference rate, units per second (ProDMP `v0`).
    pub prev_rate: &'a [f64],
}

/// The model behind a server.
pub trait ServedPolicy {
    /// Starts an episode: reseed the noise stream.
    fn reset(&mut self, seed: u64);
    /// `horizon * action_dim` values, step-major; an `Err` is sent as `POLICY_FAILED`.
    fn act(&mut self, input: &ActInput<'_>) -> std::result::Result<Vec<f64>, String>;
}

/// The running episode: the last chunk and the two last commanded actions.
#[derive(Clone, Debug)]
struct Episode {
    chunk: Option<Vec<f64>>,
    prev: Vec<f64>,
    prev2: Vec<f64>,
}

/// Server-side session rules: order (HELLO first, RESET before ACT), `executed` bookkeeping of
/// the commanded actions, finiteness checks, timing, and "a rejected request changes nothing".
pub struct Session {
    info: ModelInfo,
    default_init: Vec<f64>,
    hello: bool,
    episode: Option<Episode>,
}

/// What the server loop does after a reply.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Next {
    Continue,
    Close,
}

impl Session {
    /// `default_init`: the action before an episode when RESET gives none (`action_dim` values).
    pub fn new(info: ModelInfo, default_init: Vec<f64>) -> std::result::Result<Session, String> {
        info.validate()?;
        if default_init.len() != usize::from(info.action_dim) {
            return Err(format!(
                "default initial action has {} values, action_dim is {}",
                default_init.len(),
                info.action_dim
            ));
        }
        Ok(Session {
            info,
            default_init,
            hello: false,
            episode: None,
        })
    }

    pub fn info(&self) -> &ModelInfo {
        &self.info
    }

    /// Answers one request frame whose header passed its checks.
    pub fn handle(
        &mut self,
        msg_type: MsgType,
        payload: &[u8],
        policy: &mut dyn ServedPolicy,
    ) -> (Reply, Next) {
        match self.try_handle(msg_type, payload, policy) {
            Ok(reply) => {
                let next = if reply == Reply::CloseOk {
                    Next::Close
                } else {
                    Next::Continue
                };
                (reply, next)
            }
            Err(e) => (
                Reply::Error(ErrorReply::from_error(&e, msg_type as u8)),
                Next::Continue,
            ),
        }
    }

    fn try_handle(
        &mut self,
        msg_type: MsgType,
        payload: &[u8],
        policy: &mut dyn ServedPolicy,
    ) -> Result<Reply> {
        let out_of_order = |text: &str| Err(ProtocolError::new(ErrorCode::OutOfOrder, text));
        match msg_type {
            MsgType::Hello | MsgType::Close => {}
            _ if !self.hello => return out_of_order(&format!("{} before HELLO", msg_type.name())),
            MsgType::Act if self.episode.is_none() => {
                return out_of_order("ACT before RESET: no episode has been started")
            }
            _ => {}
        }
        match decode_request(msg_type, payload, &self.info)? {
            Request::Hello => Ok(Reply::HelloOk(self.hello())),
            Request::Close => Ok(Reply::CloseOk),
            Request::Reset { seed, init_action } => {
                self.reset(seed, init_action, policy)?;
                Ok(Reply::ResetOk { seed })
            }
            Request::Act { executed, obs, .. } => {
                Ok(Reply::Chunk(self.act(executed, obs, policy)?))
            }
        }
    }

    /// HELLO: the session has started; the model's announcement.
    pub fn hello(&mut self) -> ModelInfo {
        self.hello = true;
        self.info.clone()
    }

    /// RESET: a new episode from `init_action` (empty: the default initial action) with the
    /// policy's noise reseeded by `seed`. Non-finite values are refused and change nothing.
    pub fn reset(
        &mut self,
        seed: u64,
        init_action: Vec<f64>,
        policy: &mut dyn ServedPolicy,
    ) -> Result<()> {
        check_finite("RESET init_action", &init_action, 0)?;
        let init = if init_action.is_empty() {
            self.default_init.clone()
        } else {
            init_action
        };
        policy.reset(seed);
        self.episode = Some(Episode {
            chunk: None,
            prev: init.clone(),
            prev2: init,
        });
        Ok(())
    }

    /// Whether the running episode has had a chunk (an ACT with `executed` > 0 needs one).
    pub fn has_chunk(&self) -> bool {
        self.episode.as_ref().is_some_and(|e| e.chunk.is_some())
    }

    /// ACT: the first `executed` actions of the last chunk were commanded; the next chunk for the
    /// `obs_history x obs_dim` observations `obs`. A rejected request changes nothing.
    pub fn act(
        &mut self,
        executed: u32,
        obs: Vec<f64>,
        policy: &mut dyn ServedPolicy,
    ) -> Result<Chunk> {
        let k = usize::from(self.info.action_dim);
        let Some(episode) = self.episode.as_ref() else {
            return Err(ProtocolError::new(
                ErrorCode::OutOfOrder,
                "ACT before RESET: no episode has been started",
            ));
        };
        let (mut prev, mut prev2) = (episode.prev.clone(), episode.prev2.clone());
        if executed > 0 {
            let chunk = episode.chunk.as_ref().ok_or_else(|| {
                bad_value(format!(
                    "ACT executed is {executed} but no chunk has been sent in this episode"
                ))
            })?;
            let available = chunk.len() / k.max(1);
            if executed as usize > available {
                return Err(bad_value(format!(
                    "ACT executed is {executed} but the previous chunk has {available} actions"
                )));
            }
            for action in chunk.chunks_exact(k).take(executed as usize) {
                prev2 = std::mem::replace(&mut prev, action.to_vec());
            }
        }
        check_finite("ACT observation", &obs, usize::from(self.info.obs_dim))?;
        let dt = self.info.dt;
        let rate: Vec<f64> = prev
            .iter()
            .zip(&prev2)
            .map(|(a, b)| if dt > 0.0 { (a - b) / dt } else { 0.0 })
            .collect();
        let started = Instant::now();
        let actions = policy
            .act(&ActInput {
                obs: &obs,
                prev_action: &prev,
                prev_rate: &rate,
            })
            .map_err(|e| ProtocolError::new(ErrorCode::PolicyFailed, format!("policy: {e}")))?;
        let policy_ns = u64::try_from(started.elapsed().as_nanos()).unwrap_or(u64::MAX);
        let expected = usize::from(self.info.horizon) * k;
        if actions.len() != expected {
            return Err(ProtocolError::new(
                ErrorCode::PolicyFailed,
                format!(
                    "policy returned {} values, expected horizon x action_dim = {expected}",
                    actions.len()
                ),
            ));
        }
        check_finite("policy action", &actions, k)
            .map_err(|e| ProtocolError::new(ErrorCode::PolicyFailed, e.text))?;
        self.episode = Some(Episode {
            chunk: Some(actions.clone()),
            prev,
            prev2,
        });
        Ok(Chunk {
            policy_ns,
            horizon: self.info.horizon,
            action_dim: self.info.action_dim,
            exec_steps: self.info.exec_steps,
            actions,
        })
    }
}
