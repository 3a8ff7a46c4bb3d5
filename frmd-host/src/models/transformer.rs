//! Transformer backbone (pre-LayerNorm, GELU approximated as x sigmoid(1.702 x)): tokens are the
//! n trajectory steps, one condition token and one noise token, with learned positions; the final
//! tokens are flattened into a linear head. transformer-lite = 3 layers, 2 heads, width 128;
//! transformer = 6 layers, 4 heads, width 256.
use super::act::gelu_sigmoid;
use candle_core::{Result, Tensor, D};
use candle_nn::{Linear, Module, VarBuilder};

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

/// LayerNorm with a backward pass (`ops::layer_norm_slow`); variables `weight`, `bias`.
struct Norm {
    weight: Tensor,
    bias: Tensor,
}

impl Norm {
    fn new(width: usize, vb: VarBuilder) -> Result<Self> {
        Ok(Norm { weight: vb.get(width, "weight")?, bias: vb.get(width, "bias")? })
    }
    fn forward(&self, xs: &Tensor) -> Result<Tensor> {
        candle_nn::ops::layer_norm_slow(xs, &self.weight, &self.bias, 1e-5)
    }
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
            qkv: candle_nn::linear(width, 3 * width, vb.pp("qkv"))?,
            proj: candle_nn::linear(width, width, vb.pp("proj"))?,
            norm2: Norm::new(width, vb.pp("norm2"))?,
            fc1: candle_nn::linear(width, 4 * width, vb.pp("fc1"))?,
            fc2: candle_nn::linear(4 * width, width, vb.pp("fc2"))?,
            heads,
        })
    }

    fn forward(&self, xs: &Tensor) -> Result<Tensor> {
        let (batch, tokens, width) = xs.dims3()?;
        let head_dim = width / self.heads;
        let qkv = self.qkv.forward(&self.norm1.forward(xs)?)?;
        let qkv = qkv.reshape((batch, tokens, 3, self.heads, head_dim))?.permute((2, 0, 3, 1, 4))?;
        let q = qkv.get(0)?.contiguous()?;
        let k = qkv.get(1)?.contiguous()?;
        let v = qkv.get(2)?.contiguous()?;
        let scores = (q.matmul(&k.t()?)? / (head_dim as f64).sqrt())?;
        let attn = candle_nn::ops::softmax(&scores, D::Minus1)?.matmul(&v)?;
        let attn = attn.transpose(1, 2)?.reshape((batch, tokens, width))?;
        let xs = (xs + self.proj.forward(&attn)?)?;
        let hidden = gelu_sigmoid(&self.fc1.forward(&self.norm2.forward(&xs)?)?)?;
        xs + self.fc2.forward(&hidden)?
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
            traj_in: candle_nn::linear(sizes.action_dim, w, vb.pp("traj_in"))?,
            cond_in: candle_nn::linear(sizes.cond_dim, w, vb.pp("cond_in"))?,
            noise_in: candle_nn::linear(sizes.embed_dim, w, vb.pp("noise_in"))?,
            pos_embedding: vb.get((tokens, w), "pos_embedding")?,
            blocks,
            final_norm: Norm::new(w, vb.pp("final_norm"))?,
            head: candle_nn::linear(tokens * w, sizes.output, vb.pp("head"))?,
            sizes: sizes.clone(),
        })
    }

    /// `x_scaled` [B, n k], `cond` [B, C], `emb` [B, E] -> [B, output].
    pub fn forward(&self, x_scaled: &Tensor, cond: &Tensor, emb: &Tensor) -> Result<Tensor> {
        let batch = x_scaled.dim(0)?;
        let s = &self.sizes;
        let steps = self.traj_in.forward(&x_scaled.reshape((batch, s.horizon, s.action_dim))?)?;
        let cond_token = self.cond_in.forward(cond)?.unsqueeze(1)?;
        let noise_token = self.noise_in.forward(emb)?.unsqueeze(1)?;
        let mut h = Tensor::cat(&[&cond_token, &noise_token, &steps], 1)?.broadcast_add(&self.pos_embedding)?;
        for block in &self.blocks {
            h = block.forward(&h)?;
        }
        let h = self.final_norm.forward(&h)?;
        self.head.forward(&h.reshape((batch, (s.horizon + 2) * s.width))?)
    }
}
