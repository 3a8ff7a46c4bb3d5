//! RAM and flash figures of an exported transformer policy (the blob form), in the same
//! [`MemoryFigures`] terms as the MLP.

use super::fold::FloatNorm;
use super::quantize::{QuantizedLinear, QuantizedTransformer};
use crate::memory::{policy_table_bytes, state_bytes, MemoryFigures};
use crate::mlp::ExportPrecision;
use std::mem::size_of;

fn linear_weight_bytes<P: ExportPrecision>(layer: &QuantizedLinear<P>) -> usize {
    layer.weights.len() + size_of::<P::Acc>() * layer.bias.len()
}

/// f32 tables of a linear layer: per-channel output scales.
fn linear_table_bytes<P: ExportPrecision>(layer: &QuantizedLinear<P>) -> usize {
    4 * layer.output_scales.len()
}

fn norm_bytes(norm: &FloatNorm) -> usize {
    4 * (norm.gamma.len() + norm.beta.len())
}

impl<P: ExportPrecision> QuantizedTransformer<P> {
    /// RAM/flash figures. RAM: frmd-core's quantized transformer scratch
    /// ([`frmd_core::model::transformer::TransformerShape::quantized_scratch`], exact) plus the
    /// policy state (the same f32 buffers as the MLP policy: history, noise, trajectories, input
    /// vector, parameters). Flash: int8 weights and int32 (int16 activations: int64) biases
    /// ("weights"), and every table the loader views ("tables": output scales, fc1
    /// requantization, GELU tables, LayerNorms,
    /// positions, noise tokens, ProDMP tables, normalization, steps). The blob adds its header,
    /// descriptor and alignment padding on top.
    pub fn memory(&self) -> MemoryFigures {
        let f = &self.folded;
        let dims = self.dims();
        let input = f
            .base
            .layout
            .width(dims.history, dims.obs_dim, dims.action_dim, dims.horizon)
            .unwrap_or(0);
        let scratch = f.shape.quantized_scratch::<P>();
        // fc1 is requantized (multipliers and shifts below), so its output scales are not stored;
        // every other linear layer dequantizes with its output scales.
        let mut linears: Vec<&QuantizedLinear<P>> = vec![&self.traj_in, &self.cond_in, &self.head];
        for b in &self.blocks {
            linears.extend([&b.qkv, &b.proj, &b.fc2]);
        }
        let weights_bytes = linears
            .iter()
            .copied()
            .chain(self.blocks.iter().map(|b| &b.fc1))
            .map(linear_weight_bytes)
            .sum();
        let block_tables: usize = self
            .blocks
            .iter()
            .map(|b| {
                norm_bytes(&b.norm1)
                    + norm_bytes(&b.norm2)
                    + 4 * (b.fc1_multipliers.len() + b.fc1_shifts.len())
                    + P::TABLE_LEN * size_of::<P>()
            })
            .sum();
        let table_bytes = linears.iter().map(|l| linear_table_bytes(l)).sum::<usize>()
            + block_tables
            + norm_bytes(&f.final_norm)
            + 4 * (f.positions.len() + f.noise_tokens.iter().map(Vec::len).sum::<usize>())
            + policy_table_bytes(&dims, f.base.steps.len());
        MemoryFigures {
            scratch_width: f.shape.width,
            scratch_bytes: scratch.ram_bytes(),
            state_bytes: state_bytes(&dims, input),
            weights_bytes,
            table_bytes,
        }
    }
}
