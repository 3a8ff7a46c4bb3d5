//! The fuzz targets' entry points (frmd-host/fuzz: `CheckpointMeta::from_json` for `frmd.json`,
//! `Dataset::from_bytes` for demonstration files) on a few thousand deterministic mutations of
//! valid inputs: byte flips, truncations, insertions and, for the JSON, every kind of value put
//! into a random field. Each must give `Ok` or an error, never a panic; a config that validates
//! must not imply more than bounded sizes.
use frmd_core::rng::Rng;
use frmd_core::sigma::SigmaConfig;
use frmd_formats::checkpoint::{expected_tensors, CheckpointMeta, Role};
use frmd_host::data::{ActionBeforeStart, Dataset, Normalization, Normalizer};
use frmd_host::models::{BackboneConfig, HeadConfig, ModelConfig};
use serde_json::{json, Value};

/// Index below `n` (n > 0).
fn below(rng: &mut Rng, n: usize) -> usize {
    (rng.next_u32() as usize) % n
}

/// One byte-level mutation of `bytes`.
fn mutate_bytes(rng: &mut Rng, bytes: &[u8]) -> Vec<u8> {
    let mut out = bytes.to_vec();
    for _ in 0..=below(rng, 3) {
        if out.is_empty() {
            break;
        }
        let at = below(rng, out.len());
        match below(rng, 5) {
            0 => out[at] ^= 1 << below(rng, 8),
            1 => out[at] = rng.next_u32() as u8,
            2 => out.truncate(at),
            3 => out.insert(at, rng.next_u32() as u8),
            _ => {
                let len = below(rng, 8).min(out.len() - at);
                out.drain(at..at + len);
            }
        }
    }
    out
}

/// Values that stress a config field.
fn odd_value(rng: &mut Rng) -> Value {
    let choices = [
        json!(0),
        json!(-1),
        json!(1),
        json!(3),
        json!(u64::MAX),
        json!(1u64 << 40),
        json!(-1e308),
        json!(1e308),
        json!(1e38),
        json!(0.5),
        json!(""),
        json!("mlp"),
        json!(null),
        json!([]),
        json!([0, 0]),
        json!({}),
        json!(true),
    ];
    choices[below(rng, choices.len())].clone()
}

/// Replaces one random leaf of `value` (objects and arrays walked at random) with an odd value.
fn mutate_leaf(rng: &mut Rng, value: &mut Value) {
    match value {
        Value::Object(map) if !map.is_empty() => {
            let key = map
                .keys()
                .nth(below(rng, map.len()))
                .cloned()
                .unwrap_or_default();
            if below(rng, 4) == 0 {
                map.insert(key, odd_value(rng));
            } else if let Some(child) = map.get_mut(&key) {
                mutate_leaf(rng, child);
            }
        }
        Value::Array(items) if !items.is_empty() => {
            let at = below(rng, items.len());
            mutate_leaf(rng, &mut items[at]);
        }
        leaf => *leaf = odd_value(rng),
    }
}

fn valid_meta(transformer: bool) -> CheckpointMeta {
    let backbone = if transformer {
        BackboneConfig::Transformer {
            layers: 1,
            heads: 2,
            width: 8,
        }
    } else {
        BackboneConfig::parse("mlp:16").unwrap()
    };
    let model = ModelConfig {
        obs_dim: 3,
        history: 2,
        action_dim: 2,
        horizon: 6,
        control_dt: 0.1,
        embed_dim: 4,
        backbone,
        head: HeadConfig::prodmp(3),
    };
    let mut meta = CheckpointMeta::describe(Role::Student, &model, SigmaConfig::default());
    meta.normalization = Some(Normalization {
        obs: Normalizer {
            min: vec![-1.0; 3],
            max: vec![1.0; 3],
        },
        action: Normalizer {
            min: vec![0.0; 2],
            max: vec![2.0; 2],
        },
    });
    meta
}

fn check_meta(bytes: &[u8]) {
    if let Ok(meta) = CheckpointMeta::from_json(bytes) {
        let tensors = expected_tensors(&meta.model);
        assert!(tensors.len() < 10_000);
        let _ = meta.model.prodmp();
    }
}

#[test]
fn checkpoint_config_mutations_never_panic() {
    let mut rng = Rng::new(14);
    for transformer in [false, true] {
        let meta = valid_meta(transformer);
        let text = serde_json::to_vec_pretty(&meta).unwrap();
        assert!(CheckpointMeta::from_json(&text).is_ok());
        let value = serde_json::to_value(&meta).unwrap();
        for _ in 0..1500 {
            check_meta(&mutate_bytes(&mut rng, &text));
            let mut edited = value.clone();
            for _ in 0..=below(&mut rng, 2) {
                mutate_leaf(&mut rng, &mut edited);
            }
            check_meta(&serde_json::to_vec(&edited).unwrap());
        }
        for len in 0..text.len() {
            check_meta(&text[..len]);
        }
    }
}

#[test]
fn dataset_reader_mutations_never_panic() {
    let data = Dataset {
        obs: (0..30).map(|i| i as f32 * 0.1).collect(),
        action: (0..20).map(|i| i as f32 * -0.2).collect(),
        episode_ends: vec![4, 10],
        obs_dim: 3,
        action_dim: 2,
        task: "reach".into(),
        dt: 0.1,
        source: "test".into(),
        action_before_start: ActionBeforeStart::Zero,
        extra: Default::default(),
    };
    let bytes = data.to_bytes().unwrap();
    assert_eq!(Dataset::from_bytes(&bytes).unwrap(), data);
    let mut rng = Rng::new(4);
    let read = |b: &[u8]| {
        if let Ok(d) = Dataset::from_bytes(b) {
            let _ = d.episode_ranges();
            let _ = d.windows(2, 4);
        }
    };
    for _ in 0..3000 {
        read(&mutate_bytes(&mut rng, &bytes));
    }
    for len in 0..bytes.len() {
        read(&bytes[..len]);
    }
    // The header's shapes and offsets, edited as JSON (the safetensors header is JSON after an
    // 8-byte length).
    let header_len = u64::from_le_bytes(bytes[..8].try_into().unwrap()) as usize;
    let header: Value = serde_json::from_slice(&bytes[8..8 + header_len]).unwrap();
    for _ in 0..1500 {
        let mut edited = header.clone();
        mutate_leaf(&mut rng, &mut edited);
        let text = serde_json::to_vec(&edited).unwrap();
        let mut file = (text.len() as u64).to_le_bytes().to_vec();
        file.extend_from_slice(&text);
        file.extend_from_slice(&bytes[8 + header_len..]);
        read(&file);
    }
}
