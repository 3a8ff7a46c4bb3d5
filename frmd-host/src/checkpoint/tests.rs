use super::*;
use crate::data::toy::{toy_config, toy_prodmp_config};
use crate::models::{HeadConfig, OwnedNetwork};
use frmd_core::sigma::SigmaConfig;

fn temp_dir(tag: &str) -> std::path::PathBuf {
    let dir = std::env::temp_dir().join(format!("frmd-ckpt-{tag}-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    dir
}

fn saved(tag: &str) -> (std::path::PathBuf, CheckpointMeta, OwnedNetwork) {
    let cfg = toy_prodmp_config();
    let net = OwnedNetwork::new_seeded(&cfg, 21, &Device::Cpu).unwrap();
    let meta = CheckpointMeta::describe(Role::Student, net.net.config(), SigmaConfig::default());
    let dir = temp_dir(tag);
    save(&dir, &meta, &net).unwrap();
    (dir, meta, net)
}

#[test]
fn round_trip_is_bit_identical() {
    let (dir, meta, net) = saved("roundtrip");
    let (meta2, net2) = load(&dir).unwrap();
    assert_eq!(meta, meta2);
    for ((n1, v1), (n2, v2)) in sorted_vars(&net.varmap)
        .iter()
        .zip(sorted_vars(&net2.varmap).iter())
    {
        assert_eq!(n1, n2);
        let bits = |v: &candle_core::Var| -> Vec<u32> {
            let values = v.flatten_all().unwrap().to_vec1::<f32>().unwrap();
            values.iter().map(|v| v.to_bits()).collect()
        };
        let (a, b) = (bits(v1), bits(v2));
        assert_eq!(a, b, "{n1}");
    }
    let dir2 = temp_dir("roundtrip2");
    save(&dir2, &meta2, &net2).unwrap();
    assert_eq!(
        std::fs::read(dir.join(WEIGHTS_FILE)).unwrap(),
        std::fs::read(dir2.join(WEIGHTS_FILE)).unwrap()
    );
    assert_eq!(
        std::fs::read(dir.join(CONFIG_FILE)).unwrap(),
        std::fs::read(dir2.join(CONFIG_FILE)).unwrap()
    );
}

fn load_err(dir: &std::path::Path) -> String {
    format!("{:#}", load(dir).err().expect("load should fail"))
}

#[test]
fn corrupted_or_mismatched_checkpoints_are_rejected_with_a_reason() {
    // Truncated weights file.
    let (dir, meta, _) = saved("trunc");
    let bytes = std::fs::read(dir.join(WEIGHTS_FILE)).unwrap();
    std::fs::write(dir.join(WEIGHTS_FILE), &bytes[..bytes.len() / 2]).unwrap();
    assert!(
        load_err(&dir).contains("not a valid safetensors"),
        "{}",
        load_err(&dir)
    );

    // Config claims a different hidden width: the shape mismatch names the tensor.
    let (dir, mut meta2, _) = saved("shape");
    if let crate::models::BackboneConfig::Mlp { hidden, .. } = &mut meta2.model.backbone {
        hidden[0] = 32;
    }
    meta2.tensors = expected_tensors(&meta2.model);
    std::fs::write(
        dir.join(CONFIG_FILE),
        serde_json::to_string(&meta2).unwrap(),
    )
    .unwrap();
    let err = load_err(&dir);
    assert!(
        err.contains("mlp.layers.0.bias") && err.contains("shape"),
        "{err}"
    );

    // A tensor renamed in the weights file.
    let (dir, _, net) = saved("rename");
    let mut map: std::collections::HashMap<String, Tensor> = sorted_vars(&net.varmap)
        .into_iter()
        .map(|(n, v)| (n, v.as_tensor().clone()))
        .collect();
    let t = map.remove("mlp.layers.1.weight").unwrap();
    map.insert("mlp.layers.1.weights".into(), t);
    candle_core::safetensors::save(&map, dir.join(WEIGHTS_FILE)).unwrap();
    let err = load_err(&dir);
    assert!(
        err.contains("missing tensors [\"mlp.layers.1.weight\"]")
            && err.contains("mlp.layers.1.weights"),
        "{err}"
    );

    // Wrong dtype.
    let (dir, _, net) = saved("dtype");
    let map: std::collections::HashMap<String, Tensor> = sorted_vars(&net.varmap)
        .into_iter()
        .map(|(n, v)| {
            let t = v.as_tensor().clone();
            let t = if n == "mlp.layers.0.weight" {
                t.to_dtype(candle_core::DType::F16).unwrap()
            } else {
                t
            };
            (n, t)
        })
        .collect();
    candle_core::safetensors::save(&map, dir.join(WEIGHTS_FILE)).unwrap();
    let err = load_err(&dir);
    assert!(
        err.contains("mlp.layers.0.weight") && err.contains("F16"),
        "{err}"
    );

    // Unsupported version and a ProDMP config that does not match the model.
    let (dir, mut meta3, _) = saved("version");
    meta3.format_version = 99;
    std::fs::write(
        dir.join(CONFIG_FILE),
        serde_json::to_string(&meta3).unwrap(),
    )
    .unwrap();
    assert!(load_err(&dir).contains("format_version 99"));
    let mut meta4 = meta.clone();
    meta4.prodmp.as_mut().unwrap().alpha = 10.0;
    std::fs::write(
        dir.join(CONFIG_FILE),
        serde_json::to_string(&meta4).unwrap(),
    )
    .unwrap();
    assert!(load_err(&dir).contains("prodmp.alpha is 10"));
    // Missing config file.
    std::fs::remove_file(dir.join(CONFIG_FILE)).unwrap();
    assert!(load_err(&dir).contains("frmd.json"));
}

/// The exporter's candle-free list of variables equals the candle models' `VarMap`.
#[test]
fn expected_tensors_match_the_candle_models() {
    use crate::models::{BackboneConfig, ModelConfig};
    for backbone in ["mlp:16,8:silu", "mlp:12", "transformer-lite"] {
        let mut cfg: ModelConfig = toy_config(HeadConfig::prodmp(3));
        cfg.backbone = BackboneConfig::parse(backbone).unwrap();
        if backbone.starts_with("transformer") {
            cfg.backbone = BackboneConfig::Transformer {
                layers: 2,
                heads: 2,
                width: 8,
            };
        }
        let net = OwnedNetwork::new_seeded(&cfg, 1, &Device::Cpu).unwrap();
        let candle: Vec<TensorSpec> = sorted_vars(&net.varmap)
            .into_iter()
            .map(|(name, var)| TensorSpec {
                name,
                dtype: "F32".into(),
                shape: var.dims().to_vec(),
            })
            .collect();
        assert_eq!(expected_tensors(&cfg), candle, "{backbone}");
    }
}

/// `prodmp` and `sigma` are frmd-core's configs serialized as they are: a checkpoint written
/// before that (the firmware's checked-in student) reads, and the two sections re-serialize to
/// the same bytes.
#[test]
fn existing_checkpoints_read_and_keep_their_prodmp_and_sigma_bytes() {
    let dir =
        std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("../examples/cortex-m/policy/reach");
    let text = std::fs::read_to_string(dir.join(CONFIG_FILE)).unwrap();
    let meta = CheckpointMeta::read(&dir).unwrap();
    assert_eq!(meta.sigma, SigmaConfig::default());
    let section = |json: &str, key: &str| {
        let start = json
            .find(&format!("\n  \"{key}\": {{"))
            .unwrap_or_else(|| panic!("no {key} in {json}"));
        let end = start + json[start..].find("\n  }").unwrap();
        json[start..end].to_string()
    };
    let written = serde_json::to_string_pretty(&meta).unwrap();
    for key in ["prodmp", "sigma"] {
        assert_eq!(section(&written, key), section(&text, key), "{key}");
    }
}
