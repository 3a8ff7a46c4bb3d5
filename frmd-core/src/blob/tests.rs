//! Blob tests: CRC, round trip through the policy, and rejection of every kind of damage by a
//! named error (never a panic).

extern crate std;

use std::{vec, vec::Vec};

use proptest::prelude::*;

use super::*;
use crate::policy::test_model::*;
use crate::policy::{Noise, PolicyError};
use crate::rng::Rng;

type Loaded<'a> = LoadedMlp<'a>;

fn blob_policy<'a>(loaded: &Loaded<'a>) -> Result<Int8Policy<'a>, PolicyError> {
    loaded.policy::<M, O, K, N, P, I, WIDTH>()
}

fn model_blob(model: &TestModel) -> Vec<u8> {
    let hidden = model.int8_layers();
    let parts = model.blob_parts(&hidden);
    let len = mlp_encoded_len(&parts).unwrap();
    let mut out = vec![0xAA_u8; len + 7];
    let written = encode_mlp(&parts, &mut out).unwrap();
    assert_eq!(written, len);
    assert!(
        out[len..].iter().all(|b| *b == 0xAA),
        "encode wrote past its length"
    );
    out.truncate(len);
    out
}

fn load(bytes: &[u8]) -> Result<Loaded<'_>, BlobError> {
    Loaded::load(bytes)
}

fn load_copy(bytes: &[u8]) -> Result<(), BlobError> {
    let buffer = AlignedBlob::new(bytes);
    load(buffer.bytes()).map(|_| ())
}

fn fix_crc(blob: &mut [u8]) {
    let crc = crc32::crc32(&blob[HEADER_LEN..]);
    blob[12..16].copy_from_slice(&crc.to_le_bytes());
}

fn descriptor_of(blob: &[u8]) -> MlpDescriptor {
    descriptor_parts(blob).0
}

/// The descriptor and, if there are bytes after it, its trailer.
fn descriptor_parts(blob: &[u8]) -> (MlpDescriptor, Option<MlpActivations>) {
    let len = u32::from_le_bytes(blob[16..20].try_into().unwrap()) as usize;
    let bytes = &blob[HEADER_LEN..HEADER_LEN + len];
    let (d, rest) = postcard::take_from_bytes::<MlpDescriptor>(bytes).unwrap();
    (
        d,
        (!rest.is_empty()).then(|| postcard::from_bytes(rest).unwrap()),
    )
}

/// Rewrites the descriptor (the data area moves if the descriptor length changes alignment).
fn with_descriptor(blob: &[u8], edit: impl FnOnce(&mut MlpDescriptor)) -> Vec<u8> {
    with_descriptor_parts(blob, |d, _| edit(d))
}

/// Rewrites the descriptor and its trailer (`None`: written without one).
fn with_descriptor_parts(
    blob: &[u8],
    edit: impl FnOnce(&mut MlpDescriptor, &mut Option<MlpActivations>),
) -> Vec<u8> {
    let old_len = u32::from_le_bytes(blob[16..20].try_into().unwrap()) as usize;
    let old_start = container::data_start(old_len).unwrap();
    let (mut d, mut trailer) = descriptor_parts(blob);
    edit(&mut d, &mut trailer);
    let mut scratch = [0_u8; 4096];
    let mut encoded = postcard::to_slice(&d, &mut scratch).unwrap().to_vec();
    if let Some(trailer) = &trailer {
        encoded.extend_from_slice(postcard::to_slice(trailer, &mut scratch).unwrap());
    }
    let start = container::data_start(encoded.len()).unwrap();
    let mut out = vec![0_u8; start];
    out[..HEADER_LEN].copy_from_slice(&blob[..HEADER_LEN]);
    out[HEADER_LEN..HEADER_LEN + encoded.len()].copy_from_slice(&encoded);
    out.extend_from_slice(&blob[old_start..]);
    let total = out.len() as u32;
    out[8..12].copy_from_slice(&total.to_le_bytes());
    out[16..20].copy_from_slice(&(encoded.len() as u32).to_le_bytes());
    fix_crc(&mut out);
    out
}

/// Overwrites bytes of the data area at `section.offset + at` and fixes the CRC.
fn poke(blob: &[u8], section: Section, at: usize, bytes: &[u8]) -> Vec<u8> {
    let mut out = blob.to_vec();
    let len = u32::from_le_bytes(blob[16..20].try_into().unwrap()) as usize;
    let start = container::data_start(len).unwrap() + section.offset as usize + at;
    out[start..start + bytes.len()].copy_from_slice(bytes);
    fix_crc(&mut out);
    out
}

#[test]
fn round_trip_gives_the_same_policy_bit_for_bit() {
    for sigmas in [&[80.0][..], &[80.0, 2.0, 0.3][..]] {
        let model = TestModel::new(21, sigmas);
        let blob = model_blob(&model);
        let buffer = AlignedBlob::new(&blob);
        let loaded = load(buffer.bytes()).unwrap();
        assert_eq!(loaded.steps(), &model.steps[..]);
        assert_eq!(
            loaded.decoder(),
            crate::policy::ProDmpTables::from_baked(&model.decoder)
        );
        assert_eq!(loaded.layout(), &model.layout);
        assert_eq!(loaded.control_dt(), DT);
        let mut from_blob = blob_policy(&loaded).unwrap();
        let mut direct = model.int8_policy();
        for policy_seed in 0..3 {
            from_blob.reset(&[0.0, 0.2]).unwrap();
            direct.reset(&[0.0, 0.2]).unwrap();
            for obs in [[0.1, 1.0, 2.0], [0.3, 2.0, 2.0]] {
                from_blob.observe(&obs).unwrap();
                direct.observe(&obs).unwrap();
            }
            let a = *from_blob
                .act(Noise::Rng(&mut Rng::new(policy_seed)))
                .unwrap();
            let b = *direct.act(Noise::Rng(&mut Rng::new(policy_seed))).unwrap();
            assert_eq!(a, b);
            assert_eq!(
                from_blob.network().accumulators(),
                direct.network().accumulators()
            );
        }
        // Trailing bytes (flash padding) are ignored.
        let mut padded = blob.clone();
        padded.extend_from_slice(&[0xFF; 40]);
        assert!(load_copy(&padded).is_ok());
    }
}

#[test]
fn truncation_at_every_length_is_rejected() {
    let model = TestModel::new(22, &[80.0, 1.0]);
    let blob = model_blob(&model);
    let buffer = AlignedBlob::new(&blob);
    let bytes = buffer.bytes();
    for len in 0..bytes.len() {
        assert_eq!(
            load(&bytes[..len]).err(),
            Some(BlobError::Truncated),
            "length {len}"
        );
    }
    assert!(load(bytes).is_ok());
}

#[test]
fn header_damage_is_named() {
    let model = TestModel::new(23, &[80.0]);
    let blob = model_blob(&model);
    let mut bad = blob.clone();
    bad[0] = b'G';
    assert_eq!(load_copy(&bad), Err(BlobError::BadMagic));
    let mut bad = blob.clone();
    // Version 1 (before the two-plane input flag) and a future version.
    for version in [1_u16, FORMAT_VERSION + 1] {
        bad[4..6].copy_from_slice(&version.to_le_bytes());
        assert_eq!(
            load_copy(&bad),
            Err(BlobError::UnsupportedVersion { found: version })
        );
    }
    // Versions 2 and 3 have no trailer (int8 activations, clamps in the layer descriptors);
    // version 2 stored the input precision as a bool, which encodes as the same byte.
    let untrailed = with_descriptor_parts(&blob, |_, trailer| *trailer = None);
    assert_eq!(MIN_FORMAT_VERSION, 2);
    for version in MIN_FORMAT_VERSION..mlp::ACTIVATIONS_SINCE {
        let mut old = untrailed.clone();
        old[4..6].copy_from_slice(&version.to_le_bytes());
        fix_crc(&mut old);
        assert!(load_copy(&old).is_ok());
        let mut with_trailer = blob.clone();
        with_trailer[4..6].copy_from_slice(&version.to_le_bytes());
        fix_crc(&mut with_trailer);
        assert_eq!(load_copy(&with_trailer), Err(BlobError::Descriptor));
    }
    // From version 4 the trailer is required and names the precision and every layer's clamps;
    // version 5 changed transformer blobs only, so a version 4 MLP blob reads as before.
    assert_eq!(load_copy(&untrailed), Err(BlobError::Descriptor));
    let mut four = blob.clone();
    four[4..6].copy_from_slice(&4_u16.to_le_bytes());
    fix_crc(&mut four);
    assert!(load_copy(&four).is_ok());
    let sixteen = with_descriptor_parts(&blob, |_, t| t.as_mut().unwrap().bits = 16);
    assert_eq!(
        load_copy(&sixteen),
        Err(BlobError::ActivationBits { found: 16 })
    );
    let short = with_descriptor_parts(&blob, |_, t| {
        t.as_mut().unwrap().clamps.pop();
    });
    assert_eq!(load_copy(&short), Err(BlobError::Descriptor));
    let mut bad = blob.clone();
    bad[6] = 1;
    assert_eq!(load_copy(&bad), Err(BlobError::ReservedField));
    let mut bad = blob.clone();
    bad[8..12].copy_from_slice(&3_u32.to_le_bytes());
    assert_eq!(load_copy(&bad), Err(BlobError::InvalidLength));
    let mut bad = blob.clone();
    bad[16..20].copy_from_slice(&(blob.len() as u32).to_le_bytes());
    assert_eq!(load_copy(&bad), Err(BlobError::InvalidLength));
    // Any flipped payload bit is caught by the CRC.
    for at in [HEADER_LEN, HEADER_LEN + 5, blob.len() / 2, blob.len() - 1] {
        let mut bad = blob.clone();
        bad[at] ^= 0x10;
        assert!(
            matches!(load_copy(&bad), Err(BlobError::CrcMismatch { .. })),
            "byte {at}"
        );
    }
    // A descriptor that is not postcard: all 0xFF bytes with a fixed CRC.
    let mut bad = blob.clone();
    let len = u32::from_le_bytes(blob[16..20].try_into().unwrap()) as usize;
    bad[HEADER_LEN..HEADER_LEN + len].fill(0xFF);
    fix_crc(&mut bad);
    assert_eq!(load_copy(&bad), Err(BlobError::Descriptor));
}

#[test]
fn dimension_mismatches_are_named() {
    let model = TestModel::new(24, &[80.0]);
    let blob = model_blob(&model);
    let buffer = AlignedBlob::new(&blob);
    let bytes = buffer.bytes();
    let expect = |dims: crate::policy::PolicyDims| load(bytes).unwrap().check_dims(&dims).err();
    assert_eq!(load(bytes).unwrap().dims(), DIMS);
    assert_eq!(load(bytes).unwrap().check_dims(&DIMS), Ok(()));
    use crate::policy::PolicyDims;
    for (dims, dimension) in [
        (PolicyDims { obs_dim: 4, ..DIMS }, Dimension::ObsDim),
        (PolicyDims { history: 3, ..DIMS }, Dimension::History),
        (
            PolicyDims {
                action_dim: 3,
                ..DIMS
            },
            Dimension::ActionDim,
        ),
        (PolicyDims { horizon: 5, ..DIMS }, Dimension::Horizon),
        (
            PolicyDims {
                params_per_dof: 5,
                ..DIMS
            },
            Dimension::ParamsPerDof,
        ),
    ] {
        assert_eq!(expect(dims), Some(BlobError::DimensionMismatch(dimension)));
    }
    // Scratch or input buffer too small for the blob's network: named by the policy.
    let loaded = load(bytes).unwrap();
    assert_eq!(
        loaded.policy::<M, O, K, N, P, I, 16>().err(),
        Some(PolicyError::Model(
            crate::model::mlp::ModelError::ScratchTooSmall
        ))
    );
    assert_eq!(
        loaded.policy::<M, O, K, N, P, 8, WIDTH>().err(),
        Some(PolicyError::InputWidth)
    );
}

#[test]
fn shape_and_value_damage_is_named() {
    let model = TestModel::new(25, &[80.0, 0.5]);
    let blob = model_blob(&model);
    let d = descriptor_of(&blob);
    let check = |bytes: Vec<u8>, expected: BlobError| {
        assert_eq!(load_copy(&bytes), Err(expected));
    };
    check(
        with_descriptor(&blob, |d| d.hidden[1].in_features += 1),
        BlobError::LayerWidth { index: 1 },
    );
    check(
        with_descriptor(&blob, |d| d.hidden[0].in_features -= 1),
        BlobError::InputLayout,
    );
    check(
        with_descriptor(&blob, |d| d.output.out_features -= 1),
        BlobError::OutputWidth,
    );
    check(
        with_descriptor(&blob, |d| d.output.in_features = 7),
        BlobError::LayerWidth { index: 2 },
    );
    check(
        with_descriptor(&blob, |d| d.hidden[0].weights.offset = 1 << 30),
        BlobError::SectionBounds(MlpSection::HiddenWeights(0).into()),
    );
    check(
        with_descriptor(&blob, |d| d.tables.obs_norm.offset += 4),
        BlobError::SectionMisaligned(PolicySection::ObsNorm.into()),
    );
    check(
        with_descriptor(&blob, |d| d.hidden[1].bias.len -= 4),
        BlobError::SectionLength(MlpSection::HiddenBias(1).into()),
    );
    check(
        with_descriptor(&blob, |d| d.output.scales.len -= 2),
        BlobError::SectionLength(MlpSection::OutputScales.into()),
    );
    check(
        with_descriptor(&blob, |d| d.first_layer_biases.len -= 4),
        BlobError::SectionLength(MlpSection::FirstLayerBiases.into()),
    );
    check(
        with_descriptor(&blob, |d| d.hidden[1].lut = Some(7)),
        BlobError::LutIndex { layer: 1 },
    );
    check(
        with_descriptor(&blob, |d| d.hidden[0].output_zero_point = 300),
        BlobError::Requantization { layer: 0 },
    );
    check(
        with_descriptor(&blob, |d| d.input_scale = -1.0),
        BlobError::InputQuantization,
    );
    check(
        with_descriptor(&blob, |d| d.header.control_dt = f32::NAN),
        BlobError::ControlPeriod,
    );
    check(
        with_descriptor(&blob, |d| {
            d.header.layout = crate::policy::InputLayout::new(
                &[crate::policy::InputSegment::NoisyTrajectory],
                1.0,
            )
            .unwrap()
        }),
        BlobError::InputLayout,
    );
    check(
        with_descriptor(&blob, |d| d.tables.steps.len = 0),
        BlobError::Steps,
    );
    check(
        poke(&blob, d.tables.obs_norm, 4, &f32::NAN.to_le_bytes()),
        BlobError::NonFinite(PolicySection::ObsNorm.into()),
    );
    check(
        poke(&blob, d.tables.prodmp, 8, &f32::INFINITY.to_le_bytes()),
        BlobError::NonFinite(PolicySection::ProDmp.into()),
    );
    check(
        poke(&blob, d.tables.action_norm, 0, &9.0_f32.to_le_bytes()),
        BlobError::Normalization,
    );
    check(
        poke(&blob, d.hidden[1].shifts, 8, &40_i32.to_le_bytes()),
        BlobError::ShiftOutOfRange { layer: 1 },
    );
    check(
        poke(&blob, d.hidden[0].multipliers, 0, &(-5_i32).to_le_bytes()),
        BlobError::NegativeMultiplier { layer: 0 },
    );
    // Second step's bias variant index beyond the two variants.
    check(
        poke(
            &blob,
            d.tables.steps,
            4 * (STEP_WORDS + 5),
            &2_u32.to_le_bytes(),
        ),
        BlobError::Steps,
    );
    // First step re-noising is invalid.
    check(
        poke(&blob, d.tables.steps, 4, &0.5_f32.to_le_bytes()),
        BlobError::Steps,
    );
}

#[test]
fn misaligned_buffer_is_rejected() {
    let model = TestModel::new(26, &[80.0]);
    let blob = model_blob(&model);
    for shift in [1, 2, 3] {
        let buffer = AlignedBlob::shifted(&blob, shift);
        assert_eq!(
            load(buffer.bytes()).err(),
            Some(BlobError::SectionMisaligned(PolicySection::ObsNorm.into())),
            "shift {shift}"
        );
    }
    // 4-byte alignment is enough.
    let buffer = AlignedBlob::shifted(&blob, 4);
    assert!(load(buffer.bytes()).is_ok());
}

#[test]
fn writer_checks_part_lengths() {
    let model = TestModel::new(27, &[80.0]);
    let hidden = model.int8_layers();
    let mut parts = model.blob_parts(&hidden);
    let mut out = vec![0_u8; 1 << 16];
    parts.config.obs_norm.min = &model.obs_range.0[..2];
    assert_eq!(
        encode_mlp(&parts, &mut out),
        Err(BlobError::SectionLength(PolicySection::ObsNorm.into()))
    );
    let mut parts = model.blob_parts(&hidden);
    parts.mlp.output.output_scales = &model.quant.output_scales[1..];
    assert_eq!(
        encode_mlp(&parts, &mut out),
        Err(BlobError::SectionLength(MlpSection::OutputScales.into()))
    );
    let parts = model.blob_parts(&hidden);
    let len = mlp_encoded_len(&parts).unwrap();
    assert_eq!(
        encode_mlp(&parts, &mut out[..len - 1]),
        Err(BlobError::BufferTooSmall)
    );
}

fn fixture_blob() -> &'static [u8] {
    static BLOB: std::sync::OnceLock<Vec<u8>> = std::sync::OnceLock::new();
    BLOB.get_or_init(|| model_blob(&TestModel::new(28, &[80.0, 1.0])))
}

proptest! {
    #![proptest_config(ProptestConfig { cases: 300, ..ProptestConfig::default() })]

    #[test]
    fn arbitrary_bytes_never_panic(bytes in proptest::collection::vec(any::<u8>(), 0..600)) {
        let _ = load_copy(&bytes);
        // With a valid header and CRC the descriptor parser and section checks are reached.
        let mut framed = bytes.clone();
        if framed.len() >= HEADER_LEN {
            framed[..4].copy_from_slice(&MLP_MAGIC);
            framed[4..6].copy_from_slice(&FORMAT_VERSION.to_le_bytes());
            framed[6..8].fill(0);
            let total = framed.len() as u32;
            framed[8..12].copy_from_slice(&total.to_le_bytes());
            let desc = u32::from_le_bytes(framed[16..20].try_into().unwrap()) % (total + 1);
            framed[16..20].copy_from_slice(&desc.to_le_bytes());
            fix_crc(&mut framed);
            let _ = load_copy(&framed);
        }
    }

    #[test]
    fn mutated_blobs_never_panic(
        edits in proptest::collection::vec((any::<prop::sample::Index>(), any::<u8>()), 1..6),
    ) {
        let blob = fixture_blob();
        let mut bytes = blob.to_vec();
        for (index, value) in &edits {
            let at = HEADER_LEN + index.index(bytes.len() - HEADER_LEN);
            bytes[at] = *value;
        }
        fix_crc(&mut bytes);
        if let Ok(()) = load_copy(&bytes) {
            // A blob that still loads must give a policy that runs or fails by name.
            let buffer = AlignedBlob::new(&bytes);
            let loaded = load(buffer.bytes()).unwrap();
            if let Ok(mut policy) = blob_policy(&loaded) {
                policy.reset(&[0.0, 0.2]).unwrap();
                policy.observe(&[0.0, 1.0, 2.0]).unwrap();
                let _ = policy.act(Noise::Rng(&mut Rng::new(1)));
            };
        }
    }
}

#[test]
fn two_plane_flag_reaches_the_network() {
    let model = TestModel::new(31, &[80.0]);
    let blob = model_blob(&model);
    let plain = AlignedBlob::new(&blob);
    let loaded = load(plain.bytes()).unwrap();
    let precision = loaded.network::<WIDTH>().unwrap().input_precision();
    assert_eq!(precision, crate::model::mlp::InputPrecision::Int8);
    let flagged = with_descriptor(&blob, |d| d.input_precision = INPUT_TWO_PLANE);
    let buffer = AlignedBlob::new(&flagged);
    let loaded = load(buffer.bytes()).unwrap();
    let precision = loaded.network::<WIDTH>().unwrap().input_precision();
    assert_eq!(precision, crate::model::mlp::InputPrecision::TwoPlane);
    let wide = with_descriptor(&blob, |d| d.input_precision = INPUT_INT16);
    let buffer = AlignedBlob::new(&wide);
    let loaded = load(buffer.bytes()).unwrap();
    let precision = loaded.network::<WIDTH>().unwrap().input_precision();
    assert_eq!(precision, crate::model::mlp::InputPrecision::Int16);
    // Either without a hidden layer to take the fine grid is refused, and so is an unknown code.
    for code in [INPUT_TWO_PLANE, INPUT_INT16] {
        let no_hidden = with_descriptor(&blob, |d| {
            d.input_precision = code;
            d.hidden.clear();
        });
        assert_eq!(load_copy(&no_hidden), Err(BlobError::InputQuantization));
    }
    let unknown = with_descriptor(&blob, |d| d.input_precision = 3);
    assert_eq!(load_copy(&unknown), Err(BlobError::InputQuantization));
}

/// The sample blob the loader's doctest loads (`tests/data/sample_policy.blob`) is what the
/// encoder writes for the test model. Regenerate with
/// `FRMD_BLESS=1 cargo test -p frmd-core committed_sample_blob`.
#[test]
fn committed_sample_blob_is_current() {
    let blob = model_blob(&TestModel::new(7, &[80.0]));
    let path = concat!(env!("CARGO_MANIFEST_DIR"), "/tests/data/sample_policy.blob");
    if std::env::var_os("FRMD_BLESS").is_some() {
        std::fs::write(path, &blob).unwrap();
    }
    let committed = std::fs::read(path).unwrap();
    assert!(
        committed == blob,
        "{path} differs from the encoder's blob of the test model (FRMD_BLESS=1 to update)"
    );
    load_copy(&committed).unwrap();
}
