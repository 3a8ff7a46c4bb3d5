//! Where one chunk of an MLP student goes (`frmd bench --stages`, `scripts/host-stages.sh`): the
//! chunk of an exported blob cut into its stages with frmd-core's public pieces, each of which can
//! be run on its own (timed in a loop here, or counted under callgrind by
//! `examples/chunk_stages.rs`):
//!
//! | stage | what runs |
//! | --- | --- |
//! | `noise` | the step's `n k` Gaussian draws (`Rng::fill_gaussian`) |
//! | `input` | `x = sigma z`, the input layout (`InputLayout::write`) and the input codes |
//! | `L<i> rows` | hidden layer `i`'s accumulators alone (`FullyConnected::accumulate`) |
//! | `L<i> requant` | the layer requantized without its table, minus `rows` |
//! | `L<i> table` | the whole layer (rows, requantization, table), minus the two above |
//! | `out rows`, `out dequant` | the output layer's accumulators and their dequantization |
//! | `decode` | ProDMP decode, the consistency combination and de-normalization |
//! | `chunk` | the whole `Policy::act` of [`Int8Policy`] (host glue included) |
//!
//! The stages run exactly the chunk's work: [`Stages::check`] recombines them into a chunk and
//! compares it bit for bit with the policy's. Only the first sampling step is cut (the students
//! are one-step); two-plane inputs are not supported.
use crate::policy::int8::Int8Policy;
use crate::tasks::{Policy, PolicyInput};
use anyhow::{bail, ensure, Context};
use frmd_core::blob::{AlignedBlob, LoadedBlob, LoadedQuantMlp};
use frmd_core::kernels::{dequantize_accumulators, LayerInput};
use frmd_core::model::linear::{Int8Linear, RequantizedLinear};
use frmd_core::model::mlp::{quantize_input_i16, InputPrecision, MlpPrecision};
use frmd_core::policy::{
    skip_output, InputSources, PolicyConfig, PolicyDims, ProDmpTables, StepConstants,
};
use frmd_core::quant::QuantParams;
use frmd_core::rng::Rng;
use frmd_export::host::{packed_weights, MAX_ACTION_DIM, MAX_HORIZON, MAX_WIDTH};

/// Seed of the noise of every stage run (and of the chunk it is checked against).
const SEED: u64 = 11;

/// One MLP blob's chunk cut into stages, for either activation precision.
pub trait Stages {
    /// The stage names, in chunk order (`chunk` last).
    fn names(&self) -> Vec<String>;
    /// Runs stage `index` of [`Self::names`] once.
    fn run(&mut self, index: usize) -> anyhow::Result<()>;
    /// Runs every stage but `chunk` in order on fresh noise and checks that the result equals
    /// the policy's chunk bit for bit.
    fn check(&mut self) -> anyhow::Result<()>;
}

/// Calls `f` with the stages of the MLP blob `bytes` and `policy` (the same blob's policy) on
/// `input` (raw units). Errors for other backbones.
pub fn with_stages<R>(
    bytes: &[u8],
    policy: &mut Int8Policy,
    input: &PolicyInput<'_>,
    f: impl FnOnce(&mut dyn Stages) -> anyhow::Result<R>,
) -> anyhow::Result<R> {
    let aligned = AlignedBlob::new(bytes);
    let loaded = LoadedBlob::load(aligned.bytes()).context("loading the blob")?;
    // The layers as the policy runs them: with this CPU's packed weights, if any.
    let packed = packed_weights(&loaded)?;
    let config = loaded.config();
    match &loaded {
        LoadedBlob::Mlp(blob) => with_network(blob, &packed, config, policy, input, f),
        LoadedBlob::Mlp16(blob) => with_network(blob, &packed, config, policy, input, f),
        LoadedBlob::Transformer(_) | LoadedBlob::Transformer16(_) => {
            bail!("the stage breakdown covers MLP students only")
        }
    }
}

/// [`with_stages`] for one MLP blob, its layers those of its network with `packed` weights.
fn with_network<'b, P: MlpPrecision + TryFrom<i16>, R>(
    blob: &'b LoadedQuantMlp<'b, P>,
    packed: &'b [u8],
    config: PolicyConfig<'b>,
    policy: &mut Int8Policy,
    input: &PolicyInput<'_>,
    f: impl FnOnce(&mut dyn Stages) -> anyhow::Result<R>,
) -> anyhow::Result<R> {
    let mut network = blob.network::<MAX_WIDTH>()?;
    network.use_packed_weights(packed)?;
    let (hidden, output) = network.layers();
    f(&mut Work::new(
        blob,
        (hidden, *output),
        config,
        policy,
        input,
    )?)
}

/// The hidden layer `i` in its three forms: the whole layer, without table, accumulators only.
struct Layer<'b, P: MlpPrecision> {
    full: RequantizedLinear<'b, P>,
    plain: RequantizedLinear<'b, P>,
}

/// The chunk's state: the blob's pieces, the conditioning (normalized) and every buffer.
struct Work<'b, 'p, 'i, P: MlpPrecision> {
    config: PolicyConfig<'b>,
    dims: PolicyDims,
    step: StepConstants,
    input_params: QuantParams,
    precision: InputPrecision,
    layers: Vec<Layer<'b, P>>,
    output: Int8Linear<'b, P::Acc>,
    policy: &'p mut Int8Policy,
    raw: &'p PolicyInput<'i>,
    obs: Vec<f32>,
    prev: Vec<f32>,
    rate: Vec<f32>,
    rng: Rng,
    z: Vec<f32>,
    noisy: Vec<f32>,
    input: Vec<f32>,
    codes16: Vec<i16>,
    codes8: Vec<i8>,
    acts: Vec<Vec<P>>,
    hidden_acc: Vec<Vec<P::Acc>>,
    acc: Vec<P::Acc>,
    params: Vec<f32>,
    decoded: (Vec<f32>, Vec<f32>),
    chunk: (Vec<f32>, Vec<f32>),
    raw_chunk: (Vec<f32>, Vec<f32>),
}

impl<'b, 'p, 'i, P: MlpPrecision + TryFrom<i16>> Work<'b, 'p, 'i, P> {
    /// The stages of `blob` run with `hidden` and `output`: the blob's layers, or a network's
    /// (with the packed weights the policy runs).
    fn new(
        blob: &'b LoadedQuantMlp<'b, P>,
        (hidden, output): (&[RequantizedLinear<'b, P>], Int8Linear<'b, P::Acc>),
        config: PolicyConfig<'b>,
        policy: &'p mut Int8Policy,
        raw: &'p PolicyInput<'i>,
    ) -> anyhow::Result<Self> {
        let dims = blob.dims();
        let step = *blob.steps().first().context("no sampling step")?;
        let precision = blob.input_precision();
        ensure!(
            precision != InputPrecision::TwoPlane,
            "the stage breakdown does not cover two-plane inputs"
        );
        let mlp = blob.mlp(hidden);
        let mut layers: Vec<Layer<'b, P>> = hidden
            .iter()
            .map(|full| Layer {
                full: *full,
                plain: RequantizedLinear {
                    activation: None,
                    ..*full
                },
            })
            .collect();
        let mut output = output;
        // The step's noise-level variant replaces the first layer's bias.
        let variants = blob.noise_variants();
        if !variants.is_empty() {
            let width = layers
                .first()
                .map_or(output.fc.out_features, |l| l.full.fc.out_features);
            let start = step.noise_variant as usize * width;
            let bias = variants
                .get(start..start + width)
                .context("noise variant")?;
            match layers.first_mut() {
                Some(first) => {
                    first.full.fc.bias = bias;
                    first.plain.fc.bias = bias;
                }
                None => output.fc.bias = bias,
            }
        }
        let (m, o, k) = (dims.history, dims.obs_dim, dims.action_dim);
        ensure!(
            raw.obs_history.len() == m,
            "observation history of {m} expected"
        );
        let mut obs = vec![0.0; m * o];
        for (slot, raw_obs) in obs.chunks_exact_mut(o.max(1)).zip(raw.obs_history) {
            config.obs_norm.normalize(raw_obs, slot);
        }
        let (mut prev, mut rate) = (vec![0.0; k], vec![0.0; k]);
        config.action_norm.normalize(raw.prev_action, &mut prev);
        config.action_norm.normalize_rate(raw.prev_rate, &mut rate);
        let nk = dims.horizon * k;
        let width = mlp.input_width();
        let acts = layers
            .iter()
            .map(|l| vec![P::ZERO; l.full.fc.out_features])
            .collect();
        let hidden_acc = layers
            .iter()
            .map(|l| vec![Default::default(); l.full.fc.out_features])
            .collect();
        Ok(Self {
            config,
            dims,
            step,
            input_params: mlp.input,
            precision,
            acc: vec![Default::default(); output.fc.out_features],
            params: vec![0.0; output.fc.out_features],
            layers,
            output,
            policy,
            raw,
            obs,
            prev,
            rate,
            rng: Rng::new(SEED),
            z: vec![0.0; nk],
            noisy: vec![0.0; nk],
            input: vec![0.0; width],
            codes16: vec![0; width],
            codes8: vec![0; width],
            acts,
            hidden_acc,
            decoded: (vec![0.0; nk], vec![0.0; nk]),
            chunk: (vec![0.0; nk], vec![0.0; nk]),
            raw_chunk: (vec![0.0; nk], vec![0.0; nk]),
        })
    }

    /// The input codes of layer `index` (the network input, or the previous layer's output).
    fn layer_input(&self, index: usize) -> LayerInput<'_> {
        match index.checked_sub(1).and_then(|i| self.acts.get(i)) {
            Some(previous) => P::layer_input(previous),
            None if self.precision == InputPrecision::Int16 => LayerInput::Int16(&self.codes16),
            None => LayerInput::Int8(&self.codes8),
        }
    }

    fn noise(&mut self) {
        self.rng.fill_gaussian(&mut self.z);
    }

    fn assemble_input(&mut self) -> anyhow::Result<()> {
        for (x, z) in self.noisy.iter_mut().zip(&self.z) {
            *x = self.step.sigma * z;
        }
        let sources = InputSources {
            obs_history: &self.obs,
            prev_action: &self.prev,
            prev_rate: &self.rate,
            noisy: &self.noisy,
            c_in: self.step.c_in,
        };
        self.config
            .sampler
            .layout
            .write(&self.dims, &sources, &mut self.input)?;
        if self.precision == InputPrecision::Int16 {
            quantize_input_i16(&self.input, self.input_params, &mut self.codes16);
        } else {
            for (code, x) in self.codes8.iter_mut().zip(&self.input) {
                *code = self.input_params.quantize(*x);
            }
        }
        Ok(())
    }

    /// Hidden layer `index`: `Some(false)` accumulators only, `Some(true)` without its table,
    /// `None` the whole layer.
    fn layer(&mut self, index: usize, part: Option<bool>) -> anyhow::Result<()> {
        let mut out = core::mem::take(&mut self.acts[index]);
        let mut acc = core::mem::take(&mut self.hidden_acc[index]);
        let layer = &self.layers[index];
        let input = self.layer_input(index);
        let result = match part {
            Some(false) => layer.full.fc.accumulate(input, &mut acc),
            Some(true) => layer.plain.forward_prevalidated(input, &mut out),
            None => layer.full.forward_prevalidated(input, &mut out),
        };
        self.acts[index] = out;
        self.hidden_acc[index] = acc;
        Ok(result?)
    }

    fn output_rows(&mut self) -> anyhow::Result<()> {
        let last = self.layers.len();
        let mut acc = core::mem::take(&mut self.acc);
        let result = self.output.fc.accumulate(self.layer_input(last), &mut acc);
        self.acc = acc;
        Ok(result?)
    }

    fn dequantize(&mut self) -> anyhow::Result<()> {
        let scales = self.output.output_scales;
        Ok(dequantize_accumulators(
            &self.acc,
            scales,
            &mut self.params,
        )?)
    }

    /// ProDMP decode, `f = b + c_skip (x - b) + c_out (g - b)` as the sampler combines them,
    /// then the chunk in raw units.
    fn decode(&mut self) -> anyhow::Result<()> {
        let decoder: ProDmpTables<'_> = self.config.sampler.decoder;
        let (pos, vel) = &mut self.decoded;
        decoder.decode::<MAX_HORIZON, MAX_ACTION_DIM, { frmd_export::host::MAX_PARAMS_PER_DOF }>(
            &self.params,
            &self.prev,
            &self.rate,
            pos,
            vel,
        )?;
        let k = self.dims.action_dim.max(1);
        let (step, dt) = (self.step, self.config.sampler.control_dt);
        let mut before: &[f32] = &self.prev;
        let rows = self
            .noisy
            .chunks_exact(k)
            .zip(pos.chunks_exact(k).zip(vel.chunks_exact(k)))
            .zip(
                self.chunk
                    .0
                    .chunks_exact_mut(k)
                    .zip(self.chunk.1.chunks_exact_mut(k)),
            )
            .zip(decoder.boundary_rows());
        for (((x_t, (p_t, v_t)), (out_p, out_v)), b_t) in rows {
            for d in 0..k {
                let (b_pos, b_vel) = b_t.at(self.prev[d], self.rate[d]);
                let (x, p, v) = (x_t[d], p_t[d], v_t[d]);
                out_p[d] = skip_output(step.c_skip, step.c_out, x, p, b_pos);
                let rate = (x - before[d]) / dt;
                out_v[d] = skip_output(step.c_skip, step.c_out, rate, v, b_vel);
            }
            before = x_t;
        }
        let (raw_p, raw_v) = &mut self.raw_chunk;
        self.config
            .action_norm
            .denormalize_trajectory::<MAX_HORIZON, MAX_ACTION_DIM>(
                (&self.chunk.0, &self.chunk.1),
                (raw_p, raw_v),
            );
        Ok(())
    }

    fn chunk(&mut self) -> anyhow::Result<()> {
        self.policy.act(self.raw)?;
        Ok(())
    }
}

impl<P: MlpPrecision + TryFrom<i16>> Stages for Work<'_, '_, '_, P> {
    fn names(&self) -> Vec<String> {
        let mut names = vec!["noise".to_string(), "input".to_string()];
        for i in 0..self.layers.len() {
            names.extend(["rows", "requant", "table"].map(|part| format!("L{i} {part}")));
        }
        names.extend(["out rows", "out dequant", "decode", "chunk"].map(String::from));
        names
    }

    fn run(&mut self, index: usize) -> anyhow::Result<()> {
        let hidden = 3 * self.layers.len();
        match index {
            0 => {
                self.noise();
                Ok(())
            }
            1 => self.assemble_input(),
            i if i < 2 + hidden => {
                let (layer, part) = ((i - 2) / 3, (i - 2) % 3);
                self.layer(layer, [Some(false), Some(true), None][part])
            }
            i if i == 2 + hidden => self.output_rows(),
            i if i == 3 + hidden => self.dequantize(),
            i if i == 4 + hidden => self.decode(),
            i if i == 5 + hidden => self.chunk(),
            _ => bail!("no stage {index}"),
        }
    }

    fn check(&mut self) -> anyhow::Result<()> {
        self.rng = Rng::new(SEED);
        self.noise();
        self.assemble_input()?;
        for i in 0..self.layers.len() {
            self.layer(i, None)?;
        }
        self.output_rows()?;
        self.dequantize()?;
        self.decode()?;
        self.policy.reset(SEED);
        let chunk: Vec<f32> = self.policy.act(self.raw)?.concat();
        ensure!(
            chunk
                .iter()
                .map(|v| v.to_bits())
                .eq(self.raw_chunk.0.iter().map(|v| v.to_bits())),
            "the stages' chunk differs from the policy's: {:?} vs {chunk:?}",
            self.raw_chunk.0
        );
        Ok(())
    }
}

/// Median and smallest wall time (ns) of stage `index` per call: `batches` batches of
/// `per_batch` calls after a warm-up, each batch timed as a whole (on a loaded machine the
/// smallest batch is the one least disturbed).
pub fn time_stage(
    stages: &mut dyn Stages,
    index: usize,
    batches: usize,
    per_batch: usize,
) -> anyhow::Result<(f64, f64)> {
    for _ in 0..per_batch.max(10) {
        stages.run(index)?;
    }
    let mut times = Vec::with_capacity(batches);
    for _ in 0..batches.max(1) {
        let start = std::time::Instant::now();
        for _ in 0..per_batch.max(1) {
            stages.run(index)?;
        }
        times.push(start.elapsed().as_secs_f64() * 1e9 / per_batch.max(1) as f64);
    }
    let least = times.iter().copied().fold(f64::INFINITY, f64::min);
    Ok((crate::eval::metrics::quantile(&times, 0.5), least))
}

/// The breakdown as rows `(stage, median ns)` plus `other` (the chunk minus the stages).
pub fn stage_times(stages: &mut dyn Stages, batches: usize) -> anyhow::Result<Vec<(String, f64)>> {
    stages.check()?;
    let names = stages.names();
    let mut rows: Vec<(String, f64)> = Vec::new();
    let mut cumulative = 0.0;
    for (index, name) in names.iter().enumerate() {
        let (ns, _) = time_stage(stages, index, batches, 20)?;
        // Layer parts are reported as increments over the part before.
        let part = name.rsplit(' ').next().unwrap_or("");
        let reported = match part {
            "requant" | "table" => ns - cumulative,
            _ => ns,
        };
        cumulative = ns;
        rows.push((name.clone(), reported));
    }
    let parts: f64 = rows.iter().rev().skip(1).map(|(_, ns)| ns).sum();
    let chunk = rows.last().map_or(0.0, |(_, ns)| *ns);
    rows.insert(rows.len() - 1, ("other (host glue)".into(), chunk - parts));
    Ok(rows)
}
