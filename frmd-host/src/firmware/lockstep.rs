//! Two policies in lockstep: the first one's chunks drive the loop, the second one answers the
//! same requests and every chunk pair is compared bit for bit (the firmware against the host int8
//! policy in `frmd eval --firmware --check-host`).
use crate::tasks::{Policy, PolicyInput};
use serde::Serialize;

/// How many chunks the two policies agreed on.
#[derive(Clone, Debug, Default, Serialize)]
pub struct LockstepCount {
    pub chunks: usize,
    /// Chunks whose actions differ in any bit (or in length).
    pub differing_chunks: usize,
    /// The first differing chunk, by its index among all chunks.
    pub first_difference: Option<usize>,
}

/// `lead` drives, `shadow` is compared.
pub struct Lockstep<A, B> {
    pub lead: A,
    pub shadow: B,
    pub count: LockstepCount,
}

impl<A: Policy, B: Policy> Lockstep<A, B> {
    pub fn new(lead: A, shadow: B) -> Self {
        Lockstep {
            lead,
            shadow,
            count: LockstepCount::default(),
        }
    }
}

/// Whether two chunks hold the same f32 bit patterns.
pub fn same_bits(a: &[Vec<f32>], b: &[Vec<f32>]) -> bool {
    a.len() == b.len()
        && a.iter().zip(b).all(|(x, y)| {
            x.len() == y.len() && x.iter().zip(y).all(|(p, q)| p.to_bits() == q.to_bits())
        })
}

impl<A: Policy, B: Policy> Policy for Lockstep<A, B> {
    fn name(&self) -> String {
        format!(
            "{} (checked against {})",
            self.lead.name(),
            self.shadow.name()
        )
    }

    fn reset(&mut self, seed: u64) {
        self.lead.reset(seed);
        self.shadow.reset(seed);
    }

    fn act(&mut self, input: &PolicyInput<'_>) -> anyhow::Result<Vec<Vec<f32>>> {
        let chunk = self.lead.act(input)?;
        let reference = self.shadow.act(input)?;
        if !same_bits(&chunk, &reference) {
            self.count.first_difference.get_or_insert(self.count.chunks);
            self.count.differing_chunks += 1;
        }
        self.count.chunks += 1;
        Ok(chunk)
    }
}
