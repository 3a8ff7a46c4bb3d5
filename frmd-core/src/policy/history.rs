//! Fixed-capacity observation history: the last `m` normalized observations, oldest first.

/// Ring buffer of up to `M` observations of up to `O` values each (normalized units), holding
/// `history` observations of `obs_dim` values (set by [`ObsHistory::with_sizes`]; `M`, `O` by
/// default).
///
/// At episode start ([`ObsHistory::clear`]) it is empty; the first [`ObsHistory::push`] fills
/// every slot with that observation (padding by repeating the first observation, as the training
/// windows do). Afterwards each push overwrites the oldest slot.
#[derive(Clone, Debug, PartialEq)]
pub struct ObsHistory<const M: usize, const O: usize> {
    slots: [[f32; O]; M],
    history: usize,
    obs_dim: usize,
    /// Index of the oldest observation (`0` when empty).
    oldest: usize,
    filled: bool,
}

impl<const M: usize, const O: usize> ObsHistory<M, O> {
    /// Empty history of `M` observations of `O` values.
    pub const fn new() -> Self {
        Self {
            slots: [[0.0; O]; M],
            history: M,
            obs_dim: O,
            oldest: 0,
            filled: false,
        }
    }

    /// Empty history of `history` observations of `obs_dim` values; `None` beyond the capacity.
    pub fn with_sizes(history: usize, obs_dim: usize) -> Option<Self> {
        (history <= M && obs_dim <= O).then_some(Self {
            history,
            obs_dim,
            ..Self::new()
        })
    }

    /// Forgets every observation (start of an episode).
    pub fn clear(&mut self) {
        self.oldest = 0;
        self.filled = false;
    }

    /// `true` once at least one observation was pushed since the last [`Self::clear`].
    pub fn is_filled(&self) -> bool {
        self.filled
    }

    /// Appends the newest observation (its first `obs_dim` values; pads every slot with it if
    /// the history is empty).
    pub fn push(&mut self, observation: &[f32]) {
        let (history, obs_dim) = (self.history, self.obs_dim);
        let store = |slot: &mut [f32; O]| {
            for (value, new) in slot.iter_mut().take(obs_dim).zip(observation) {
                *value = *new;
            }
        };
        if !self.filled {
            self.slots.iter_mut().take(history).for_each(store);
            self.oldest = 0;
            self.filled = true;
            return;
        }
        if let Some(slot) = self.slots.get_mut(self.oldest) {
            store(slot);
        }
        let next = self.oldest + 1;
        self.oldest = if next >= history { 0 } else { next };
    }

    /// The observations, oldest first (meaningful only when [`Self::is_filled`]).
    pub fn iter_oldest_first(&self) -> impl Iterator<Item = &[f32]> {
        let slots = self.slots.get(..self.history).unwrap_or(&[]);
        let (newer, older) = slots.split_at(self.oldest.min(slots.len()));
        older
            .iter()
            .chain(newer)
            .map(|slot| slot.get(..self.obs_dim).unwrap_or(&[]))
    }

    /// The newest observation, if any.
    pub fn newest(&self) -> Option<&[f32]> {
        if !self.filled {
            return None;
        }
        let index = if self.oldest == 0 {
            self.history.checked_sub(1)?
        } else {
            self.oldest - 1
        };
        self.slots.get(index)?.get(..self.obs_dim)
    }
}

impl<const M: usize, const O: usize> Default for ObsHistory<M, O> {
    fn default() -> Self {
        Self::new()
    }
}
