//! The baked form: a generated Rust module with `const`/`static` shapes, scales, requantization
//! parameters, LUTs, normalization, ProDMP tables and step constants, plus an aligned
//! `weights.bin` (int8 weights and int32 biases) that the module reads with `include_bytes!`.
//!
//! The module has no inner attributes, so it works as a plain file module (`mod policy;`) and
//! with `include!` from a build script's `OUT_DIR`
//! (`mod baked { include!(concat!(env!("OUT_DIR"), "/policy.rs")); }`); `weights.bin` must sit
//! next to it. It needs only `frmd-core` and exposes `mlp_parts()`, `network()`, `config()`,
//! `policy()`, the
//! `BakedPolicy` type and RAM/flash figures (`SCRATCH_BYTES`, `FLASH_BYTES`, `POLICY_RAM_BYTES`).

use std::fmt::Write as _;
use std::io;
use std::path::Path;

use frmd_core::policy::InputSegment;

use crate::{ProDmpTablesOwned, QuantizedPolicy};

/// File name of the generated module.
pub const MODULE_FILE: &str = "policy.rs";
/// File name of the weight file.
pub const WEIGHTS_FILE: &str = "weights.bin";
/// Alignment of every array in the weight file.
const ALIGN: usize = 16;

/// One array of the weight file: byte offset and element count.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct WeightEntry {
    /// Byte offset in the weight file (multiple of 16).
    pub offset: usize,
    /// Number of elements.
    pub count: usize,
}

/// Where each array goes: per hidden layer (weights i8, bias i32), then the first-layer bias
/// variants (i32), the output weights (i8) and bias (i32). Returns the entries in that order and
/// the file length.
pub fn weight_file_layout(policy: &QuantizedPolicy) -> (Vec<WeightEntry>, usize) {
    let mut entries = Vec::new();
    let mut cursor = 0;
    let mut place = |count: usize, size: usize| {
        let entry = WeightEntry {
            offset: cursor,
            count,
        };
        cursor = (cursor + count * size).div_ceil(ALIGN) * ALIGN;
        entries.push(entry);
    };
    for layer in &policy.hidden {
        place(layer.weights.len(), 1);
        place(layer.bias.len(), 4);
    }
    place(policy.first_layer_biases.len(), 4);
    place(policy.output.weights.len(), 1);
    place(policy.output.bias.len(), 4);
    (entries, cursor)
}

/// The weight file bytes (little endian), laid out by [`weight_file_layout`].
pub fn weight_file(policy: &QuantizedPolicy) -> Vec<u8> {
    let (entries, len) = weight_file_layout(policy);
    let mut bytes = vec![0_u8; len];
    let mut arrays: Vec<Vec<u8>> = Vec::new();
    for layer in &policy.hidden {
        arrays.push(layer.weights.iter().map(|w| *w as u8).collect());
        arrays.push(layer.bias.iter().flat_map(|b| b.to_le_bytes()).collect());
    }
    arrays.push(
        policy
            .first_layer_biases
            .iter()
            .flat_map(|b| b.to_le_bytes())
            .collect(),
    );
    arrays.push(policy.output.weights.iter().map(|w| *w as u8).collect());
    arrays.push(
        policy
            .output
            .bias
            .iter()
            .flat_map(|b| b.to_le_bytes())
            .collect(),
    );
    for (entry, array) in entries.iter().zip(&arrays) {
        bytes[entry.offset..entry.offset + array.len()].copy_from_slice(array);
    }
    bytes
}

fn invalid(message: String) -> io::Error {
    io::Error::new(io::ErrorKind::InvalidInput, message)
}

/// Checks what the generated code cannot: finite floats and consistent lengths (the blob writer's
/// shape checks are reused by encoding once).
fn check(policy: &QuantizedPolicy) -> io::Result<()> {
    crate::blob::write(policy).map_err(|e| invalid(format!("inconsistent policy: {e}")))?;
    let p = &policy.prodmp;
    let floats = policy
        .obs_min
        .iter()
        .chain(&policy.obs_max)
        .chain(&policy.action_min)
        .chain(&policy.action_max)
        .chain(&p.pos_params)
        .chain(&p.vel_params)
        .chain(&p.pos_y0)
        .chain(&p.pos_v0)
        .chain(&p.vel_y0)
        .chain(&p.vel_v0)
        .chain(&policy.output.scales)
        .chain([
            &policy.control_dt,
            &policy.input.scale,
            &policy.layout.rate_scale,
        ]);
    let step_floats = policy
        .steps
        .iter()
        .flat_map(|s| [s.sigma, s.renoise_std, s.c_in, s.c_skip, s.c_out]);
    if floats.copied().chain(step_floats).any(|v| !v.is_finite()) {
        return Err(invalid("policy contains NaN or infinity".into()));
    }
    if policy.input_width().is_none() {
        return Err(invalid("input layout width overflows".into()));
    }
    let luts = policy.luts.len();
    if policy
        .hidden
        .iter()
        .any(|l| l.lut.is_some_and(|i| i >= luts))
    {
        return Err(invalid("a layer refers to a missing LUT".into()));
    }
    Ok(())
}

/// `[a, b, c]` with each value formatted by `f`.
fn list<T>(values: &[T], f: impl Fn(&T) -> String) -> String {
    let items: Vec<String> = values.iter().map(f).collect();
    format!("[{}]", items.join(", "))
}

/// An f32 literal that reads back to the same bits (`{:?}` is the shortest round-trip form).
fn float(value: &f32) -> String {
    format!("{value:?}")
}

/// The tables of a baked ProDMP decoder as a Rust expression `BakedProDmp { pos_params: .., .. }`
/// (`BakedProDmp` = `frmd_core::prodmp::BakedProDmp` must be in scope), every f32 as a literal that
/// reads back to the same bits; `params_per_dof` values per row of the `[N][P]` tables. The
/// generated policy module's `DECODER` and the firmware's stand-alone decoder use it.
pub fn decoder_expression(prodmp: &ProDmpTablesOwned, params_per_dof: usize) -> String {
    let rows = |table: &[f32]| {
        let rows: Vec<String> = table
            .chunks(params_per_dof.max(1))
            .map(|row| format!("        {},", list(row, float)))
            .collect();
        format!("[\n{}\n    ]", rows.join("\n"))
    };
    format!(
        "BakedProDmp {{\n    pos_params: {},\n    vel_params: {},\n    pos_y0: {},\n    pos_v0: {},\n    vel_y0: {},\n    vel_v0: {},\n}}",
        rows(&prodmp.pos_params),
        rows(&prodmp.vel_params),
        list(&prodmp.pos_y0, float),
        list(&prodmp.pos_v0, float),
        list(&prodmp.vel_y0, float),
        list(&prodmp.vel_v0, float)
    )
}

fn segment_name(segment: InputSegment) -> &'static str {
    match segment {
        InputSegment::ObsHistory => "ObsHistory",
        InputSegment::PrevAction => "PrevAction",
        InputSegment::PrevRate => "PrevRate",
        InputSegment::NoisyTrajectory => "NoisyTrajectory",
    }
}

/// The generated module's source text.
pub fn module_source(policy: &QuantizedPolicy) -> io::Result<String> {
    check(policy)?;
    let q = policy;
    let (entries, weights_len) = weight_file_layout(q);
    let memory = q.memory();
    let input_width = q.input_width().unwrap_or(0);
    let mut s = String::new();
    let w = &mut s;
    let fmt_err = |_| invalid("formatting failed".into());
    writeln!(
        w,
        "// Baked FRMD policy, @generated by frmd-export: do not edit."
    )
    .map_err(fmt_err)?;
    writeln!(
        w,
        "// Needs `{WEIGHTS_FILE}` next to this file; only depends on frmd-core."
    )
    .map_err(fmt_err)?;
    w.push_str(
        "\nuse frmd_core::kernels::{FcRequant, FullyConnected, Lut8};\n\
         use frmd_core::model::linear::{Int8Linear, RequantizedLinear};\n\
         use frmd_core::model::mlp::InputPrecision;\n\
         use frmd_core::policy::{\n    baked_slice, AlignedBytes, InputLayout, InputSegment, Int8MlpNetwork, Policy, PolicyConfig,\n    PolicyError, ProDmpTables, RangeNormalizer, Sampler, StepConstants, StepTable,\n};\n\
         use frmd_core::prodmp::BakedProDmp;\n\
         use frmd_core::quant::QuantParams;\n\n",
    );
    let consts = [
        ("HISTORY", q.history, "Observation history length M."),
        ("OBS_DIM", q.obs_dim, "Observation dimension O."),
        ("ACTION_DIM", q.action_dim, "Action dimension K (DoF)."),
        ("HORIZON", q.horizon, "Horizon N (actions per chunk)."),
        (
            "PARAMS_PER_DOF",
            q.params_per_dof,
            "ProDMP parameters per DoF P.",
        ),
        ("INPUT_WIDTH", input_width, "Model input width."),
        (
            "SCRATCH_WIDTH",
            memory.scratch_width,
            "Widest layer: the scratch `WIDTH`.",
        ),
        ("NUM_STEPS", q.steps.len(), "Sampling steps."),
        (
            "SCRATCH_BYTES",
            memory.scratch_bytes,
            "Forward-pass scratch RAM, bytes.",
        ),
        (
            "STATE_BYTES",
            memory.state_bytes,
            "Policy state and sampler buffers (f32), bytes.",
        ),
        ("WEIGHTS_BYTES", weights_len, "Weight file length, bytes."),
        (
            "TABLE_BYTES",
            memory.table_bytes,
            "Constant tables in flash, bytes.",
        ),
        (
            "FLASH_BYTES",
            memory.flash_bytes(),
            "Weights plus tables in flash, bytes.",
        ),
    ];
    for (name, value, doc) in consts {
        writeln!(w, "/// {doc}\npub const {name}: usize = {value};").map_err(fmt_err)?;
    }
    writeln!(w, "/// Exact RAM of one `BakedPolicy` on this target, bytes.\npub const POLICY_RAM_BYTES: usize = core::mem::size_of::<BakedPolicy>();").map_err(fmt_err)?;
    writeln!(
        w,
        "/// Control period, seconds.\npub const CONTROL_DT: f32 = {};",
        float(&q.control_dt)
    )
    .map_err(fmt_err)?;
    writeln!(
        w,
        "/// Quantization of the f32 input vector.\npub const INPUT: QuantParams = QuantParams {{ scale: {}, zero_point: {} }};",
        float(&q.input.scale),
        q.input.zero_point
    )
    .map_err(fmt_err)?;
    writeln!(
        w,
        "/// How the first layer quantizes the input (its multipliers are made for it).\npub const INPUT_PRECISION: InputPrecision = InputPrecision::{:?};",
        q.input_precision
    )
    .map_err(fmt_err)?;
    let segments = q.layout.segments();
    let mut padded: Vec<&str> = segments.iter().map(|s| segment_name(*s)).collect();
    while padded.len() < frmd_core::policy::MAX_INPUT_SEGMENTS {
        padded.push("NoisyTrajectory");
    }
    writeln!(
        w,
        "/// Model input layout.\npub const LAYOUT: InputLayout = InputLayout::from_segments(\n    {},\n    {},\n    {},\n);",
        list(&padded, |n| format!("InputSegment::{n}")),
        segments.len(),
        float(&q.layout.rate_scale)
    )
    .map_err(fmt_err)?;
    writeln!(
        w,
        "/// Observation range (raw units).\npub static OBS_MIN: [f32; OBS_DIM] = {};\npub static OBS_MAX: [f32; OBS_DIM] = {};\n/// Observation normalization.\npub const OBS_NORM: RangeNormalizer<'static> = RangeNormalizer::new(&OBS_MIN, &OBS_MAX);",
        list(&q.obs_min, float),
        list(&q.obs_max, float)
    )
    .map_err(fmt_err)?;
    writeln!(
        w,
        "/// Action range (raw units).\npub static ACTION_MIN: [f32; ACTION_DIM] = {};\npub static ACTION_MAX: [f32; ACTION_DIM] = {};\n/// Action normalization.\npub const ACTION_NORM: RangeNormalizer<'static> = RangeNormalizer::new(&ACTION_MIN, &ACTION_MAX);",
        list(&q.action_min, float),
        list(&q.action_max, float)
    )
    .map_err(fmt_err)?;
    writeln!(
        w,
        "/// Baked ProDMP decoder.\npub static DECODER: BakedProDmp<HORIZON, PARAMS_PER_DOF> = {};",
        decoder_expression(&q.prodmp, q.params_per_dof)
    )
    .map_err(fmt_err)?;
    let steps = list(&q.steps, |s| {
        format!(
            "\n    StepConstants {{ sigma: {}, renoise_std: {}, c_in: {}, c_skip: {}, c_out: {}, noise_variant: {} }}",
            float(&s.sigma),
            float(&s.renoise_std),
            float(&s.c_in),
            float(&s.c_skip),
            float(&s.c_out),
            s.noise_variant
        )
    });
    writeln!(
        w,
        "/// Sampling step constants.\npub static STEPS: [StepConstants; NUM_STEPS] = {steps};"
    )
    .map_err(fmt_err)?;
    for (i, lut) in q.luts.iter().enumerate() {
        writeln!(
            w,
            "/// Activation table {i}.\npub static LUT_{i}: Lut8 = Lut8::from_table({});",
            list(lut, |v| v.to_string())
        )
        .map_err(fmt_err)?;
    }
    for (i, layer) in q.hidden.iter().enumerate() {
        let n = layer.out_features;
        writeln!(
            w,
            "/// Hidden layer {i}: Q31 multipliers.\npub static HIDDEN_{i}_MULTIPLIERS: [i32; {n}] = {};\n/// Hidden layer {i}: shifts.\npub static HIDDEN_{i}_SHIFTS: [i32; {n}] = {};",
            list(&layer.multipliers, |v| v.to_string()),
            list(&layer.shifts, |v| v.to_string())
        )
        .map_err(fmt_err)?;
    }
    writeln!(
        w,
        "/// Output dequantization scales.\npub static OUTPUT_SCALES: [f32; {}] = {};",
        q.output.out_features,
        list(&q.output.scales, float)
    )
    .map_err(fmt_err)?;
    writeln!(
        w,
        "/// The weight file ({weights_len} bytes, 16-aligned arrays).\npub static WEIGHTS: AlignedBytes<WEIGHTS_BYTES> = AlignedBytes(*include_bytes!(\"{WEIGHTS_FILE}\"));\n"
    )
    .map_err(fmt_err)?;
    // mlp_parts() and network()
    let layers = q.hidden.len();
    writeln!(
        w,
        "/// The hidden layers, the output layer and the first-layer bias variants over the baked\n\
         /// weights.\n\
         #[allow(clippy::type_complexity)]\n\
         pub fn mlp_parts() -> Result<([RequantizedLinear<'static>; {layers}], Int8Linear<'static>, &'static [i32]), PolicyError> {{\n    let bytes = &WEIGHTS.0;\n    let hidden = ["
    )
    .map_err(fmt_err)?;
    for (i, layer) in q.hidden.iter().enumerate() {
        let (weights, bias) = (entries[2 * i], entries[2 * i + 1]);
        let activation = match layer.lut {
            Some(l) => format!("Some(&LUT_{l}.table)"),
            None => "None".into(),
        };
        writeln!(
            w,
            "        RequantizedLinear {{\n            fc: FullyConnected::new(\n                {},\n                {},\n                baked_slice(bytes, {}, {})?,\n                baked_slice(bytes, {}, {})?,\n            ),\n            requant: FcRequant {{\n                multipliers: &HIDDEN_{i}_MULTIPLIERS,\n                shifts: &HIDDEN_{i}_SHIFTS,\n                output_zero_point: {},\n                activation_min: {},\n                activation_max: {},\n            }},\n            activation: {activation},\n        }},",
            layer.in_features,
            layer.out_features,
            weights.offset,
            weights.count,
            bias.offset,
            bias.count,
            layer.output_zero_point,
            layer.activation_min,
            layer.activation_max
        )
        .map_err(fmt_err)?;
    }
    let base = 2 * q.hidden.len();
    let (variants, out_weights, out_bias) = (entries[base], entries[base + 1], entries[base + 2]);
    writeln!(
        w,
        "    ];\n    let output = Int8Linear {{\n        fc: FullyConnected::new(\n            {},\n            {},\n            baked_slice(bytes, {}, {})?,\n            baked_slice(bytes, {}, {})?,\n        ),\n        output_scales: &OUTPUT_SCALES,\n    }};\n    Ok((hidden, output, baked_slice(bytes, {}, {})?))\n}}\n\n\
         /// The int8 network over the baked weights (`WIDTH` >= `SCRATCH_WIDTH`).\n\
         pub fn network<const WIDTH: usize>() -> Result<Int8MlpNetwork<'static, WIDTH>, PolicyError> {{\n    let (hidden, output, first_layer_biases) = mlp_parts()?;\n    Int8MlpNetwork::new(INPUT, INPUT_PRECISION, &hidden, output, first_layer_biases)\n}}\n",
        q.output.in_features,
        q.output.out_features,
        out_weights.offset,
        out_weights.count,
        out_bias.offset,
        out_bias.count,
        variants.offset,
        variants.count
    )
    .map_err(fmt_err)?;
    w.push_str(
        "/// Normalization and sampler configuration.\n\
         pub fn config() -> PolicyConfig<'static> {\n    PolicyConfig {\n        history: HISTORY,\n        obs_norm: OBS_NORM,\n        action_norm: ACTION_NORM,\n        sampler: Sampler {\n            steps: StepTable::new(&STEPS),\n            decoder: ProDmpTables::from_baked(&DECODER),\n            layout: LAYOUT,\n            control_dt: CONTROL_DT,\n        },\n    }\n}\n\n\
         /// The baked policy type.\n\
         pub type BakedPolicy = Policy<\n    'static,\n    Int8MlpNetwork<'static, SCRATCH_WIDTH>,\n    HISTORY,\n    OBS_DIM,\n    ACTION_DIM,\n    HORIZON,\n    PARAMS_PER_DOF,\n    INPUT_WIDTH,\n>;\n\n\
         /// A ready policy (validated); call `reset` before the first chunk.\n\
         pub fn policy() -> Result<BakedPolicy, PolicyError> {\n    Policy::new(config(), network::<SCRATCH_WIDTH>()?)\n}\n",
    );
    Ok(s)
}

/// Writes `policy.rs` and `weights.bin` into `dir` (created if missing).
pub fn write_module(policy: &QuantizedPolicy, dir: &Path) -> io::Result<()> {
    let source = module_source(policy)?;
    std::fs::create_dir_all(dir)?;
    crate::artifact::write_atomic(&dir.join(MODULE_FILE), source.as_bytes())
        .map_err(|e| io::Error::other(format!("{e:#}")))?;
    crate::artifact::write_atomic(&dir.join(WEIGHTS_FILE), &weight_file(policy))
        .map_err(|e| io::Error::other(format!("{e:#}")))?;
    Ok(())
}
