//! Fixed-capacity observation history: the last `M` normalized observations, oldest first.

/// Ring buffer of `M` observations of `O` values each (normalized units).
///
/// At episode start ([`ObsHistory::clear`]) it is empty; the first [`ObsHistory::push`] fills
/// every slot with that observation (padding by repeating the first observation, as the training
/// windows do). Afterwards each push overwrites the oldest slot.
#[derive(Clone, Debug, PartialEq)]
pub struct ObsHistory<const M: usize, const O: usize> {
    slots: [[f32; O]; M],
    /// Index of the oldest observation (`0` when empty or `M == 0`).
    oldest: usize,
    filled: bool,
}

impl<const M: usize, const O: usize> ObsHistory<M, O> {
    /// Empty history.
    pub const fn new() -> Self {
        Self {
            slots: [[0.0; O]; M],
            oldest: 0,
            filled: false,
        }
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

    /// Appends the newest observation (pads every slot with it if the history is empty).
    pub fn push(&mut self, observation: &[f32; O]) {
        if !self.filled {
            self.slots = [*observation; M];
            self.oldest = 0;
            self.filled = true;
            return;
        }
        if let Some(slot) = self.slots.get_mut(self.oldest) {
            *slot = *observation;
        }
        let next = self.oldest + 1;
        self.oldest = if next >= M { 0 } else { next };
    }

    /// The `M` observations, oldest first (meaningful only when [`Self::is_filled`]).
    pub fn iter_oldest_first(&self) -> impl Iterator<Item = &[f32; O]> {
        let (newer, older) = self.slots.split_at(self.oldest.min(M));
        older.iter().chain(newer)
    }

    /// The newest observation, if any.
    pub fn newest(&self) -> Option<&[f32; O]> {
        if !self.filled {
            return None;
        }
        let index = if self.oldest == 0 {
            M.checked_sub(1)?
        } else {
            self.oldest - 1
        };
        self.slots.get(index)
    }
}

impl<const M: usize, const O: usize> Default for ObsHistory<M, O> {
    fn default() -> Self {
        Self::new()
    }
}
