//! MLP policy networks ([`QuantMlpNetwork`]: int8 weights with int8 or int16 activations, and
//! its f32 reference [`F32MlpNetwork`]): the noise embedding of each step is folded into the
//! first layer's bias (the first hidden layer, or the output layer if there is none), one bias
//! row per variant.

use heapless::Vec;

mod packed;

use super::{Network, NoiseVariants};
use crate::kernels::{Accumulator, KernelError, Precision};
use crate::model::linear::{F32Linear, Int8Linear, RequantizedLinear};
use crate::model::mlp::{
    F32Mlp, F32Scratch, InputPrecision, MlpPrecision, ModelError, QuantMlp, QuantScratch,
};
use crate::policy::PolicyError;
use crate::quant::QuantParams;

/// Most hidden layers an MLP policy network can hold.
pub const MAX_HIDDEN_LAYERS: usize = 8;

/// A layer whose bias the network replaces by a noise-level variant.
trait BiasedLayer<'a> {
    type Bias: 'a;
    fn out_features(&self) -> usize;
    fn set_bias(&mut self, bias: &'a [Self::Bias]);
}

impl<'a, P: Precision> BiasedLayer<'a> for RequantizedLinear<'a, P> {
    type Bias = P::Acc;
    fn out_features(&self) -> usize {
        self.fc.out_features
    }
    fn set_bias(&mut self, bias: &'a [P::Acc]) {
        self.fc.bias = bias;
    }
}

impl<'a, A: Accumulator> BiasedLayer<'a> for Int8Linear<'a, A> {
    type Bias = A;
    fn out_features(&self) -> usize {
        self.fc.out_features
    }
    fn set_bias(&mut self, bias: &'a [A]) {
        self.fc.bias = bias;
    }
}

impl<'a> BiasedLayer<'a> for F32Linear<'a> {
    type Bias = f32;
    fn out_features(&self) -> usize {
        self.out_features
    }
    fn set_bias(&mut self, bias: &'a [f32]) {
        self.bias = bias;
    }
}

/// Hidden layers held by value and the output layer, so that a step's bias can be swapped in.
#[derive(Clone, Debug)]
struct Layers<L, O> {
    hidden: Vec<L, MAX_HIDDEN_LAYERS>,
    output: O,
}

impl<'a, L, O> Layers<L, O>
where
    L: BiasedLayer<'a> + Clone,
    O: BiasedLayer<'a, Bias = L::Bias> + Clone,
{
    fn new(hidden: &[L], output: O) -> Result<Self, PolicyError> {
        let hidden = Vec::from_slice(hidden).map_err(|()| PolicyError::TooManyLayers)?;
        Ok(Self { hidden, output })
    }

    /// Width of the first layer's output (one variant row).
    fn first_width(&self) -> usize {
        self.hidden
            .first()
            .map_or(self.output.out_features(), BiasedLayer::out_features)
    }

    /// The layers with variant `index` of `variants` as the first layer's bias.
    fn with_variant(
        &self,
        variants: &NoiseVariants<'a, L::Bias>,
        index: usize,
    ) -> Result<Self, PolicyError> {
        let mut layers = self.clone();
        if let Some(bias) = variants.select(index)? {
            match layers.hidden.first_mut() {
                Some(first) => first.set_bias(bias),
                None => layers.output.set_bias(bias),
            }
        }
        Ok(layers)
    }
}

/// [`QuantMlp`] with per-step first-layer biases and its own scratch (`WIDTH` >= every layer
/// width); `P` is the activation precision.
#[derive(Clone, Debug)]
pub struct QuantMlpNetwork<'a, P: MlpPrecision, const WIDTH: usize> {
    input: QuantParams,
    precision: InputPrecision,
    layers: Layers<RequantizedLinear<'a, P>, Int8Linear<'a, P::Acc>>,
    variants: NoiseVariants<'a, P::Acc>,
    scratch: QuantScratch<P, WIDTH>,
}

/// The int8-activation MLP network.
pub type Int8MlpNetwork<'a, const WIDTH: usize> = QuantMlpNetwork<'a, i8, WIDTH>;
/// The int16-activation MLP network.
pub type Int16MlpNetwork<'a, const WIDTH: usize> = QuantMlpNetwork<'a, i16, WIDTH>;

impl<'a, P: MlpPrecision, const WIDTH: usize> QuantMlpNetwork<'a, P, WIDTH> {
    /// The network of the quantized MLP `input`, `hidden` (copied, so their slice may be
    /// short-lived), `output`, with its input quantized as `precision` says
    /// ([`InputPrecision::TwoPlane`] and [`InputPrecision::Int16`] need a hidden layer and a
    /// first layer made for them, see [`crate::model::mlp`]; int16 activations take
    /// [`InputPrecision::Int16`] only). `noise_variants` holds the first layer's bias variants
    /// back to back (input zero point folded), `out_features` each, or is empty to always use
    /// the layer's own bias.
    pub fn new(
        input: QuantParams,
        precision: InputPrecision,
        hidden: &[RequantizedLinear<'a, P>],
        output: Int8Linear<'a, P::Acc>,
        noise_variants: &'a [P::Acc],
    ) -> Result<Self, PolicyError> {
        if precision != InputPrecision::Int8 && hidden.is_empty() {
            return Err(PolicyError::Model(ModelError::TwoPlaneWithoutHiddenLayer));
        }
        let layers = Layers::new(hidden, output)?;
        let mlp = QuantMlp {
            input,
            hidden,
            output,
        };
        mlp.validate(WIDTH).map_err(PolicyError::Model)?;
        // Once here, so that `forward` need not repeat the per-channel checks.
        mlp.validate_requantization().map_err(PolicyError::Model)?;
        mlp.validate_input_precision(precision)
            .map_err(PolicyError::Model)?;
        // The variants replace the first layer's bias: the same bounds (int64 accumulators).
        if noise_variants.iter().any(|b| !b.bias_valid()) {
            return Err(PolicyError::Model(ModelError::Kernel(
                KernelError::BiasRange,
            )));
        }
        let variants = NoiseVariants::new(noise_variants, layers.first_width())?;
        Ok(Self {
            input,
            precision,
            layers,
            variants,
            scratch: QuantScratch::new(),
        })
    }

    /// How the input is quantized.
    pub fn input_precision(&self) -> InputPrecision {
        self.precision
    }

    /// Hidden layers (the stages of [`Self::forward_staged`] are these plus the input
    /// quantization, the output accumulators and their dequantization).
    pub fn hidden_layers(&self) -> usize {
        self.layers.hidden.len()
    }

    /// The layers as the network runs them (packed weights included; the first layer with
    /// its own bias, which each step's noise variant replaces): hidden, output.
    pub fn layers(&self) -> (&[RequantizedLinear<'a, P>], &Int8Linear<'a, P::Acc>) {
        (&self.layers.hidden, &self.layers.output)
    }

    /// `(in_features, out_features)` of every layer, the output layer last.
    pub fn layer_shapes(&self) -> impl Iterator<Item = (usize, usize)> + '_ {
        let output = &self.layers.output.fc;
        self.layers
            .hidden
            .iter()
            .map(|layer| (layer.fc.in_features, layer.fc.out_features))
            .chain([(output.in_features, output.out_features)])
    }

    /// [`Network::forward`] calling `stage` at every stage boundary of the MLP
    /// ([`QuantMlp::forward_staged`]): a firmware's per-stage timing of the very same pass.
    pub fn forward_staged(
        &mut self,
        variant: usize,
        input: &[f32],
        output: &mut [f32],
        stage: &mut impl FnMut(),
    ) -> Result<(), PolicyError> {
        let layers = self.layers.with_variant(&self.variants, variant)?;
        let mlp = QuantMlp {
            input: self.input,
            hidden: &layers.hidden,
            output: layers.output,
        };
        mlp.forward_staged(self.precision, input, output, self.scratch.buffers(), stage)
            .map_err(PolicyError::Model)
    }

    /// The output layer's accumulators of the last forward pass (for bit-exactness checks).
    pub fn accumulators(&self) -> &[P::Acc] {
        self.scratch
            .accumulators()
            .get(..self.layers.output.fc.out_features)
            .unwrap_or(&[])
    }
}

impl<P: MlpPrecision, const WIDTH: usize> Network for QuantMlpNetwork<'_, P, WIDTH> {
    fn input_width(&self) -> usize {
        self.layers
            .hidden
            .first()
            .map_or(self.layers.output.fc.in_features, |layer| {
                layer.fc.in_features
            })
    }

    fn output_width(&self) -> usize {
        self.layers.output.fc.out_features
    }

    fn num_noise_variants(&self) -> usize {
        self.variants.count()
    }

    fn forward(
        &mut self,
        variant: usize,
        input: &[f32],
        output: &mut [f32],
    ) -> Result<(), PolicyError> {
        self.forward_staged(variant, input, output, &mut || {})
    }
}

/// [`F32Mlp`] with per-step first-layer biases and its own scratch (the f32 reference of
/// [`QuantMlpNetwork`]).
#[derive(Clone, Debug)]
pub struct F32MlpNetwork<'a, const WIDTH: usize> {
    layers: Layers<F32Linear<'a>, F32Linear<'a>>,
    variants: NoiseVariants<'a, f32>,
    scratch: F32Scratch<WIDTH>,
}

impl<'a, const WIDTH: usize> F32MlpNetwork<'a, WIDTH> {
    /// The network of the f32 MLP `hidden` (copied), `output`; `noise_variants` as in
    /// [`QuantMlpNetwork::new`], in f32.
    pub fn new(
        hidden: &[F32Linear<'a>],
        output: F32Linear<'a>,
        noise_variants: &'a [f32],
    ) -> Result<Self, PolicyError> {
        let layers = Layers::new(hidden, output)?;
        F32Mlp { hidden, output }
            .validate(WIDTH)
            .map_err(PolicyError::Model)?;
        let variants = NoiseVariants::new(noise_variants, layers.first_width())?;
        Ok(Self {
            layers,
            variants,
            scratch: F32Scratch::new(),
        })
    }
}

impl<const WIDTH: usize> Network for F32MlpNetwork<'_, WIDTH> {
    fn input_width(&self) -> usize {
        self.layers
            .hidden
            .first()
            .map_or(self.layers.output.in_features, |layer| layer.in_features)
    }

    fn output_width(&self) -> usize {
        self.layers.output.out_features
    }

    fn num_noise_variants(&self) -> usize {
        self.variants.count()
    }

    fn forward(
        &mut self,
        variant: usize,
        input: &[f32],
        output: &mut [f32],
    ) -> Result<(), PolicyError> {
        let layers = self.layers.with_variant(&self.variants, variant)?;
        let mlp = F32Mlp {
            hidden: &layers.hidden,
            output: layers.output,
        };
        mlp.forward(input, output, &mut self.scratch)
            .map_err(PolicyError::Model)
    }
}
