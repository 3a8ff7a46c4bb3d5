//! Per-stage instruction counts: timestamps taken inside a forward pass ([`Marks`]), a wrapper
//! that marks the entry and exit of any policy network ([`MarkedNetwork`]) and an int8 MLP network
//! that marks the boundary of every layer ([`StagedMlpNetwork`]). `core` + frmd-core only: the host
//! test runs the same code with a clock that always reads 0 and checks that the staged network
//! computes exactly what frmd-core's `Int8MlpNetwork` computes.

use frmd_core::kernels::{dequantize_accumulators, LayerInput};
use frmd_core::model::linear::{Int8Linear, RequantizedLinear};
use frmd_core::model::mlp::{
    quantize_input_i16, quantize_input_two_plane, InputPrecision, ModelError,
};
use frmd_core::policy::{Network, PolicyError};
use frmd_core::quant::QuantParams;

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

/// An int8 MLP as a policy [`Network`] that marks every stage boundary. It runs the same frmd-core
/// kernels in the same order as `Int8MlpNetwork` (input quantization, per hidden layer
/// `RequantizedLinear::forward_prevalidated`, output `forward_accumulators` +
/// `dequantize_accumulators`), with the first-layer bias variant selected as `Int8MlpNetwork`
/// does; `L` hidden layers, `S` readings (`mlp_marks(L)`), activations up to `WIDTH` wide.
pub struct StagedMlpNetwork<'a, const L: usize, const S: usize, const WIDTH: usize> {
    input: QuantParams,
    hidden: [RequantizedLinear<'a>; L],
    output: Int8Linear<'a>,
    first_layer_biases: &'a [i32],
    input_precision: InputPrecision,
    ping: [i8; WIDTH],
    pong: [i8; WIDTH],
    accumulators: [i32; WIDTH],
    marks: Marks<S>,
}

impl<'a, const L: usize, const S: usize, const WIDTH: usize> StagedMlpNetwork<'a, L, S, WIDTH> {
    /// The network; `first_layer_biases` as for `Int8MlpNetwork::new` (back-to-back variants of
    /// the first hidden layer's bias, or empty). Needs `L >= 1` and every width `<= WIDTH`.
    pub fn new(
        input: QuantParams,
        hidden: [RequantizedLinear<'a>; L],
        output: Int8Linear<'a>,
        first_layer_biases: &'a [i32],
        clock: Clock,
    ) -> Result<Self, PolicyError> {
        let widths_fit = hidden
            .iter()
            .map(|layer| &layer.fc)
            .chain([&output.fc])
            .all(|fc| fc.in_features <= WIDTH && fc.out_features <= WIDTH);
        if L == 0 || S < mlp_marks(L) || !widths_fit {
            return Err(PolicyError::Model(ModelError::ScratchTooSmall));
        }
        // Once here, as `Int8MlpNetwork` does, so that `forward` need not repeat it.
        for layer in &hidden {
            layer
                .requant
                .validate(layer.fc.out_features)
                .map_err(|e| PolicyError::Model(ModelError::Kernel(e)))?;
        }
        Ok(Self {
            input,
            hidden,
            output,
            first_layer_biases,
            input_precision: InputPrecision::Int8,
            ping: [0; WIDTH],
            pong: [0; WIDTH],
            accumulators: [0; WIDTH],
            marks: Marks::new(clock),
        })
    }

    /// The same network quantizing its input as `precision` says (as `Int8MlpNetwork`'s
    /// `with_input_precision`; the first layer is one stage whatever its input, whose codes are
    /// made in the `quantize` stage).
    pub fn with_input_precision(mut self, precision: InputPrecision) -> Self {
        self.input_precision = precision;
        self
    }

    /// Readings of the last forward pass (see [`mlp_marks`]).
    pub fn marks(&self) -> &Marks<S> {
        &self.marks
    }
}

impl<const L: usize, const S: usize, const WIDTH: usize> Network
    for StagedMlpNetwork<'_, L, S, WIDTH>
{
    fn input_width(&self) -> usize {
        self.hidden.first().map_or(0, |layer| layer.fc.in_features)
    }

    fn output_width(&self) -> usize {
        self.output.fc.out_features
    }

    fn num_noise_variants(&self) -> usize {
        let width = self.hidden.first().map_or(0, |layer| layer.fc.out_features);
        self.first_layer_biases
            .len()
            .checked_div(width)
            .unwrap_or(0)
    }

    fn forward(
        &mut self,
        variant: usize,
        input: &[f32],
        output: &mut [f32],
    ) -> Result<(), PolicyError> {
        self.marks.clear();
        self.marks.mark();
        let mut hidden = self.hidden;
        if let Some(first) = hidden.first_mut() {
            if !self.first_layer_biases.is_empty() {
                let width = first.fc.out_features;
                let start = variant
                    .checked_mul(width)
                    .ok_or(PolicyError::NoiseVariantIndex)?;
                first.fc.bias = start
                    .checked_add(width)
                    .and_then(|end| self.first_layer_biases.get(start..end))
                    .ok_or(PolicyError::NoiseVariantIndex)?;
            } else if variant != 0 {
                return Err(PolicyError::NoiseVariantIndex);
            }
        }
        let model = |error| PolicyError::Model(ModelError::Kernel(error));
        let (mut current, mut next) = (&mut self.ping, &mut self.pong);
        let first = current
            .get_mut(..input.len())
            .ok_or(PolicyError::InputWidth)?;
        let mut width = input.len();
        let mut layers = &hidden[..];
        match self.input_precision {
            InputPrecision::Int8 => {
                for (code, value) in first.iter_mut().zip(input) {
                    *code = self.input.quantize(*value);
                }
                self.marks.mark();
            }
            InputPrecision::Int16 => {
                let (layer, rest) = hidden
                    .split_first()
                    .ok_or(PolicyError::Model(ModelError::TwoPlaneWithoutHiddenLayer))?;
                let codes = bytemuck::cast_slice_mut::<i32, i16>(self.accumulators.as_mut_slice())
                    .get_mut(..input.len())
                    .ok_or(PolicyError::InputWidth)?;
                quantize_input_i16(input, self.input, codes);
                self.marks.mark();
                let out_width = layer.fc.out_features;
                let layer_output = next.get_mut(..out_width).ok_or(PolicyError::OutputWidth)?;
                layer
                    .forward_prevalidated(LayerInput::Int16(codes), layer_output)
                    .map_err(model)?;
                core::mem::swap(&mut current, &mut next);
                width = out_width;
                layers = rest;
                self.marks.mark();
            }
            InputPrecision::TwoPlane => {
                let fine = next.get_mut(..input.len()).ok_or(PolicyError::InputWidth)?;
                quantize_input_two_plane(input, self.input, first, fine);
                self.marks.mark();
                let (layer, rest) = hidden
                    .split_first()
                    .ok_or(PolicyError::Model(ModelError::TwoPlaneWithoutHiddenLayer))?;
                let out_width = layer.fc.out_features;
                let accumulators = self
                    .accumulators
                    .get_mut(..out_width)
                    .ok_or(PolicyError::OutputWidth)?;
                layer
                    .two_plane_accumulators(first, fine, accumulators)
                    .map_err(model)?;
                let layer_output = next.get_mut(..out_width).ok_or(PolicyError::OutputWidth)?;
                layer
                    .requantize_and_activate(accumulators, layer_output)
                    .map_err(model)?;
                core::mem::swap(&mut current, &mut next);
                width = out_width;
                layers = rest;
                self.marks.mark();
            }
        }
        for layer in layers {
            let out_width = layer.fc.out_features;
            let layer_input = current.get(..width).ok_or(PolicyError::InputWidth)?;
            let layer_output = next.get_mut(..out_width).ok_or(PolicyError::OutputWidth)?;
            layer
                .forward_prevalidated(LayerInput::Int8(layer_input), layer_output)
                .map_err(model)?;
            core::mem::swap(&mut current, &mut next);
            width = out_width;
            self.marks.mark();
        }
        let last_input = current.get(..width).ok_or(PolicyError::InputWidth)?;
        let accumulators = self
            .accumulators
            .get_mut(..self.output.fc.out_features)
            .ok_or(PolicyError::OutputWidth)?;
        self.output
            .fc
            .forward_accumulators(last_input, accumulators)
            .map_err(model)?;
        self.marks.mark();
        dequantize_accumulators(accumulators, self.output.output_scales, output).map_err(model)?;
        self.marks.mark();
        Ok(())
    }
}
