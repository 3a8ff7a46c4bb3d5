//! Transformer backbone (pre-LayerNorm, GELU approximated as x sigmoid(1.702 x), the same
//! function as frmd-core's `kernels::gelu_sigmoid` that the int8 LUT is built from): tokens are
//! the n trajectory steps, one condition token and one noise token, with learned positions; the
//! final tokens are flattened into a linear head. transformer-lite = 3 layers, 2 heads, width 128;
//! transformer = 6 layers, 4 heads, width 256.
//!
//! Training speed (candle 0.11 on CPU, measured on this project's 2-core machine): candle
//! differentiates a broadcast by summing the gradient over the broadcast dimensions, and its sums
//! over leading dimensions are slow scalar loops. Every per-feature vector (biases, LayerNorm
//! gain and offset, positions) and every per-row statistic (LayerNorm mean and scale) is therefore
//! expanded with a matmul against a vector of ones ([`Rows`]), so that its gradient is a matmul
//! too. Activations stay 2-D `[B T, W]` (row-major tokens) between the blocks. The math is that of
//! the plain broadcast form (`candle_nn::Linear`, `ops::layer_norm_slow`; the tests compare
//! values and gradients against it).
use super::act::gelu_sigmoid;
use candle_core::{DType, Result, Tensor, D};
use candle_nn::VarBuilder;

/// Sizes of a transformer backbone.
#[derive(Clone, Debug)]
pub struct TransformerSizes {
    pub layers: usize,
    pub heads: usize,
    pub width: usize,
    pub horizon: usize,
    pub action_dim: usize,
    pub cond_dim: usize,
    pub embed_dim: usize,
    pub output: usize,
}

/// LayerNorm epsilon (as frmd-core's `kernels::norm`).
const NORM_EPS: f64 = 1e-5;

/// Columns of ones used to expand per-feature rows and reduce per-row values with matmuls.
struct Rows {
    /// `[R, 1]` ones, R = rows of the activation (tokens x batch, or batch for the head).
    ones_rows: Tensor,
    /// `[W, 1]` ones, W = features (LayerNorm mean and variance).
    ones_width: Tensor,
    /// `[1, W]` ones (broadcasts a per-row value over the features).
    ones_width_row: Tensor,
}

impl Rows {
    fn new(rows: usize, width: usize, like: &Tensor) -> Result<Self> {
        let device = like.device();
        Ok(Rows {
            ones_rows: Tensor::ones((rows, 1), DType::F32, device)?,
            ones_width: Tensor::ones((width, 1), DType::F32, device)?,
            ones_width_row: Tensor::ones((1, width), DType::F32, device)?,
        })
    }

    /// `[W]` -> `[R, W]` with every row equal to `vector` (gradient: ones^T grad, a matmul).
    fn expand(&self, vector: &Tensor) -> Result<Tensor> {
        self.ones_rows.matmul(&vector.unsqueeze(0)?)
    }

    /// `[R, 1]` -> `[R, W]` (gradient: grad ones, a matmul).
    fn spread(&self, per_row: &Tensor) -> Result<Tensor> {
        per_row.matmul(&self.ones_width_row)
    }

    /// Mean over the features of `[R, W]` -> `[R, 1]`.
    fn row_mean(&self, xs: &Tensor) -> Result<Tensor> {
        let width = self.ones_width.dim(0)?;
        xs.matmul(&self.ones_width)? / width as f64
    }
}

/// `x W^T + b` on 2-D input, weight `[out, in]` and bias `[out]` (names as `candle_nn::Linear`).
struct Linear {
    weight: Tensor,
    bias: Tensor,
}

impl Linear {
    fn new(in_features: usize, out_features: usize, vb: VarBuilder) -> Result<Self> {
        Ok(Linear {
            weight: vb.get((out_features, in_features), "weight")?,
            bias: vb.get(out_features, "bias")?,
        })
    }

    /// `xs` `[R, in]` -> `[R, out]`; `rows` sized for R rows.
    fn forward(&self, xs: &Tensor, rows: &Rows) -> Result<Tensor> {
        xs.matmul(&self.weight.t()?)? + rows.expand(&self.bias)?
    }
}

/// LayerNorm over the last dimension with a backward pass; variables `weight`, `bias`.
struct Norm {
    weight: Tensor,
    bias: Tensor,
}

impl Norm {
    fn new(width: usize, vb: VarBuilder) -> Result<Self> {
        Ok(Norm {
            weight: vb.get(width, "weight")?,
            bias: vb.get(width, "bias")?,
        })
    }

    /// `xs` `[R, W]` -> `(x - mean) / sqrt(var + eps) * weight + bias`, biased variance.
    fn forward(&self, xs: &Tensor, rows: &Rows) -> Result<Tensor> {
        let centred = (xs - rows.spread(&rows.row_mean(xs)?)?)?;
        let inv_std = (rows.row_mean(&centred.sqr()?)? + NORM_EPS)?
            .sqrt()?
            .recip()?;
        let normed = (centred * rows.spread(&inv_std)?)?;
        (normed * rows.expand(&self.weight)?)? + rows.expand(&self.bias)?
    }
}

/// Softmax over the last dimension. The row maximum is a constant shift (softmax does not depend
/// on it), so it is detached: no gradient flows through the max.
fn softmax_last(xs: &Tensor) -> Result<Tensor> {
    let shifted = xs
        .broadcast_sub(&xs.max_keepdim(D::Minus1)?.detach())?
        .exp()?;
    shifted.broadcast_div(&shifted.sum_keepdim(D::Minus1)?)
}

struct Block {
    norm1: Norm,
    qkv: Linear,
    proj: Linear,
    norm2: Norm,
    fc1: Linear,
    fc2: Linear,
    heads: usize,
}

impl Block {
    fn new(width: usize, heads: usize, vb: VarBuilder) -> Result<Self> {
        Ok(Block {
            norm1: Norm::new(width, vb.pp("norm1"))?,
            qkv: Linear::new(width, 3 * width, vb.pp("qkv"))?,
            proj: Linear::new(width, width, vb.pp("proj"))?,
            norm2: Norm::new(width, vb.pp("norm2"))?,
            fc1: Linear::new(width, 4 * width, vb.pp("fc1"))?,
            fc2: Linear::new(4 * width, width, vb.pp("fc2"))?,
            heads,
        })
    }

    /// `xs` `[B T, W]` (batch-major tokens) -> same shape.
    fn forward(&self, xs: &Tensor, batch: usize, rows: &Rows) -> Result<Tensor> {
        let (row_count, width) = xs.dims2()?;
        let tokens = row_count / batch;
        let head_dim = width / self.heads;
        let qkv = self.qkv.forward(&self.norm1.forward(xs, rows)?, rows)?;
        let qkv = qkv
            .reshape((batch, tokens, 3, self.heads, head_dim))?
            .permute((2, 0, 3, 1, 4))?;
        let q = qkv.get(0)?.contiguous()?;
        let k = qkv.get(1)?.contiguous()?;
        let v = qkv.get(2)?.contiguous()?;
        let scores = (q.matmul(&k.t()?)? / (head_dim as f64).sqrt())?;
        let attn = softmax_last(&scores)?.matmul(&v)?;
        let attn = attn.transpose(1, 2)?.reshape((row_count, width))?;
        let xs = (xs + self.proj.forward(&attn, rows)?)?;
        let hidden = gelu_sigmoid(&self.fc1.forward(&self.norm2.forward(&xs, rows)?, rows)?)?;
        xs + self.fc2.forward(&hidden, rows)?
    }
}

/// Variables: `traj_in`, `cond_in`, `noise_in`, `pos_embedding` [n+2, width], `blocks.{i}.*`,
/// `final_norm`, `head`.
pub struct Transformer {
    traj_in: Linear,
    cond_in: Linear,
    noise_in: Linear,
    pos_embedding: Tensor,
    blocks: Vec<Block>,
    final_norm: Norm,
    head: Linear,
    sizes: TransformerSizes,
}

impl Transformer {
    pub fn new(sizes: &TransformerSizes, vb: VarBuilder) -> Result<Self> {
        let w = sizes.width;
        let tokens = sizes.horizon + 2;
        let blocks = (0..sizes.layers)
            .map(|i| Block::new(w, sizes.heads, vb.pp(format!("blocks.{i}"))))
            .collect::<Result<Vec<_>>>()?;
        Ok(Transformer {
            traj_in: Linear::new(sizes.action_dim, w, vb.pp("traj_in"))?,
            cond_in: Linear::new(sizes.cond_dim, w, vb.pp("cond_in"))?,
            noise_in: Linear::new(sizes.embed_dim, w, vb.pp("noise_in"))?,
            pos_embedding: vb.get((tokens, w), "pos_embedding")?,
            blocks,
            final_norm: Norm::new(w, vb.pp("final_norm"))?,
            head: Linear::new(tokens * w, sizes.output, vb.pp("head"))?,
            sizes: sizes.clone(),
        })
    }

    /// `x_scaled` [B, n k], `cond` [B, C], `emb` [B, E] -> [B, output].
    pub fn forward(&self, x_scaled: &Tensor, cond: &Tensor, emb: &Tensor) -> Result<Tensor> {
        let batch = x_scaled.dim(0)?;
        let s = &self.sizes;
        let tokens = s.horizon + 2;
        let per_batch = Rows::new(batch, s.width, x_scaled)?;
        let per_step = Rows::new(batch * s.horizon, s.width, x_scaled)?;
        let per_token = Rows::new(batch * tokens, s.width, x_scaled)?;
        let steps = self.traj_in.forward(
            &x_scaled.reshape((batch * s.horizon, s.action_dim))?,
            &per_step,
        )?;
        let cond_token = self.cond_in.forward(cond, &per_batch)?.unsqueeze(1)?;
        let noise_token = self.noise_in.forward(emb, &per_batch)?.unsqueeze(1)?;
        let steps = steps.reshape((batch, s.horizon, s.width))?;
        let h = Tensor::cat(&[&cond_token, &noise_token, &steps], 1)?
            .reshape((batch, tokens * s.width))?;
        let h = (h + per_batch
            .ones_rows
            .matmul(&self.pos_embedding.reshape((1, tokens * s.width))?)?)?;
        let mut h = h.reshape((batch * tokens, s.width))?;
        for block in &self.blocks {
            h = block.forward(&h, batch, &per_token)?;
        }
        let h = self.final_norm.forward(&h, &per_token)?;
        self.head
            .forward(&h.reshape((batch, tokens * s.width))?, &per_batch)
    }
}

#[cfg(test)]
mod tests;
