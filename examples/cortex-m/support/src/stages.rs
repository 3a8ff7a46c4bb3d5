//! Per-stage instruction counts: timestamps taken inside a forward pass ([`Marks`]), a wrapper
//! that marks the entry and exit of any policy network ([`MarkedNetwork`]) and a quantized MLP
//! network that marks the boundary of every layer ([`StagedMlpNetwork`], over frmd-core's own
//! staged forward pass). `core` + frmd-core only: the host test runs the same code with a
//! counting clock and checks that the staged network computes exactly what frmd-core's
//! `QuantMlpNetwork` computes.

use frmd_core::model::mlp::{MlpPrecision, ModelError};
use frmd_core::policy::{Network, PolicyError, QuantMlpNetwork};

/// Reads a free-running counter (SysTick on the firmware, counting down; a constant on the host).
pub type Clock = fn() -> u32;

/// Up to `S` counter readings of one pass, in order.
#[derive(Clone, Copy, Debug)]
pub struct Marks<const S: usize> {
    clock: Clock,
    ticks: [u32; S],
    count: usize,
}

impl<const S: usize> Marks<S> {
    pub const fn new(clock: Clock) -> Self {
        Self {
            clock,
            ticks: [0; S],
            count: 0,
        }
    }

    /// Forgets the readings (call at the start of a pass).
    #[inline(always)]
    pub fn clear(&mut self) {
        self.count = 0;
    }

    /// Records one reading; readings beyond `S` are dropped.
    #[inline(always)]
    pub fn mark(&mut self) {
        if let Some(slot) = self.ticks.get_mut(self.count) {
            *slot = (self.clock)();
            self.count += 1;
        }
    }

    /// The readings of the current pass.
    pub fn ticks(&self) -> &[u32] {
        self.ticks.get(..self.count).unwrap_or(&[])
    }
}

/// Any policy network with its entry and exit marked (the transformer breakdown).
pub struct MarkedNetwork<Net> {
    inner: Net,
    marks: Marks<2>,
}

impl<Net: Network> MarkedNetwork<Net> {
    /// `inner`, reading `clock` at the entry and the exit of every forward pass.
    pub fn new(inner: Net, clock: Clock) -> Self {
        Self {
            inner,
            marks: Marks::new(clock),
        }
    }

    /// The wrapped network.
    pub fn inner(&self) -> &Net {
        &self.inner
    }

    /// Clock readings at the entry and the exit of the last forward pass.
    pub fn marks(&self) -> &Marks<2> {
        &self.marks
    }
}

impl<Net: Network> Network for MarkedNetwork<Net> {
    fn input_width(&self) -> usize {
        self.inner.input_width()
    }

    fn output_width(&self) -> usize {
        self.inner.output_width()
    }

    fn num_noise_variants(&self) -> usize {
        self.inner.num_noise_variants()
    }

    fn forward(
        &mut self,
        variant: usize,
        input: &[f32],
        output: &mut [f32],
    ) -> Result<(), PolicyError> {
        self.marks.clear();
        self.marks.mark();
        let result = self.inner.forward(variant, input, output);
        self.marks.mark();
        result
    }
}

/// Readings of [`StagedMlpNetwork`]: entry, after input quantization, after each of `L` hidden
/// layers, after the output layer's accumulators, after dequantization.
pub const fn mlp_marks(hidden_layers: usize) -> usize {
    hidden_layers + 4
}

/// A quantized MLP policy network (int8 or int16 activations) that marks every stage boundary:
/// frmd-core's own forward pass ([`QuantMlpNetwork::forward_staged`]) with a reading at entry and
/// at each boundary it reports, so the breakdown times exactly what the policy runs. `S`
/// readings (at least `mlp_marks(hidden layers)`).
pub struct StagedMlpNetwork<'a, P: MlpPrecision, const S: usize, const WIDTH: usize> {
    inner: QuantMlpNetwork<'a, P, WIDTH>,
    marks: Marks<S>,
}

impl<'a, P: MlpPrecision, const S: usize, const WIDTH: usize> StagedMlpNetwork<'a, P, S, WIDTH> {
    /// `inner` with its stages read from `clock`; refuses `S` below `mlp_marks` of its hidden
    /// layers.
    pub fn new(inner: QuantMlpNetwork<'a, P, WIDTH>, clock: Clock) -> Result<Self, PolicyError> {
        if S < mlp_marks(inner.hidden_layers()) {
            return Err(PolicyError::Model(ModelError::ScratchTooSmall));
        }
        Ok(Self {
            inner,
            marks: Marks::new(clock),
        })
    }

    /// Readings of the last forward pass (see [`mlp_marks`]).
    pub fn marks(&self) -> &Marks<S> {
        &self.marks
    }
}

impl<P: MlpPrecision, const S: usize, const WIDTH: usize> Network
    for StagedMlpNetwork<'_, P, S, WIDTH>
{
    fn input_width(&self) -> usize {
        self.inner.input_width()
    }

    fn output_width(&self) -> usize {
        self.inner.output_width()
    }

    fn num_noise_variants(&self) -> usize {
        self.inner.num_noise_variants()
    }

    fn forward(
        &mut self,
        variant: usize,
        input: &[f32],
        output: &mut [f32],
    ) -> Result<(), PolicyError> {
        let marks = &mut self.marks;
        marks.clear();
        marks.mark();
        self.inner
            .forward_staged(variant, input, output, &mut || marks.mark())
    }
}
