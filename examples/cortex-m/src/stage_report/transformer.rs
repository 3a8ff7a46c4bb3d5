//! The transformer policy's breakdown: token embedding, blocks (by prefixes of the forward
//! pass), head, and the stages outside the network (see the parent module).

use super::*;
use frmd_core::kernels::LayerInput;

/// Ticks of `Int8Transformer::forward` of `model` restricted to its first `layers` blocks, on the
/// fixed input.
fn time_prefix<const F: usize, const B: usize, const A: usize>(
    model: &Int8Transformer<'_>,
    layers: usize,
    trajectory: &[f32],
    condition: &[f32],
    output: &mut [f32],
    scratch: &mut TransformerScratch<F, B, A>,
) -> Result<u64, PolicyError> {
    let failed = |_| PolicyError::Model(frmd_core::model::mlp::ModelError::InputLength);
    let blocks = model
        .blocks
        .get(..layers)
        .ok_or(PolicyError::TooManyLayers)?;
    let prefix = Int8Transformer {
        shape: TransformerShape {
            layers,
            ..model.shape
        },
        blocks,
        ..*model
    };
    let start = systick();
    let result = prefix.forward(trajectory, condition, output, scratch);
    let end = systick();
    result.map_err(failed)?;
    Ok(elapsed(start, end))
}

/// Token embedding (`cond_in`, the folded noise token, `traj_in` per step, plus positions) as
/// `Int8Transformer::forward` does it, into `residual`; and the head (final LayerNorm, quantization,
/// `head`) from `residual`. Returns the ticks of one run of each.
fn time_embedding_and_head<const TW: usize, const WIDTH: usize, const OUT: usize>(
    model: &Int8Transformer<'_>,
    trajectory: &[f32],
    condition: &[f32],
) -> Result<(u64, u64), PolicyError> {
    let failed = |_| PolicyError::Model(frmd_core::model::mlp::ModelError::InputLength);
    let shape = &model.shape;
    let mut residual = [0.0_f32; TW];
    let mut codes = [0_i8; TW];
    let mut accumulators = [0_i32; WIDTH];
    let mut row = [0.0_f32; WIDTH];
    let mut output = [0.0_f32; OUT];
    let (embedding, head);
    let project = |layer: &TokenLinear<'_>,
                   input: &[f32],
                   codes: &mut [i8],
                   acc: &mut [i32],
                   out: &mut [f32]| match layer {
        TokenLinear::Quantized(linear) => {
            let codes = codes
                .get_mut(..input.len())
                .ok_or(PolicyError::InputWidth)?;
            linear.forward(input, codes, acc, out).map_err(failed)
        }
        TokenLinear::Float(linear) => linear.forward(input, out).map_err(failed),
    };
    {
        let start = systick();
        let mut rows = residual.chunks_exact_mut(shape.width);
        let mut positions = model.positions.chunks_exact(shape.width);
        if let (Some(token), Some(position)) = (rows.next(), positions.next()) {
            project(
                &model.cond_in,
                condition,
                &mut codes,
                &mut accumulators,
                token,
            )?;
            token.iter_mut().zip(position).for_each(|(t, p)| *t += p);
        }
        if let (Some(token), Some(_)) = (rows.next(), positions.next()) {
            token
                .iter_mut()
                .zip(model.noise_token)
                .for_each(|(t, n)| *t = *n);
        }
        for ((token, position), step) in rows
            .zip(positions)
            .zip(trajectory.chunks_exact(shape.action_dim))
        {
            project(&model.traj_in, step, &mut codes, &mut accumulators, token)?;
            token.iter_mut().zip(position).for_each(|(t, p)| *t += p);
        }
        let end = systick();
        embedding = elapsed(start, end);
        core::hint::black_box(&residual);

        let start = systick();
        for (token, token_codes) in residual
            .chunks_exact(shape.width)
            .zip(codes.chunks_exact_mut(shape.width))
        {
            model.final_norm.apply(token, &mut row).map_err(failed)?;
            for (code, value) in token_codes.iter_mut().zip(&row) {
                *code = model.head.input.quantize(*value);
            }
        }
        let acc = accumulators
            .get_mut(..OUT)
            .ok_or(PolicyError::OutputWidth)?;
        model
            .head
            .linear
            .forward_input(LayerInput::Int8(&codes), acc, &mut output)
            .map_err(failed)?;
        let end = systick();
        head = elapsed(start, end);
        core::hint::black_box(&output);
    }
    Ok((embedding, head))
}

#[inline(never)]
/// Breakdown of the transformer policy: `workload`'s network clock must be [`systick`]; its
/// chunks must reproduce `expected_digest`. `TW`, `WIDTH`, `OUT` are the model's `T W`, `W` and
/// output width.
pub fn transformer_policy<
    const F: usize,
    const B: usize,
    const A: usize,
    const TW: usize,
    const WIDTH: usize,
    const OUT: usize,
    const M: usize,
    const O: usize,
    const K: usize,
    const N: usize,
    const P: usize,
    const I: usize,
>(
    workload: &mut PolicyWorkload<
        '_,
        MarkedNetwork<Int8TransformerNetwork<'_, &mut TransformerScratch<F, B, A>>>,
        M,
        O,
        K,
        N,
        P,
        I,
    >,
    scratch: &mut TransformerScratch<F, B, A>,
    calibration: &Calibration,
    expected_digest: u64,
) -> Result<(), PolicyError> {
    let model = *workload.policy().network().inner().model();
    let shape = model.shape;
    let (t, w) = (shape.tokens() as u64, shape.width as u64);
    let mut stages = Breakdown::new();
    let noise = stages.stage("noise", 0);
    let input = stages.stage("input", 0);
    let embedding = stages.stage(
        "embedding",
        (shape.cond_dim as u64 + shape.trajectory_len() as u64) * w,
    );
    const BLOCK_NAMES: [&str; 8] = [
        "block1", "block2", "block3", "block4", "block5", "block6", "block7", "block8",
    ];
    let first_block = stages.count;
    for name in BLOCK_NAMES.iter().take(shape.layers) {
        stages.stage(name, 12 * t * w * w + 2 * t * t * w);
    }
    let head = stages.stage("head", t * w * shape.output as u64);
    let network_rest = stages.stage("network_rest", 0);
    let outer = stages.close_policy(noise, input, (N, K, P));
    let mut digest = Fnv1a64::new();
    let mut network_ticks = 0;
    for case in 0..CASES {
        workload.prepare(case)?;
        let run = TimedRun::of(workload, |w| w.policy().network().marks().ticks())?;
        stages.add(outer.input, elapsed(run.start, run.entry) * REPEATS as u64);
        network_ticks += elapsed(run.entry, run.exit) * REPEATS as u64;
        stages.add(
            outer.output_stage,
            elapsed(run.exit, run.end) * REPEATS as u64,
        );
        workload.digest_outputs(&mut digest);
        stages.split_standalone(
            outer,
            time_noise::<N, K>(case),
            time_post_stages(workload.policy())?,
        );
    }
    check_digest(digest, expected_digest);
    // The network's parts on a fixed input, REPEATS runs per case.
    let mut rng = Rng::new(0x4652_4D44_5354_4731);
    let mut condition = [0.0_f32; 64];
    let mut trajectory = [0.0_f32; 64];
    let condition = condition
        .get_mut(..shape.cond_dim)
        .ok_or(PolicyError::InputWidth)?;
    let trajectory = trajectory
        .get_mut(..shape.trajectory_len())
        .ok_or(PolicyError::InputWidth)?;
    condition
        .iter_mut()
        .for_each(|v| *v = 2.0 * rng.uniform() - 1.0);
    rng.fill_gaussian(trajectory);
    let mut output = [0.0_f32; OUT];
    // Their cost hardly depends on the data, so each is timed once (about 70 M instructions for
    // the three prefixes) and weighted like the CASES * REPEATS calls above.
    let weight = (CASES * REPEATS) as u64;
    let (embedding_ticks, head_ticks) =
        time_embedding_and_head::<TW, WIDTH, OUT>(&model, trajectory, condition)?;
    stages.add(embedding, embedding_ticks * weight);
    stages.add(head, head_ticks * weight);
    let mut previous = 0;
    for layers in 1..=shape.layers {
        let ticks = time_prefix(&model, layers, trajectory, condition, &mut output, scratch)?;
        let block = first_block + layers - 1;
        if layers == 1 {
            stages.add(block, ticks * weight);
            stages.sub(block, (embedding_ticks + head_ticks) * weight);
        } else {
            stages.add(block, ticks.saturating_sub(previous) * weight);
        }
        previous = ticks;
    }
    let prefix_ticks = previous * weight;
    // What `act` spent in the network beyond the standalone full forward pass (the adapter, the
    // input split, differences of input data).
    stages.add(network_rest, network_ticks.saturating_sub(prefix_ticks));
    let calls = (CASES * REPEATS) as u64;
    report!(
        "stage_network_in_act: {}",
        (calibration.instructions(network_ticks) + calls / 2) / calls
    );
    stages.print(calibration, (CASES * REPEATS) as u64);
    Ok(())
}
