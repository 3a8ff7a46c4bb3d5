//! The transformer exporter with int16 activations (the 16x8 scheme): closer to the f32 model
//! than int8 on the same rows (about half the error on this random student: the int8 weights,
//! the same in both, keep the rest), its blob loads only with the int16 loader and runs bit-exact with
//! the exporter's model, its layers match the wide-integer model, and an int8 blob of format 4
//! (before the activation trailer) still loads.

use super::tests::{calibration_set, chunk_error, exported_lite_as, lite_config, step_inputs};
use super::*;
use crate::host::{HostWork, MAX_WIDTH};
use frmd_core::blob::{
    crc32, AlignedBlob, BlobError, LoadedBlob, LoadedTransformer, LoadedTransformer16,
    FORMAT_VERSION, HEADER_LEN, SECTION_ALIGN,
};
use frmd_core::policy::Network;

/// The int8 and int16 (headroom 1.5) exports of one random transformer-lite student (`steps`
/// steps, the same checkpoint and calibration), with its normalization and directory.
fn both(
    name: &str,
    steps: usize,
) -> (
    QuantizedTransformer<i8>,
    QuantizedTransformer<i16>,
    Normalization,
    PathBuf,
) {
    let (int8, _, _) = exported_lite_as::<i8>(name, steps, 1.0);
    let (int16, norm, dir) = exported_lite_as::<i16>(name, steps, 1.5);
    (int8, int16, norm, dir)
}

#[test]
fn int16_chunk_tracks_f32_closer_than_int8() {
    let (int8, int16, _norm, dir) = both("int16-chunk", 1);
    let held_out = calibration_set(&lite_config(), 16, 99);
    let error8 = chunk_error(&int8, &held_out);
    let error16 = chunk_error(&int16, &held_out);
    error16.assert_tracks("transformer-lite int16, 1 step", "normalized units");
    println!(
        "mean error int8 {:.5}, int16 {:.5}",
        error8.mean(),
        error16.mean()
    );
    assert!(
        error16.mean() < 0.75 * error8.mean() && error16.max < error8.max,
        "int16 (mean {}, max {}) is not closer to f32 than int8 (mean {}, max {})",
        error16.mean(),
        error16.max,
        error8.mean(),
        error8.max
    );
    std::fs::remove_dir_all(&dir).unwrap();
}

#[test]
fn int16_blob_round_trip_is_bit_exact_and_loaders_check_the_precision() {
    let (int8, int16, norm, dir) = both("int16-blob", 2);
    let bytes = int16.blob(&norm).unwrap();
    let aligned = AlignedBlob::new(&bytes);
    assert_eq!(
        LoadedTransformer::load(aligned.bytes()).err(),
        Some(BlobError::ActivationBits { found: 16 })
    );
    let int8_bytes = int8.blob(&norm).unwrap();
    let int8_aligned = AlignedBlob::new(&int8_bytes);
    assert_eq!(
        LoadedTransformer16::load(int8_aligned.bytes()).err(),
        Some(BlobError::ActivationBits { found: 8 })
    );
    let any = LoadedBlob::load(aligned.bytes()).unwrap();
    assert!(matches!(any, LoadedBlob::Transformer16(_)));
    assert_eq!(any.activation_bits(), 16);
    let mut work = HostWork::new();
    let mut network = any.network::<MAX_WIDTH, _>(&mut work).unwrap();
    assert_eq!(network.num_noise_variants(), 2);
    for (i, input) in step_inputs(&int16.folded, 8).iter().enumerate() {
        let mut out = vec![0.0; lite_config().output_dim()];
        network.forward(i, input, &mut out).unwrap();
        assert_eq!(out, int16.forward(i, input).unwrap(), "step {i}");
        assert_ne!(
            out,
            int8.forward(i, input).unwrap(),
            "step {i}: int8 gave the same bits"
        );
    }
    // Damage is named as for int8: a weight of -128 breaks the int64 accumulators' exactness.
    let mut bad = int16.clone();
    bad.blocks[0].fc2.weights[5] = i8::MIN;
    let bad_bytes = bad.blob(&norm).unwrap();
    let err = LoadedTransformer16::load(AlignedBlob::new(&bad_bytes).bytes()).err();
    assert!(
        matches!(
            err,
            Some(BlobError::Transformer(
                frmd_core::model::transformer::TransformerError::Weights {
                    part: frmd_core::model::transformer::Part::Fc2 { layer: 0 },
                    error: frmd_core::kernels::KernelError::WeightRange,
                }
            ))
        ),
        "{err:?}"
    );
    std::fs::remove_dir_all(&dir).unwrap();
}

#[test]
fn int16_layers_match_the_wide_model_and_the_check_sees_an_overflowing_bias() {
    let (_int8, int16, _norm, dir) = both("int16-layers", 1);
    let check = reference::check_layers(&int16, 4, 1).unwrap();
    assert_eq!(check.mismatches, 0, "{:?}", check.first_mismatch);
    assert_eq!(check.cases, (3 + 5 * int16.blocks.len() as u64) * 8);
    // A bias beyond the int64 accumulators' domain is refused before anything runs.
    let mut huge = int16.clone();
    huge.head.bias[0] = i64::MAX;
    assert!(huge
        .view(&huge.quant_blocks(), 0)
        .unwrap()
        .validate()
        .is_err());
    let check = reference::check_layers(&huge, 1, 1).unwrap();
    assert!(
        check.mismatches >= 1,
        "an overflowing bias was not detected"
    );
    assert!(check.first_mismatch.unwrap().starts_with("head"));
    std::fs::remove_dir_all(&dir).unwrap();
}

/// `bytes` as format 4 wrote it: no activation trailer (its last descriptor byte) and version 4.
fn without_trailer(bytes: &[u8]) -> Vec<u8> {
    let desc_len = u32::from_le_bytes(bytes[16..20].try_into().unwrap()) as usize;
    let align = |n: usize| n.div_ceil(SECTION_ALIGN) * SECTION_ALIGN;
    let data = &bytes[align(HEADER_LEN + desc_len)..];
    let mut out = bytes[..HEADER_LEN + desc_len - 1].to_vec();
    out.resize(align(HEADER_LEN + desc_len - 1), 0);
    out.extend_from_slice(data);
    out[4..6].copy_from_slice(&4_u16.to_le_bytes());
    let total = out.len() as u32;
    out[8..12].copy_from_slice(&total.to_le_bytes());
    out[16..20].copy_from_slice(&((desc_len - 1) as u32).to_le_bytes());
    let crc = crc32::crc32(&out[HEADER_LEN..]);
    out[12..16].copy_from_slice(&crc.to_le_bytes());
    out
}

#[test]
fn format_4_transformer_blob_reads_as_int8() {
    assert_eq!(FORMAT_VERSION, 5);
    let (int8, int16, norm, dir) = both("int16-v4", 1);
    let old = without_trailer(&int8.blob(&norm).unwrap());
    let aligned = AlignedBlob::new(&old);
    let loaded = LoadedBlob::load(aligned.bytes()).unwrap();
    assert_eq!(loaded.activation_bits(), 8);
    // An int16 blob without its trailer would be read as int8 and refused by its sections.
    let old16 = without_trailer(&int16.blob(&norm).unwrap());
    assert!(LoadedBlob::load(AlignedBlob::new(&old16).bytes()).is_err());
    // A version 5 blob must carry the trailer.
    let mut untrailed = old.clone();
    untrailed[4..6].copy_from_slice(&5_u16.to_le_bytes());
    let crc = crc32::crc32(&untrailed[HEADER_LEN..]);
    untrailed[12..16].copy_from_slice(&crc.to_le_bytes());
    assert_eq!(
        LoadedBlob::load(AlignedBlob::new(&untrailed).bytes()).err(),
        Some(BlobError::Descriptor)
    );
    std::fs::remove_dir_all(&dir).unwrap();
}
