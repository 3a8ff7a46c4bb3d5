//! The [`Network`] trait: one generic sampler path over the int8 MLP and its f32 reference.
//!
//! A network maps the model input vector (see [`super::InputLayout`]) to the `K * P` ProDMP
//! parameters (DoF-major, normalized action units). The noise-level embedding is folded by the
//! exporter into the first layer's bias, one bias variant per sampling step; `forward` selects the
//! variant by index (see [`super::StepConstants::first_layer_bias_index`]).

use crate::kernels::{FcRequant, FullyConnected};
use crate::model::mlp::{
    F32Layer, F32Mlp, F32Scratch, InputPrecision, Int8Layer, Int8Mlp, Int8Scratch, ModelError,
};
use crate::quant::QuantParams;

use super::PolicyError;

/// Most hidden layers an [`Int8Network`] / [`F32Network`] can hold.
pub const MAX_HIDDEN_LAYERS: usize = 8;

/// A forward pass the sampler can drive.
pub trait Network {
    /// Input width.
    fn input_width(&self) -> usize;
    /// Output width (`K * P` for a ProDMP student).
    fn output_width(&self) -> usize;
    /// Number of first-layer bias variants; 0 means the first layer's own bias is used for every
    /// index 0 request.
    fn num_first_layer_biases(&self) -> usize;
    /// Runs the network with first-layer bias variant `first_layer_bias` on `input`, writing the
    /// output parameters into `output` (f32, normalized units).
    fn forward(
        &mut self,
        first_layer_bias: usize,
        input: &[f32],
        output: &mut [f32],
    ) -> Result<(), PolicyError>;
}

/// Points `bias` (the first layer's, `width` outputs) at the `index`-th `width`-long chunk of
/// `variants`; with no variants only index 0 is valid and keeps the layer's own bias.
fn use_bias_variant<'a, T>(
    variants: &'a [T],
    bias: &mut &'a [T],
    width: usize,
    index: usize,
) -> Result<(), PolicyError> {
    if variants.is_empty() {
        return if index == 0 {
            Ok(())
        } else {
            Err(PolicyError::FirstLayerBiasIndex)
        };
    }
    let start = index
        .checked_mul(width)
        .ok_or(PolicyError::FirstLayerBiasIndex)?;
    let end = start
        .checked_add(width)
        .ok_or(PolicyError::FirstLayerBiasIndex)?;
    *bias = variants
        .get(start..end)
        .ok_or(PolicyError::FirstLayerBiasIndex)?;
    Ok(())
}

fn variant_count<T>(variants: &[T], width: usize) -> Result<usize, PolicyError> {
    if width == 0 || !variants.len().is_multiple_of(width) {
        return Err(PolicyError::FirstLayerBiasLength);
    }
    Ok(variants.len() / width)
}

/// Placeholder for unused layer slots.
pub(crate) const EMPTY_INT8_LAYER: Int8Layer<'static> = Int8Layer {
    fc: FullyConnected::new(0, 0, &[], &[]),
    requant: FcRequant {
        multipliers: &[],
        shifts: &[],
        output_zero_point: 0,
        activation_min: i8::MIN,
        activation_max: i8::MAX,
    },
    activation: None,
};

/// [`Int8Mlp`] with per-step first-layer biases and its own scratch (`WIDTH` >= every layer width).
#[derive(Clone, Debug)]
pub struct Int8Network<'a, const WIDTH: usize> {
    input: QuantParams,
    hidden: [Int8Layer<'a>; MAX_HIDDEN_LAYERS],
    num_hidden: usize,
    output: FullyConnected<'a>,
    output_scales: &'a [f32],
    first_layer_biases: &'a [i32],
    num_variants: usize,
    input_precision: InputPrecision,
    scratch: Int8Scratch<WIDTH>,
}

impl<'a, const WIDTH: usize> Int8Network<'a, WIDTH> {
    /// Wraps `mlp`; `first_layer_biases` holds the bias variants of the first layer (the first
    /// hidden layer, or the output layer if there is none) back to back, `out_features` each
    /// (int32, input zero point folded), or is empty to always use the layer's own bias.
    pub fn new(mlp: &Int8Mlp<'a>, first_layer_biases: &'a [i32]) -> Result<Self, PolicyError> {
        Self::from_parts(
            mlp.input,
            mlp.hidden,
            mlp.output,
            mlp.output_scales,
            first_layer_biases,
        )
    }

    /// As [`Self::new`] from the parts of an [`Int8Mlp`]; the hidden layers are copied, so their
    /// slice may be short-lived. The input is quantized to int8 ([`InputPrecision::Int8`]).
    pub fn from_parts(
        input: QuantParams,
        layers: &[Int8Layer<'a>],
        output: FullyConnected<'a>,
        output_scales: &'a [f32],
        first_layer_biases: &'a [i32],
    ) -> Result<Self, PolicyError> {
        Self::from_parts_with_input(
            input,
            InputPrecision::Int8,
            layers,
            output,
            output_scales,
            first_layer_biases,
        )
    }

    /// [`Self::from_parts`] with the input quantized as `precision` says;
    /// [`InputPrecision::TwoPlane`] and [`InputPrecision::Int16`] need a hidden layer and a first
    /// layer made for them (see [`crate::model::mlp`]).
    pub fn from_parts_with_input(
        input: QuantParams,
        precision: InputPrecision,
        layers: &[Int8Layer<'a>],
        output: FullyConnected<'a>,
        output_scales: &'a [f32],
        first_layer_biases: &'a [i32],
    ) -> Result<Self, PolicyError> {
        if precision != InputPrecision::Int8 && layers.is_empty() {
            return Err(PolicyError::Model(ModelError::TwoPlaneWithoutHiddenLayer));
        }
        if layers.len() > MAX_HIDDEN_LAYERS {
            return Err(PolicyError::TooManyLayers);
        }
        let mut hidden = [EMPTY_INT8_LAYER; MAX_HIDDEN_LAYERS];
        for (slot, layer) in hidden.iter_mut().zip(layers) {
            *slot = *layer;
        }
        let mlp = Int8Mlp {
            input,
            hidden: layers,
            output,
            output_scales,
        };
        mlp.validate::<WIDTH>().map_err(PolicyError::Model)?;
        // Once here, so that `forward` need not repeat the per-channel checks.
        mlp.validate_requantization().map_err(PolicyError::Model)?;
        let first_width = layers
            .first()
            .map_or(output.out_features, |layer| layer.fc.out_features);
        let num_variants = if first_layer_biases.is_empty() {
            0
        } else {
            variant_count(first_layer_biases, first_width)?
        };
        Ok(Self {
            input,
            hidden,
            num_hidden: layers.len(),
            output,
            output_scales,
            first_layer_biases,
            num_variants,
            input_precision: precision,
            scratch: Int8Scratch::new(),
        })
    }

    /// How the input is quantized.
    pub fn input_precision(&self) -> InputPrecision {
        self.input_precision
    }

    /// The output layer's int32 accumulators of the last forward pass (for bit-exactness checks).
    pub fn accumulators(&self) -> &[i32] {
        self.scratch
            .accumulators()
            .get(..self.output.out_features)
            .unwrap_or(&[])
    }
}

impl<const WIDTH: usize> Network for Int8Network<'_, WIDTH> {
    fn input_width(&self) -> usize {
        self.hidden
            .get(..self.num_hidden)
            .and_then(<[_]>::first)
            .map_or(self.output.in_features, |layer| layer.fc.in_features)
    }

    fn output_width(&self) -> usize {
        self.output.out_features
    }

    fn num_first_layer_biases(&self) -> usize {
        self.num_variants
    }

    fn forward(
        &mut self,
        first_layer_bias: usize,
        input: &[f32],
        output: &mut [f32],
    ) -> Result<(), PolicyError> {
        let mut hidden = self.hidden;
        let layers = hidden
            .get_mut(..self.num_hidden)
            .ok_or(PolicyError::TooManyLayers)?;
        let mut last = self.output;
        match layers.first_mut() {
            Some(first) => use_bias_variant(
                self.first_layer_biases,
                &mut first.fc.bias,
                first.fc.out_features,
                first_layer_bias,
            )?,
            None => use_bias_variant(
                self.first_layer_biases,
                &mut last.bias,
                last.out_features,
                first_layer_bias,
            )?,
        }
        let mlp = Int8Mlp {
            input: self.input,
            hidden: layers,
            output: last,
            output_scales: self.output_scales,
        };
        mlp.forward_prevalidated(self.input_precision, input, output, &mut self.scratch)
            .map_err(PolicyError::Model)
    }
}

const EMPTY_F32_LAYER: F32Layer<'static> = F32Layer {
    in_features: 0,
    out_features: 0,
    weights: &[],
    bias: &[],
    activation: crate::kernels::Activation::Identity,
};

/// [`F32Mlp`] with per-step first-layer biases and its own scratch (the f32 reference of
/// [`Int8Network`]).
#[derive(Clone, Debug)]
pub struct F32Network<'a, const WIDTH: usize> {
    hidden: [F32Layer<'a>; MAX_HIDDEN_LAYERS],
    num_hidden: usize,
    output: F32Layer<'a>,
    first_layer_biases: &'a [f32],
    num_variants: usize,
    scratch: F32Scratch<WIDTH>,
}

impl<'a, const WIDTH: usize> F32Network<'a, WIDTH> {
    /// Wraps `mlp`; `first_layer_biases` as in [`Int8Network::new`], in f32.
    pub fn new(mlp: &F32Mlp<'a>, first_layer_biases: &'a [f32]) -> Result<Self, PolicyError> {
        Self::from_parts(mlp.hidden, mlp.output, first_layer_biases)
    }

    /// As [`Self::new`] from the parts of an [`F32Mlp`]; the hidden layers are copied, so their
    /// slice may be short-lived.
    pub fn from_parts(
        layers: &[F32Layer<'a>],
        output: F32Layer<'a>,
        first_layer_biases: &'a [f32],
    ) -> Result<Self, PolicyError> {
        if layers.len() > MAX_HIDDEN_LAYERS {
            return Err(PolicyError::TooManyLayers);
        }
        let mut hidden = [EMPTY_F32_LAYER; MAX_HIDDEN_LAYERS];
        for (slot, layer) in hidden.iter_mut().zip(layers) {
            *slot = *layer;
        }
        let mlp = F32Mlp {
            hidden: layers,
            output,
        };
        mlp.validate::<WIDTH>().map_err(PolicyError::Model)?;
        let first_width = layers
            .first()
            .map_or(output.out_features, |layer| layer.out_features);
        let num_variants = if first_layer_biases.is_empty() {
            0
        } else {
            variant_count(first_layer_biases, first_width)?
        };
        Ok(Self {
            hidden,
            num_hidden: layers.len(),
            output,
            first_layer_biases,
            num_variants,
            scratch: F32Scratch::new(),
        })
    }
}

impl<const WIDTH: usize> Network for F32Network<'_, WIDTH> {
    fn input_width(&self) -> usize {
        self.hidden
            .get(..self.num_hidden)
            .and_then(<[_]>::first)
            .map_or(self.output.in_features, |layer| layer.in_features)
    }

    fn output_width(&self) -> usize {
        self.output.out_features
    }

    fn num_first_layer_biases(&self) -> usize {
        self.num_variants
    }

    fn forward(
        &mut self,
        first_layer_bias: usize,
        input: &[f32],
        output: &mut [f32],
    ) -> Result<(), PolicyError> {
        let mut hidden = self.hidden;
        let layers = hidden
            .get_mut(..self.num_hidden)
            .ok_or(PolicyError::TooManyLayers)?;
        let mut last = self.output;
        match layers.first_mut() {
            Some(first) => use_bias_variant(
                self.first_layer_biases,
                &mut first.bias,
                first.out_features,
                first_layer_bias,
            )?,
            None => use_bias_variant(
                self.first_layer_biases,
                &mut last.bias,
                last.out_features,
                first_layer_bias,
            )?,
        }
        let mlp = F32Mlp {
            hidden: layers,
            output: last,
        };
        mlp.forward(input, output, &mut self.scratch)
            .map_err(PolicyError::Model)
    }
}
