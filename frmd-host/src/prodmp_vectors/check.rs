//! Decodes a reference case with the f64 decoder and with f32 linear rows, and measures errors.
//!
//! Errors are `|ours - ref| / max(|ref|, 1)` (absolute for values up to 1, relative above), the
//! maximum over every position and velocity of a query set (and over `pos_H_unscaled` and the
//! derived values for the f64 path). The f32 path rounds the f64 linear rows of the query's own
//! times to f32 and applies them with `frmd_core::prodmp::apply_row_f32`, the kernel of the
//! baked firmware decoder, so it works for any times, initial time and config.
use super::{Case, ScaleSpec};
use frmd_core::prodmp::{apply_row, apply_row_f32, ProDmp, ProDmpConfig, ProDmpError};

/// Pass thresholds for the two paths.
#[derive(Clone, Copy, Debug)]
pub struct Tolerances {
    pub f64_err: f64,
    pub f32_err: f64,
}

impl Default for Tolerances {
    fn default() -> Self {
        Self {
            f64_err: 1e-9,
            f32_err: 1e-4,
        }
    }
}

/// Result of one query set of a case.
#[derive(Clone, Debug)]
pub struct QueryReport {
    /// e.g. `12 t in [0, 1]`.
    pub summary: String,
    /// Times are `k tau / N`, `k = 1..=N`, with initial time 0 and no delay: the layout
    /// `BakedProDmp<N, P>` bakes.
    pub policy_form: bool,
    pub f64_err: f64,
    pub f32_err: f64,
    pub pass: bool,
}

/// Result of one case.
#[derive(Clone, Debug)]
pub struct CaseReport {
    pub label: String,
    pub config_summary: String,
    /// f64 threshold used for this case: `Tolerances::f64_err`, or `f32_err` when the reference
    /// itself was computed in float32 (`config.dtype` other than "float64").
    pub f64_tol: f64,
    /// Worst relative error of the derived values present in the file (centres, bandwidths,
    /// table maxima, scales); `None` if the file has none.
    pub derived_err: Option<f64>,
    /// Grid size mismatch or decoder error, if any (the case then fails).
    pub error: Option<String>,
    pub queries: Vec<QueryReport>,
}

impl CaseReport {
    pub fn pass(&self) -> bool {
        self.error.is_none()
            && self.derived_err.is_none_or(|e| e <= self.f64_tol)
            && self.queries.iter().all(|q| q.pass)
    }
}

fn scaled_err(ours: f64, reference: f64) -> f64 {
    let err = (ours - reference).abs() / reference.abs().max(1.0);
    if err.is_nan() {
        f64::INFINITY
    } else {
        err
    }
}

fn relative_err(ours: f64, reference: f64) -> f64 {
    let err = (ours - reference).abs() / reference.abs().max(f64::MIN_POSITIVE);
    if err.is_nan() {
        f64::INFINITY
    } else {
        err
    }
}

fn max_relative(ours: &[f64], reference: &[f64]) -> f64 {
    ours.iter()
        .zip(reference)
        .map(|(a, b)| relative_err(*a, *b))
        .fold(0.0, f64::max)
}

/// The decoder config of a case plus per-column factors for a per-basis `weights_scale`
/// (the core config holds one scalar; the decoder is linear per column, so the rest is a factor).
fn core_config(case: &Case) -> (ProDmpConfig, Vec<f64>) {
    let c = &case.config;
    let width = c.num_basis + 1;
    let (scalar, factors) = match &c.weights_scale {
        ScaleSpec::Scalar(scale) => (*scale, vec![1.0; width]),
        ScaleSpec::PerBasis(scales) => match scales.first() {
            Some(first) if scales.iter().all(|s| s == first) => (*first, vec![1.0; width]),
            _ => (1.0, scales.iter().copied().chain([1.0]).collect()),
        },
    };
    let cfg = ProDmpConfig {
        num_dof: c.num_dof,
        num_basis: c.num_basis,
        tau: c.tau,
        delay: c.delay,
        alpha: c.alpha,
        alpha_phase: c.alpha_phase,
        bandwidth_factor: c.basis_bandwidth_factor,
        num_basis_outside: c.num_basis_outside,
        dt: c.dt,
        weights_scale: scalar,
        goal_scale: c.goal_scale,
        relative_goal: c.relative_goal,
        auto_scale_basis: c.auto_scale_basis,
    };
    (cfg, factors)
}

/// `[w_0..w_{b-1}, g]` of every DoF, zero-filling parts disabled by `disable_weights`/`disable_goal`.
fn full_params(case: &Case) -> Vec<f64> {
    let c = &case.config;
    let stored = case.stored_params_per_dof().max(1);
    let mut full = Vec::with_capacity(c.num_dof * (c.num_basis + 1));
    for dof in case.inputs.params.chunks(stored) {
        if c.disable_weights {
            full.extend(std::iter::repeat_n(0.0, c.num_basis));
            full.extend_from_slice(dof);
        } else if c.disable_goal {
            full.extend_from_slice(dof);
            full.push(0.0);
        } else {
            full.extend_from_slice(dof);
        }
    }
    full
}

fn summarize_config(case: &Case) -> String {
    let c = &case.config;
    let mut text = format!(
        "dof {} b {} tau {} dt {} a {} ap {} bw {}",
        c.num_dof, c.num_basis, c.tau, c.dt, c.alpha, c.alpha_phase, c.basis_bandwidth_factor
    );
    if c.delay != 0.0 {
        text += &format!(" delay {}", c.delay);
    }
    if c.num_basis_outside != 0 {
        text += &format!(" out {}", c.num_basis_outside);
    }
    if c.pre_compute_length_factor != frmd_core::prodmp::PRE_COMPUTE_LENGTH_FACTOR {
        text += &format!(" L {}", c.pre_compute_length_factor);
    }
    text += if c.relative_goal { " rel" } else { " abs" };
    if c.auto_scale_basis {
        text += " auto";
    }
    match &c.weights_scale {
        ScaleSpec::Scalar(s) if *s != 1.0 => text += &format!(" ws {s}"),
        ScaleSpec::PerBasis(v) if v.iter().any(|s| *s != 1.0) => match v.first() {
            Some(first) if v.iter().all(|s| s == first) => text += &format!(" ws {first}"),
            _ => text += " ws [per basis]",
        },
        _ => {}
    }
    if let Some(dtype) = c.dtype.as_deref().filter(|d| *d != "float64") {
        text += &format!(" ref {dtype}");
    }
    if c.goal_scale != 1.0 {
        text += &format!(" gs {}", c.goal_scale);
    }
    if c.disable_weights {
        text += " no-w";
    }
    if c.disable_goal {
        text += " no-g";
    }
    text
}

fn is_policy_form(case: &Case, times: &[f64]) -> bool {
    let n = times.len() as f64;
    case.inputs.init_time == 0.0
        && case.config.delay == 0.0
        && !times.is_empty()
        && times.iter().enumerate().all(|(k, t)| {
            let expected = (k + 1) as f64 * (case.config.tau / n);
            (t - expected).abs() <= 1e-9 * case.config.tau.max(1.0)
        })
}

fn derived_error(case: &Case, decoder: &ProDmp, factors: &[f64]) -> Result<Option<f64>, String> {
    let Some(derived) = &case.derived else {
        return Ok(None);
    };
    let mut worst: Option<f64> = None;
    let mut note = |e: f64| worst = Some(worst.map_or(e, |w: f64| w.max(e)));
    if let Some(points) = derived.num_pre_compute {
        if points != decoder.num_grid_points() {
            return Err(format!(
                "grid has {} points, reference num_pre_compute {points}",
                decoder.num_grid_points()
            ));
        }
    }
    if let Some(centers) = &derived.centers_phase {
        note(max_relative(decoder.centers_phase(), centers));
    }
    if let Some(bandwidth) = &derived.bandwidth {
        note(max_relative(decoder.bandwidths(), bandwidth));
    }
    if let Some(scale) = &derived.weights_goal_scale {
        let ours: Vec<f64> = decoder
            .weights_goal_scale()
            .iter()
            .zip(factors)
            .map(|(a, b)| a * b)
            .collect();
        note(max_relative(&ours, scale));
    }
    if let Some(table_max) = &derived.pc_pos_basis_max {
        let mut ours = vec![0.0; decoder.num_params_per_dof()];
        decoder
            .position_table_max(&mut ours)
            .map_err(|e| e.to_string())?;
        note(max_relative(&ours, table_max));
    }
    Ok(worst)
}

/// Worst errors of one query set: (f64 path incl. `pos_H_unscaled`, f32 rows).
fn query_errors(
    case: &Case,
    decoder: &ProDmp,
    factors: &[f64],
    query: &super::Query,
) -> Result<(f64, f64), ProDmpError> {
    let c = &case.config;
    let width = c.num_basis + 1;
    let inputs = &case.inputs;
    let params = full_params(case);
    let params32: Vec<f32> = params.iter().map(|x| *x as f32).collect();
    let (mut f64_err, mut f32_err) = (0.0f64, 0.0f64);
    let (mut pos_row, mut vel_row) = (vec![0.0; width], vec![0.0; width]);
    for (index, &time) in query.times.iter().enumerate() {
        let coeffs = decoder.linear_row(inputs.init_time, time, &mut pos_row, &mut vel_row)?;
        for ((pos, vel), factor) in pos_row.iter_mut().zip(vel_row.iter_mut()).zip(factors) {
            *pos *= factor;
            *vel *= factor;
        }
        let pos32: Vec<f32> = pos_row.iter().map(|x| *x as f32).collect();
        let vel32: Vec<f32> = vel_row.iter().map(|x| *x as f32).collect();
        let (ref_pos, ref_vel) = match (query.pos.get(index), query.vel.get(index)) {
            (Some(p), Some(v)) => (p, v),
            _ => return Err(ProDmpError::WrongLength),
        };
        let dofs = params.chunks_exact(width).zip(params32.chunks_exact(width));
        let initial = inputs.init_pos.iter().zip(&inputs.init_vel);
        for (((theta, theta32), (y0, v0)), (ref_p, ref_v)) in
            dofs.zip(initial).zip(ref_pos.iter().zip(ref_vel))
        {
            let pos = apply_row(&pos_row, coeffs.pos_y0, coeffs.pos_v0, theta, *y0, *v0);
            let vel = apply_row(&vel_row, coeffs.vel_y0, coeffs.vel_v0, theta, *y0, *v0);
            f64_err = f64_err
                .max(scaled_err(pos, *ref_p))
                .max(scaled_err(vel, *ref_v));
            let (y0, v0) = (*y0 as f32, *v0 as f32);
            let pos = apply_row_f32(
                &pos32,
                coeffs.pos_y0 as f32,
                coeffs.pos_v0 as f32,
                theta32,
                y0,
                v0,
            );
            let vel = apply_row_f32(
                &vel32,
                coeffs.vel_y0 as f32,
                coeffs.vel_v0 as f32,
                theta32,
                y0,
                v0,
            );
            f32_err = f32_err
                .max(scaled_err(pos as f64, *ref_p))
                .max(scaled_err(vel as f64, *ref_v));
        }
        if let Some(ref_h) = query.pos_h_unscaled.as_ref().and_then(|h| h.get(index)) {
            let (mut h, mut dh) = (vec![0.0; width], vec![0.0; width]);
            decoder.unscaled_rows(inputs.init_time, time, &mut h, &mut dh)?;
            for (ours, reference) in h.iter().zip(ref_h) {
                f64_err = f64_err.max(scaled_err(*ours, *reference));
            }
        }
    }
    Ok((f64_err, f32_err))
}

fn summarize_times(case: &Case, times: &[f64]) -> String {
    let min = times.iter().copied().fold(f64::INFINITY, f64::min);
    let max = times.iter().copied().fold(f64::NEG_INFINITY, f64::max);
    let mut text = format!("{} t in [{min:.4}, {max:.4}]", times.len());
    if case.inputs.init_time != 0.0 {
        text += &format!(" t0 {}", case.inputs.init_time);
    }
    text
}

/// Decodes every query set of `case` (validated, see [`Case::validate`]) and compares.
pub fn check_case(case: &Case, index: usize, tol: &Tolerances) -> CaseReport {
    let float64_reference = case.config.dtype.as_deref().is_none_or(|d| d == "float64");
    let f64_tol = if float64_reference {
        tol.f64_err
    } else {
        tol.f32_err.max(tol.f64_err)
    };
    let mut report = CaseReport {
        label: case.label(index),
        f64_tol,
        config_summary: summarize_config(case),
        derived_err: None,
        error: None,
        queries: Vec::new(),
    };
    let (cfg, factors) = core_config(case);
    let decoder = match ProDmp::with_length_factor(&cfg, case.config.pre_compute_length_factor) {
        Ok(decoder) => decoder,
        Err(error) => {
            report.error = Some(format!("decoder rejects config: {error}"));
            return report;
        }
    };
    match derived_error(case, &decoder, &factors) {
        Ok(err) => report.derived_err = err,
        Err(message) => report.error = Some(message),
    }
    for query in &case.queries {
        let summary = summarize_times(case, &query.times);
        let policy_form = is_policy_form(case, &query.times);
        match query_errors(case, &decoder, &factors, query) {
            Ok((f64_err, f32_err)) => report.queries.push(QueryReport {
                summary,
                policy_form,
                f64_err,
                f32_err,
                pass: f64_err <= f64_tol && f32_err <= tol.f32_err,
            }),
            Err(error) => {
                report.error = Some(format!("decoding {summary}: {error}"));
                report.queries.push(QueryReport {
                    summary,
                    policy_form,
                    f64_err: f64::INFINITY,
                    f32_err: f64::INFINITY,
                    pass: false,
                });
            }
        }
    }
    report
}

#[cfg(test)]
mod tests {
    use super::*;

    fn case_with(disable_weights: bool, disable_goal: bool, params: Vec<f64>) -> Case {
        let json = serde_json::json!({
            "name": "t", "config": {"num_dof": 2, "tau": 1.0, "delay": 0.0, "alpha_phase": 3.0,
            "num_basis": 2, "basis_bandwidth_factor": 3.0, "dt": 0.01, "alpha": 25.0,
            "disable_weights": disable_weights, "disable_goal": disable_goal},
            "inputs": {"params": params, "init_time": 0.0, "init_pos": [0.0, 0.0], "init_vel": [0.0, 0.0]},
            "queries": []
        });
        serde_json::from_value(json).expect("test case")
    }

    #[test]
    fn disabled_parts_are_zero_filled() {
        assert_eq!(
            full_params(&case_with(false, false, vec![1., 2., 3., 4., 5., 6.])),
            vec![1., 2., 3., 4., 5., 6.]
        );
        assert_eq!(
            full_params(&case_with(true, false, vec![7., 8.])),
            vec![0., 0., 7., 0., 0., 8.]
        );
        assert_eq!(
            full_params(&case_with(false, true, vec![1., 2., 3., 4.])),
            vec![1., 2., 0., 3., 4., 0.]
        );
    }
}
