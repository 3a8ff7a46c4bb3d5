//! The matmul-with-ones transformer against the plain broadcast form it replaces
//! (`candle_nn::Linear`, `ops::layer_norm_slow`, `ops::softmax`) over the same variables: same
//! values, same gradients, and every parameter receives a gradient.
use super::*;
use crate::models::init::{init_seeded, sorted_vars};
use crate::rng::HostRng;
use candle_core::{Device, Module};
use candle_nn::VarMap;
use std::collections::HashMap;

fn sizes() -> TransformerSizes {
    TransformerSizes {
        layers: 2,
        heads: 2,
        width: 16,
        horizon: 5,
        action_dim: 3,
        cond_dim: 7,
        embed_dim: 4,
        output: 9,
    }
}

/// The broadcast-form forward pass (the previous implementation), reading the same variables.
fn reference_forward(
    vars: &HashMap<String, Tensor>,
    s: &TransformerSizes,
    x: &Tensor,
    cond: &Tensor,
    emb: &Tensor,
) -> Result<Tensor> {
    let get = |name: &str| {
        vars.get(&format!("transformer.{name}"))
            .cloned()
            .expect("variable")
    };
    let linear = |name: &str| {
        candle_nn::Linear::new(
            get(&format!("{name}.weight")),
            Some(get(&format!("{name}.bias"))),
        )
    };
    let norm = |name: &str, xs: &Tensor| {
        candle_nn::ops::layer_norm_slow(
            xs,
            &get(&format!("{name}.weight")),
            &get(&format!("{name}.bias")),
            1e-5,
        )
    };
    let batch = x.dim(0)?;
    let steps = linear("traj_in").forward(&x.reshape((batch, s.horizon, s.action_dim))?)?;
    let cond_token = linear("cond_in").forward(cond)?.unsqueeze(1)?;
    let noise_token = linear("noise_in").forward(emb)?.unsqueeze(1)?;
    let mut h = Tensor::cat(&[&cond_token, &noise_token, &steps], 1)?
        .broadcast_add(&get("pos_embedding"))?;
    let head_dim = s.width / s.heads;
    for i in 0..s.layers {
        let p = format!("blocks.{i}");
        let (b, t, w) = h.dims3()?;
        let qkv = linear(&format!("{p}.qkv")).forward(&norm(&format!("{p}.norm1"), &h)?)?;
        let qkv = qkv
            .reshape((b, t, 3, s.heads, head_dim))?
            .permute((2, 0, 3, 1, 4))?;
        let (q, k, v) = (
            qkv.get(0)?.contiguous()?,
            qkv.get(1)?.contiguous()?,
            qkv.get(2)?.contiguous()?,
        );
        let scores = (q.matmul(&k.t()?)? / (head_dim as f64).sqrt())?;
        let attn = candle_nn::ops::softmax(&scores, D::Minus1)?.matmul(&v)?;
        let attn = attn.transpose(1, 2)?.reshape((b, t, w))?;
        h = (&h + linear(&format!("{p}.proj")).forward(&attn)?)?;
        let hidden =
            gelu_sigmoid(&linear(&format!("{p}.fc1")).forward(&norm(&format!("{p}.norm2"), &h)?)?)?;
        h = (&h + linear(&format!("{p}.fc2")).forward(&hidden)?)?;
    }
    let h = norm("final_norm", &h)?;
    linear("head").forward(&h.reshape((batch, (s.horizon + 2) * s.width))?)
}

fn random(shape: (usize, usize), rng: &mut HostRng) -> Tensor {
    let values: Vec<f32> = (0..shape.0 * shape.1)
        .map(|_| rng.normal() as f32)
        .collect();
    Tensor::from_vec(values, shape, &Device::Cpu).unwrap()
}

/// A transformer of [`sizes`] under `transformer.` in a fresh `VarMap`, seeded with `seed`.
fn seeded_model(seed: u64) -> anyhow::Result<(VarMap, Transformer)> {
    let varmap = VarMap::new();
    let vb = VarBuilder::from_varmap(&varmap, DType::F32, &Device::Cpu);
    let model = Transformer::new(&sizes(), vb.pp("transformer"))?;
    init_seeded(&varmap, seed)?;
    Ok((varmap, model))
}

/// The largest magnitude in `t`.
fn max_abs(t: &Tensor) -> Result<f32> {
    t.abs()?.max_all()?.to_scalar::<f32>()
}

#[test]
fn matches_the_broadcast_form_in_values_and_gradients() -> anyhow::Result<()> {
    let s = sizes();
    let (varmap, model) = seeded_model(3)?;
    // Non-trivial biases, gains and offsets (the seeded init sets them to 0 and 1).
    let mut rng = HostRng::derive(9, "transformer-test");
    for (name, var) in sorted_vars(&varmap) {
        if var.dims().len() == 1 {
            let n = var.dims()[0];
            let offset = if name.ends_with(".weight") { 1.0 } else { 0.0 };
            let values: Vec<f32> = (0..n).map(|_| offset + 0.3 * rng.normal() as f32).collect();
            var.set(&Tensor::from_vec(values, n, &Device::Cpu)?)?;
        }
    }
    let batch = 4;
    let x = random((batch, s.horizon * s.action_dim), &mut rng);
    let cond = random((batch, s.cond_dim), &mut rng);
    let emb = random((batch, s.embed_dim), &mut rng);
    let target = random((batch, s.output), &mut rng);
    let ours = model.forward(&x, &cond, &emb)?;
    let tensors: HashMap<String, Tensor> = sorted_vars(&varmap)
        .into_iter()
        .map(|(n, v)| (n, v.as_tensor().clone()))
        .collect();
    let reference = reference_forward(&tensors, &s, &x, &cond, &emb)?;
    let value_error = max_abs(&(&ours - &reference)?)?;
    let scale = max_abs(&reference)?;
    assert!(scale > 0.1, "degenerate output (max |y| = {scale})");
    assert!(
        value_error <= 2e-5 * scale,
        "forward differs by {value_error} (output scale {scale})"
    );

    let loss = |y: &Tensor| (y - &target)?.sqr()?.sum_all();
    let ours_grads = loss(&ours)?.backward()?;
    let reference_grads = loss(&reference)?.backward()?;
    let vars = sorted_vars(&varmap);
    assert_eq!(vars.len(), 5 * 2 + 2 * s.layers * 6 + 1, "variable count");
    for (name, var) in vars {
        let g = ours_grads
            .get(var.as_tensor())
            .unwrap_or_else(|| panic!("no gradient reaches `{name}`"));
        let r = reference_grads
            .get(var.as_tensor())
            .unwrap_or_else(|| panic!("reference: no gradient for `{name}`"));
        let norm = max_abs(r)?;
        let diff = max_abs(&(g - r)?)?;
        assert!(norm > 0.0, "`{name}` has an all-zero gradient");
        assert!(
            diff <= 1e-4 * norm,
            "`{name}`: gradient differs by {diff} (max |grad| {norm})"
        );
    }
    Ok(())
}

#[test]
fn batch_rows_do_not_interact() -> anyhow::Result<()> {
    // Row b of a batch equals the same input run alone (the ones-matmuls must not mix rows).
    let s = sizes();
    let (_varmap, model) = seeded_model(5)?;
    let mut rng = HostRng::derive(11, "rows");
    let x = random((3, s.horizon * s.action_dim), &mut rng);
    let cond = random((3, s.cond_dim), &mut rng);
    let emb = random((3, s.embed_dim), &mut rng);
    let all = model.forward(&x, &cond, &emb)?;
    for b in 0..3 {
        let one = model.forward(
            &x.narrow(0, b, 1)?,
            &cond.narrow(0, b, 1)?,
            &emb.narrow(0, b, 1)?,
        )?;
        let diff = max_abs(&(one - all.narrow(0, b, 1)?)?)?;
        assert!(diff < 1e-5, "row {b} differs by {diff}");
    }
    Ok(())
}
