//! Manual diagnostic: which quantization point dominates the int8 error of a real MLP student.
//! FRMD_CKPT=dir (with calibration.safetensors) cargo test -p frmd-export --test quant_error_sources -- --ignored --nocapture
use frmd_core::policy::Network;

#[test]
#[ignore]
fn input_quantization_share_of_the_error() {
    let Ok(dir) = std::env::var("FRMD_CKPT") else {
        return;
    };
    let options = frmd_export::ExportOptions {
        activations: Some(frmd_export::Activations::Int8),
        ..Default::default()
    };
    let student = frmd_export::export(std::path::Path::new(&dir), &options, None).unwrap();
    let exported = student.mlp().expect("an MLP student");
    let set = student.calibration();
    let (folded, policy) = (&exported.folded, &exported.policy);
    let mut net = frmd_export::mlp::reference::quantized_network::<i8, 1024>(policy).unwrap();
    let (mut err_int8, mut err_input_only, mut n) = (0f64, 0f64, 0usize);
    for row in 0..set.rows() {
        let mut input = Vec::new();
        let noise = set.noise(row, 1, folded.base.config.traj_dim());
        student
            .sample_f32(set.row(row), &noise, |_, v| input = v.to_vec())
            .unwrap();
        let float = folded.forward_observed(0, &input, |_, _| {}).unwrap();
        let mut out = vec![0f32; float.len()];
        net.forward(0, &input, &mut out).unwrap();
        let fq: Vec<f32> = input
            .iter()
            .map(|&v| policy.input.dequantize(policy.input.quantize(v)))
            .collect();
        let float_fq = folded.forward_observed(0, &fq, |_, _| {}).unwrap();
        for ((f, q), g) in float.iter().zip(&out).zip(&float_fq) {
            err_int8 += f64::from((f - q).abs());
            err_input_only += f64::from((f - g).abs());
            n += 1;
        }
    }
    eprintln!(
        "input scale {} zp {}: mean |param error| int8 {:.5}, input fake-quant only {:.5}",
        policy.input.scale,
        policy.input.zero_point,
        err_int8 / n as f64,
        err_input_only / n as f64
    );
}
