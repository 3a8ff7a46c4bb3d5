//! Seeded, order-independent initialization of every variable, and value copies / EMA updates
//! between variable maps of the same architecture.
use crate::rng::HostRng;
use anyhow::{bail, Context};
use candle_core::Tensor;
use candle_nn::VarMap;

/// Variables of a map, sorted by name.
pub fn sorted_vars(varmap: &VarMap) -> Vec<(String, candle_core::Var)> {
    let data = varmap.data().lock().expect("VarMap lock poisoned");
    let mut vars: Vec<_> = data.iter().map(|(k, v)| (k.clone(), v.clone())).collect();
    vars.sort_by(|a, b| a.0.cmp(&b.0));
    vars
}

/// Sets every variable from a stream derived from (`seed`, its name), so values do not depend
/// on construction order. Rules by name and rank: rank-2 `*.weight` ~ U(-1/sqrt(fan_in), +);
/// rank-1 `*.bias` = 0; rank-1 `*.weight` (LayerNorm gain) = 1; `*pos_embedding` ~ 0.02 N(0, 1).
pub fn init_seeded(varmap: &VarMap, seed: u64) -> anyhow::Result<()> {
    for (name, var) in sorted_vars(varmap) {
        let dims = var.dims().to_vec();
        let count: usize = dims.iter().product();
        let mut rng = HostRng::derive(seed, &name);
        let values: Vec<f32> = if name.ends_with("pos_embedding") {
            (0..count).map(|_| 0.02 * rng.normal() as f32).collect()
        } else if name.ends_with(".weight") && dims.len() == 2 {
            let bound = 1.0 / (dims[1] as f64).sqrt();
            (0..count)
                .map(|_| ((2.0 * rng.uniform() - 1.0) * bound) as f32)
                .collect()
        } else if name.ends_with(".bias") && dims.len() == 1 {
            vec![0.0; count]
        } else if name.ends_with(".weight") && dims.len() == 1 {
            vec![1.0; count]
        } else {
            bail!("no initialization rule for variable `{name}` with shape {dims:?}");
        };
        let tensor = Tensor::from_vec(values, dims.as_slice(), var.device())?;
        var.set(&tensor)
            .with_context(|| format!("initializing `{name}`"))?;
    }
    Ok(())
}

/// Copies every variable of `from` into the same-named variable of `to` (names must match).
pub fn copy_values(from: &VarMap, to: &VarMap) -> anyhow::Result<()> {
    ema_update(to, from, 0.0)
}

/// `target <- mu * target + (1 - mu) * source`, variable by variable.
pub fn ema_update(target: &VarMap, source: &VarMap, mu: f64) -> anyhow::Result<()> {
    let sources = sorted_vars(source);
    let targets = sorted_vars(target);
    if sources.len() != targets.len() {
        bail!(
            "EMA: {} source variables vs {} target variables",
            sources.len(),
            targets.len()
        );
    }
    for ((sname, svar), (tname, tvar)) in sources.iter().zip(&targets) {
        if sname != tname {
            bail!("EMA: variable names differ (`{sname}` vs `{tname}`)");
        }
        let value = if mu == 0.0 {
            svar.as_tensor().copy()?
        } else {
            ((tvar.as_tensor() * mu)? + (svar.as_tensor() * (1.0 - mu))?)?
        };
        tvar.set(&value.detach())?;
    }
    Ok(())
}
