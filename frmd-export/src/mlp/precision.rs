//! What quantization does differently per activation precision ([`ExportPrecision`], the MLP's
//! and transformer-lite's exporters) and the wide-integer model of one output code
//! ([`WideModel`]):
//! int8 activations (TFLite's int8 scheme: asymmetric codes, int32 biases, 256-entry tables) or
//! int16 activations (TFLite's 16x8 scheme: symmetric codes, int64 biases, interpolated 513-knot
//! tables). Everything else in [`super::quantize`] is shared.
use anyhow::{bail, Context};
use frmd_core::kernels::{Lut16, Lut16Table, Lut8, LutTable};
use frmd_core::model::mlp::MlpPrecision;
use frmd_core::quant::{reference, symmetric_i16_scale, QuantParams};

use super::quantized::QuantizedLayer;
use crate::calibrate::{int_bias, int_bias_i64, QuantizedWeights};

/// An activation precision the MLP exporter writes.
pub trait ExportPrecision: MlpPrecision + WideModel + Into<i16> + TryFrom<i16> {
    /// The codes' parameters at a quantization point from its calibrated int8 parameters
    /// (`calibrated` represents the recorded range), widened by `headroom` (>= 1) where the
    /// precision affords it.
    fn activation(calibrated: QuantParams, headroom: f32) -> anyhow::Result<QuantParams>;

    /// `bias` at `input.scale * weight_scale[o]`, the input zero point folded in.
    fn bias(
        bias: &[f32],
        q: &QuantizedWeights,
        input: QuantParams,
        in_features: usize,
    ) -> anyhow::Result<Vec<Self::Acc>>;

    /// The table of `f` from pre-activation codes (`pre`) to output codes (`out`).
    fn activation_table(
        f: impl Fn(f32) -> f32,
        pre: QuantParams,
        out: QuantParams,
    ) -> anyhow::Result<Self::Table>;

    /// Whether the accumulators are int32 (wrapping), so that a 16-bit first-layer input must be
    /// checked to stay within them; int64 accumulators are exact by construction.
    const INT32_ACCUMULATORS: bool;
}

impl ExportPrecision for i8 {
    /// The calibrated parameters as they are: an int8 code cannot afford wider ranges (every
    /// widening measured worse, docs/design.md section 7).
    fn activation(calibrated: QuantParams, _headroom: f32) -> anyhow::Result<QuantParams> {
        Ok(calibrated)
    }

    fn bias(
        bias: &[f32],
        q: &QuantizedWeights,
        input: QuantParams,
        in_features: usize,
    ) -> anyhow::Result<Vec<i32>> {
        int_bias(bias, q, input, in_features)
    }

    fn activation_table(
        f: impl Fn(f32) -> f32,
        pre: QuantParams,
        out: QuantParams,
    ) -> anyhow::Result<LutTable> {
        let lut = Lut8::build(f, pre, out)?;
        let mut table = [0_i8; 256];
        for (i, slot) in table.iter_mut().enumerate() {
            *slot = lut.lookup((i as i32 - 128) as i8);
        }
        Ok(table)
    }

    const INT32_ACCUMULATORS: bool = true;
}

impl ExportPrecision for i16 {
    /// Symmetric codes over the calibrated range's larger end times `headroom`: closed-loop
    /// pre-activations leave the calibrated ranges, and int16 keeps resolution where int8 could
    /// not (docs/design.md section 7).
    fn activation(calibrated: QuantParams, headroom: f32) -> anyhow::Result<QuantParams> {
        if !(headroom.is_finite() && headroom >= 1.0) {
            bail!("activation headroom {headroom} must be finite and at least 1");
        }
        let reach = calibrated
            .dequantize(i8::MIN)
            .abs()
            .max(calibrated.dequantize(i8::MAX).abs());
        let scale = symmetric_i16_scale(reach * headroom)
            .with_context(|| format!("int16 range +-{}", reach * headroom))?;
        Ok(QuantParams {
            scale,
            zero_point: 0,
        })
    }

    fn bias(
        bias: &[f32],
        q: &QuantizedWeights,
        input: QuantParams,
        in_features: usize,
    ) -> anyhow::Result<Vec<i64>> {
        int_bias_i64(bias, q, input, in_features)
    }

    fn activation_table(
        f: impl Fn(f32) -> f32,
        pre: QuantParams,
        out: QuantParams,
    ) -> anyhow::Result<Lut16Table> {
        Ok(Lut16::build(f, pre.scale, out.scale)?.table)
    }

    const INT32_ACCUMULATORS: bool = false;
}

/// The wide-integer model of one output code, per precision: the requantization of an exact
/// accumulator and the activation table read from its entries (the MLP's and the transformer's
/// kernel checks).
pub trait WideModel: frmd_core::kernels::Precision + Into<i64> {
    /// The i128 model of the requantization of `acc` to the codes `lo..=hi`.
    fn wide_requantize(
        acc: i128,
        multiplier: i32,
        shift: i32,
        zero_point: i32,
        lo: Self,
        hi: Self,
    ) -> Self;

    /// The table's value at `code`, computed from its entries.
    fn wide_lookup(table: &Self::Table, code: Self) -> Self;

    /// Channel `o`'s output code of an MLP hidden layer for the exact accumulator `acc`.
    fn output(layer: &QuantizedLayer<Self>, tables: &[Self::Table], o: usize, acc: i64) -> i64 {
        let q = Self::wide_requantize(
            i128::from(acc),
            layer.multipliers[o],
            layer.shifts[o],
            layer.output_zero_point,
            layer.activation_min,
            layer.activation_max,
        );
        match layer.lut {
            Some(t) => Self::wide_lookup(&tables[t], q),
            None => q,
        }
        .into()
    }
}

impl WideModel for i8 {
    /// The i128 model of Q31 requantization (int32 accumulators wrap: the model takes the low
    /// 32 bits, as the definition does).
    fn wide_requantize(
        acc: i128,
        multiplier: i32,
        shift: i32,
        zero_point: i32,
        lo: i8,
        hi: i8,
    ) -> i8 {
        reference::requantize(acc as i32, multiplier, shift, zero_point, lo, hi)
    }

    /// The table indexed directly.
    fn wide_lookup(table: &[i8; 256], code: i8) -> i8 {
        table[(i32::from(code) + 128) as usize]
    }
}

impl WideModel for i16 {
    /// The i128 model of the Q15 requantization (zero point 0).
    fn wide_requantize(
        acc: i128,
        multiplier: i32,
        shift: i32,
        _zero_point: i32,
        lo: i16,
        hi: i16,
    ) -> i16 {
        reference::requantize16(acc, multiplier, shift, lo, hi)
    }

    /// The slope form of the interpolation.
    fn wide_lookup(table: &[i16; 513], code: i16) -> i16 {
        reference::lookup16(table, code).unwrap_or(i16::MIN)
    }
}
