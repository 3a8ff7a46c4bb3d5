//! A [`QuantizedTransformer`] as a transformer blob (format and loader in
//! [`frmd_core::blob::transformer`]).

use super::quantize::{QuantizedLinear, QuantizedTransformer};
use super::FloatNorm;
use crate::checkpoint::Normalization;
use frmd_core::blob::format::{Section, SECTION_ALIGN, STEP_WORDS};
use frmd_core::blob::transformer::{BlockDesc, LinearDesc, NormDesc};
use frmd_core::blob::{encode_transformer, transformer_encoded_len, BlobError, TransformerDescriptor};

/// The data area being laid out: every section starts at a multiple of [`SECTION_ALIGN`].
#[derive(Default)]
struct DataArea {
    bytes: Vec<u8>,
}

impl DataArea {
    fn push<const B: usize, T: Copy>(&mut self, values: &[T], to_bytes: impl Fn(T) -> [u8; B]) -> Result<Section, BlobError> {
        let offset = self.bytes.len().next_multiple_of(SECTION_ALIGN);
        self.bytes.resize(offset, 0);
        for value in values {
            self.bytes.extend_from_slice(&to_bytes(*value));
        }
        let small = |v: usize| u32::try_from(v).map_err(|_| BlobError::TooLarge);
        Ok(Section { offset: small(offset)?, len: small(values.len() * B)? })
    }

    fn f32s(&mut self, values: &[f32]) -> Result<Section, BlobError> {
        self.push(values, f32::to_le_bytes)
    }

    fn i32s(&mut self, values: &[i32]) -> Result<Section, BlobError> {
        self.push(values, i32::to_le_bytes)
    }

    fn i8s(&mut self, values: &[i8]) -> Result<Section, BlobError> {
        self.push(values, i8::to_le_bytes)
    }

    fn linear(&mut self, layer: &QuantizedLinear, with_scales: bool) -> Result<LinearDesc, BlobError> {
        Ok(LinearDesc {
            input_scale: layer.input.scale,
            input_zero_point: layer.input.zero_point,
            weights: self.i8s(&layer.weights)?,
            bias: self.i32s(&layer.bias)?,
            scales: self.f32s(if with_scales { &layer.output_scales } else { &[] })?,
        })
    }

    fn norm(&mut self, norm: &FloatNorm) -> Result<NormDesc, BlobError> {
        Ok(NormDesc { gamma: self.f32s(&norm.gamma)?, beta: self.f32s(&norm.beta)? })
    }
}

/// Writes `model` with normalization `norm` as a transformer blob. Fails with a named error if
/// a size does not fit the format (more than [`frmd_core::blob::transformer::MAX_BLOCKS`]
/// blocks, sizes beyond u32); the loader checks every shape.
pub fn write(model: &QuantizedTransformer, norm: &Normalization) -> Result<Vec<u8>, BlobError> {
    let f = &model.folded;
    let c = &f.config;
    let small = |v: usize| u32::try_from(v).map_err(|_| BlobError::TooLarge);
    let mut data = DataArea::default();
    let obs_norm = data.f32s(&[norm.obs.min.as_slice(), &norm.obs.max].concat())?;
    let action_norm = data.f32s(&[norm.action.min.as_slice(), &norm.action.max].concat())?;
    let t = &f.prodmp;
    let prodmp = data.f32s(&[&t.pos_params[..], &t.vel_params, &t.pos_y0, &t.pos_v0, &t.vel_y0, &t.vel_v0].concat())?;
    let words: Vec<u32> = f
        .steps
        .iter()
        .flat_map(|s| -> [u32; STEP_WORDS] {
            [s.sigma.to_bits(), s.renoise_std.to_bits(), s.c_in.to_bits(), s.c_skip.to_bits(), s.c_out.to_bits(), s.first_layer_bias_index]
        })
        .collect();
    let steps = data.push(&words, u32::to_le_bytes)?;
    let noise_tokens = data.f32s(&f.flat_noise_tokens())?;
    let positions = data.f32s(&f.positions)?;
    let traj_in = data.linear(&model.traj_in, true)?;
    let cond_in = data.linear(&model.cond_in, true)?;
    let mut blocks = heapless::Vec::new();
    for b in &model.blocks {
        let desc = BlockDesc {
            norm1: data.norm(&b.norm1)?,
            qkv: data.linear(&b.qkv, true)?,
            proj: data.linear(&b.proj, true)?,
            norm2: data.norm(&b.norm2)?,
            fc1: data.linear(&b.fc1, false)?,
            fc1_multipliers: data.i32s(&b.fc1_multipliers)?,
            fc1_shifts: data.i32s(&b.fc1_shifts)?,
            fc1_output_zero_point: b.fc1_output.zero_point,
            gelu: data.i8s(&b.gelu.table)?,
            fc2: data.linear(&b.fc2, true)?,
        };
        blocks.push(desc).map_err(|_| BlobError::TooLarge)?;
    }
    let final_norm = data.norm(&f.final_norm)?;
    let head = data.linear(&model.head, true)?;
    let descriptor = TransformerDescriptor {
        history: small(c.history)?,
        obs_dim: small(c.obs_dim)?,
        action_dim: small(c.action_dim)?,
        horizon: small(c.horizon)?,
        params_per_dof: small(c.output_dim() / c.action_dim.max(1))?,
        control_dt: c.control_dt as f32,
        layout: f.layout,
        width: small(f.shape.width)?,
        heads: small(f.shape.heads)?,
        obs_norm,
        action_norm,
        prodmp,
        steps,
        noise_tokens,
        positions,
        traj_in,
        cond_in,
        blocks,
        final_norm,
        head,
    };
    let mut out = vec![0u8; transformer_encoded_len(&descriptor, data.bytes.len())?];
    let written = encode_transformer(&descriptor, &data.bytes, &mut out)?;
    out.truncate(written);
    Ok(out)
}
