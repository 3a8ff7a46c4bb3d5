//! The boundary-skip parametrization keeps the ProDMP initial condition and is the identity at
//! sigma_min; the direct one is unchanged.
use super::*;
use crate::data::toy::toy_config;
use crate::models::decoder::ProDmpDecoder;
use crate::models::{HeadConfig, OwnedNetwork};
use crate::rng::HostRng;
use candle_core::Device;

const BATCH: usize = 6;

fn setup(output: ProDmpOutput) -> (OwnedNetwork, ProDmpDecoder, Condition, Tensor, Tensor) {
    let cfg = toy_config(HeadConfig::ProDmp {
        num_basis: 4,
        output,
        auto_scale_basis: true,
    });
    let net = OwnedNetwork::new_seeded(&cfg, 7, &Device::Cpu).unwrap();
    let decoder = ProDmpDecoder::new(&cfg.prodmp().unwrap(), cfg.horizon, &Device::Cpu).unwrap();
    let mut rng = HostRng::new(21);
    let mut draw = |cols: usize| {
        crate::diffusion::samplers::gaussian(&mut rng, BATCH, cols, &Device::Cpu).unwrap()
    };
    let (obs, y0, v0) = (draw(cfg.obs_dim), draw(1), draw(1));
    let weights = draw(cfg.output_dim());
    let cond = Condition::new(&obs, y0, v0, cfg.control_dt).unwrap();
    // A chunk in the ProDMP span of this condition: x = G(w; y0, v0).
    let x = decoder.decode(&weights, &cond.y0, &cond.v0).unwrap();
    (net, decoder, cond, weights, x)
}

fn max_abs_diff(a: &Tensor, b: &Tensor) -> f32 {
    (a - b)
        .unwrap()
        .abs()
        .unwrap()
        .flatten_all()
        .unwrap()
        .max(0)
        .unwrap()
        .to_scalar::<f32>()
        .unwrap()
}

/// With x = G(w; y0, v0), the skip output is G(c_skip w + c_out E; y0, v0): a ProDMP trajectory
/// with the condition's y0 and v0, whatever sigma (E = the network's raw parameters).
fn check_keeps_initial_condition(teacher: bool) {
    let (net, decoder, cond, w, x) = setup(ProDmpOutput::BoundarySkip);
    let sig = SigmaConfig::default();
    for sigma in [sig.sigma_min, 0.01, 0.3, 2.0, sig.sigma_max] {
        let sigmas = [sigma; BATCH];
        let out = if teacher {
            teacher_denoise(&net.net, &sig, &x, &cond, &sigmas)
        } else {
            consistency(&net.net, &sig, &x, &cond, &sigmas)
        }
        .unwrap();
        let (c_in, emb) =
            noise_inputs(&sig, &sigmas, net.net.config().embed_dim, &Device::Cpu).unwrap();
        let raw = net
            .net
            .raw_output(&x.broadcast_mul(&c_in).unwrap(), &cond, &emb)
            .unwrap();
        let (c_skip, c_out) = if teacher {
            (
                sig.edm_c_skip(sigma).unwrap(),
                sig.edm_c_out(sigma).unwrap(),
            )
        } else {
            (sig.c_skip(sigma).unwrap(), sig.c_out(sigma).unwrap())
        };
        let params = ((&w * c_skip).unwrap() + (raw * c_out).unwrap()).unwrap();
        let expected = decoder.decode(&params, &cond.y0, &cond.v0).unwrap();
        let err = max_abs_diff(&out, &expected);
        assert!(
            err <= 1e-4,
            "sigma {sigma}: output differs from G(c_skip w + c_out E; y0, v0) by {err}"
        );
    }
}

#[test]
fn boundary_skip_teacher_keeps_the_initial_condition() {
    check_keeps_initial_condition(true);
}

#[test]
fn boundary_skip_student_keeps_the_initial_condition() {
    check_keeps_initial_condition(false);
}

#[test]
fn boundary_skip_student_is_the_identity_at_sigma_min() {
    let (net, _, cond, _, x) = setup(ProDmpOutput::BoundarySkip);
    let sig = SigmaConfig::default();
    let out = consistency(&net.net, &sig, &x, &cond, &[sig.sigma_min; BATCH]).unwrap();
    assert_eq!(out.to_vec2::<f32>().unwrap(), x.to_vec2::<f32>().unwrap());
    // Any chunk, not only those in the span of this condition.
    let noise = (&x * 3.0).unwrap().sin().unwrap();
    let out = consistency(&net.net, &sig, &noise, &cond, &[sig.sigma_min; BATCH]).unwrap();
    assert_eq!(
        out.to_vec2::<f32>().unwrap(),
        noise.to_vec2::<f32>().unwrap()
    );
    // Above sigma_min the network contributes.
    let out = consistency(&net.net, &sig, &x, &cond, &[0.5; BATCH]).unwrap();
    assert!(max_abs_diff(&out, &x) > 1e-3);
}

#[test]
fn direct_output_is_the_decoded_trajectory() -> anyhow::Result<()> {
    let (net, _, cond, _, x) = setup(ProDmpOutput::Direct);
    let sig = SigmaConfig::default();
    let sigmas = [0.7; BATCH];
    let g = decoded(&net.net, &sig, &x, &cond, &sigmas)?.to_vec2::<f32>()?;
    let denoised = teacher_denoise(&net.net, &sig, &x, &cond, &sigmas)?;
    assert_eq!(denoised.to_vec2::<f32>()?, g);
    let consistent = consistency(&net.net, &sig, &x, &cond, &sigmas)?;
    assert_eq!(consistent.to_vec2::<f32>()?, g);
    Ok(())
}
