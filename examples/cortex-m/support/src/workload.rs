//! What the benchmark harness needs from a workload. `core` only: the host tests compute the same
//! digest with [`digest_all`].

use frmd_core::hash::Fnv1a64;

/// A fixed list of inputs, each processed by a measured [`Workload::run`] call.
pub trait Workload {
    type Error: core::fmt::Display;

    /// Printed as the `workload:` line.
    fn name(&self) -> &'static str;
    /// Number of distinct inputs.
    fn cases(&self) -> usize;
    /// Loads input number `case` (not measured).
    fn prepare(&mut self, case: usize) -> Result<(), Self::Error>;
    /// The measured call.
    fn run(&mut self) -> Result<(), Self::Error>;
    /// Feeds the outputs of the last [`Workload::run`] to `digest`.
    fn digest_outputs(&self, digest: &mut Fnv1a64);
    /// Multiply-accumulates of one call (int8 and f32 together), 0 if not stated; printed as the
    /// `macs:` line when nonzero. Workloads with a per-stage breakdown state theirs per stage.
    fn macs(&self) -> u64 {
        0
    }
}

/// Digest of every case run once, in order (what the firmware prints as `digest:`).
pub fn digest_all<W: Workload>(workload: &mut W) -> Result<u64, W::Error> {
    let mut digest = Fnv1a64::new();
    for case in 0..workload.cases() {
        workload.prepare(case)?;
        workload.run()?;
        workload.digest_outputs(&mut digest);
    }
    Ok(digest.finish())
}

/// Multiply-accumulates of one baked ProDMP decode (`BakedProDmp::decode`): per query time and
/// DoF, `params + 2` for the position (basis weights and goal, then `y0`, `v0`) and as many for
/// the velocity.
pub const fn prodmp_decode_macs(horizon: usize, dof: usize, params: usize) -> u64 {
    (2 * horizon * dof * (params + 2)) as u64
}
