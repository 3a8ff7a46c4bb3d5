//! The f64 and baked f32 ProDMP decoders against mp_pytorch 0.1.4 reference vectors
//! (`tests/data/prodmp_vectors.json`, computed with mp_pytorch and committed with the tests).
use frmd_core::prodmp::{apply_row_f32, BakedProDmp, ProDmp, ProDmpConfig};
use serde_json::Value;
use std::path::PathBuf;

const F64_TOL: f64 = 1e-9;
const F32_TOL: f64 = 1e-4;

fn repo_copy() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("tests/data/prodmp_vectors.json")
}

fn load(path: &PathBuf) -> Value {
    let text = std::fs::read_to_string(path).expect("read vectors");
    serde_json::from_str(&text).expect("parse vectors")
}

fn f(v: &Value) -> f64 {
    v.as_f64().expect("number")
}

fn vec_f(v: &Value) -> Vec<f64> {
    v.as_array().expect("array").iter().map(f).collect()
}

fn mat_f(v: &Value) -> Vec<Vec<f64>> {
    v.as_array().expect("array").iter().map(vec_f).collect()
}

fn config_of(case: &Value) -> ProDmpConfig {
    let c = &case["config"];
    let ws = vec_f(&c["weights_scale"]);
    assert!(
        ws.iter().all(|w| *w == ws[0]),
        "test expects a uniform weights_scale"
    );
    ProDmpConfig {
        num_dof: c["num_dof"].as_u64().unwrap() as usize,
        num_basis: c["num_basis"].as_u64().unwrap() as usize,
        tau: f(&c["tau"]),
        delay: f(&c["delay"]),
        alpha: f(&c["alpha"]),
        alpha_phase: f(&c["alpha_phase"]),
        bandwidth_factor: f(&c["basis_bandwidth_factor"]),
        num_basis_outside: c["num_basis_outside"].as_u64().unwrap() as usize,
        dt: f(&c["dt"]),
        weights_scale: ws[0],
        goal_scale: f(&c["goal_scale"]),
        relative_goal: c["relative_goal"].as_bool().unwrap(),
        auto_scale_basis: c["auto_scale_basis"].as_bool().unwrap(),
    }
}

/// |a - b| / max(|b|, 1).
fn scaled_err(actual: f64, reference: f64) -> f64 {
    (actual - reference).abs() / reference.abs().max(1.0)
}

/// Checks every case with the f64 path; returns (cases, worst error).
fn check_f64(doc: &Value) -> (usize, f64) {
    let cases = doc["cases"].as_array().unwrap();
    let mut worst: f64 = 0.0;
    for case in cases {
        let name = case["name"].as_str().unwrap();
        let cfg = config_of(case);
        assert_eq!(
            case["config"]["pre_compute_length_factor"].as_u64(),
            Some(6)
        );
        let decoder = ProDmp::new(&cfg).unwrap();
        let derived = &case["derived"];
        assert_eq!(
            decoder.num_grid_points() as u64,
            derived["num_pre_compute"].as_u64().unwrap()
        );
        let mut table_max = vec![0.0; cfg.num_basis + 1];
        decoder.position_table_max(&mut table_max).unwrap();
        // Each derived value against the reference's, within `close`.
        let check = |what: &str, values: &[f64], key: &str, close: &dyn Fn(f64, f64) -> bool| {
            for (ours, reference) in values.iter().zip(vec_f(&derived[key])) {
                assert!(
                    close(*ours, reference),
                    "{name}: {what} {ours} vs {reference}"
                );
            }
        };
        let relative_1e9 =
            |ours: f64, reference: f64| (ours - reference).abs() <= 1e-9 * reference.abs();
        check(
            "centre",
            decoder.centers_phase(),
            "centers_phase",
            &|ours, reference| scaled_err(ours, reference) < 1e-12,
        );
        check(
            "bandwidth",
            decoder.bandwidths(),
            "bandwidth",
            &|ours, reference| (ours - reference).abs() / reference < 1e-12,
        );
        check("table max", &table_max, "pc_pos_basis_max", &relative_1e9);
        check(
            "scale",
            decoder.weights_goal_scale(),
            "weights_goal_scale",
            &relative_1e9,
        );
        let inputs = &case["inputs"];
        let params = vec_f(&inputs["params"]);
        let init_time = f(&inputs["init_time"]);
        let y0 = vec_f(&inputs["init_pos"]);
        let v0 = vec_f(&inputs["init_vel"]);
        for query in case["queries"].as_array().unwrap() {
            let times = vec_f(&query["times"]);
            let ref_pos = mat_f(&query["pos"]);
            let ref_vel = mat_f(&query["vel"]);
            let ref_h = query.get("pos_H_unscaled").map(mat_f);
            let mut pos = vec![0.0; cfg.num_dof];
            let mut vel = vec![0.0; cfg.num_dof];
            for (index, time) in times.iter().enumerate() {
                decoder
                    .decode_at(init_time, *time, &params, &y0, &v0, &mut pos, &mut vel)
                    .unwrap();
                for dof in 0..cfg.num_dof {
                    let ep = scaled_err(pos[dof], ref_pos[index][dof]);
                    let ev = scaled_err(vel[dof], ref_vel[index][dof]);
                    assert!(
                        ep < F64_TOL,
                        "{name} t={time} dof {dof}: pos {} vs {}",
                        pos[dof],
                        ref_pos[index][dof]
                    );
                    assert!(
                        ev < F64_TOL,
                        "{name} t={time} dof {dof}: vel {} vs {}",
                        vel[dof],
                        ref_vel[index][dof]
                    );
                    worst = worst.max(ep).max(ev);
                }
                if let Some(ref_h) = &ref_h {
                    let mut h = vec![0.0; cfg.num_basis + 1];
                    let mut dh = vec![0.0; cfg.num_basis + 1];
                    decoder
                        .unscaled_rows(init_time, *time, &mut h, &mut dh)
                        .unwrap();
                    for (ours, reference) in h.iter().zip(&ref_h[index]) {
                        assert!(
                            scaled_err(*ours, *reference) < 1e-12,
                            "{name} t={time}: H {ours} vs {reference}"
                        );
                    }
                }
            }
        }
    }
    (cases.len(), worst)
}

#[test]
fn all_cases_match_reference_f64() {
    let (count, worst) = check_f64(&load(&repo_copy()));
    assert_eq!(count, 18);
    eprintln!("f64: {count} cases, worst scaled error {worst:.3e}");
}

/// Baked f32 policy decoder on the cases in policy form (init 0, times k tau / N, k = 1..=N).
fn check_baked<const N: usize, const P: usize, const K: usize>(doc: &Value, name: &str) -> f64 {
    let case = doc["cases"]
        .as_array()
        .unwrap()
        .iter()
        .find(|c| c["name"] == name)
        .unwrap();
    let cfg = config_of(case);
    assert_eq!((cfg.num_dof, cfg.num_basis + 1), (K, P));
    let inputs = &case["inputs"];
    assert_eq!(f(&inputs["init_time"]), 0.0);
    let baked = BakedProDmp::<N, P>::from_config(&cfg).unwrap();
    let flat = vec_f(&inputs["params"]);
    let mut params = [[0.0f32; P]; K];
    for (dof, row) in params.iter_mut().enumerate() {
        for (j, value) in row.iter_mut().enumerate() {
            *value = flat[dof * P + j] as f32;
        }
    }
    let y0: [f32; K] = std::array::from_fn(|d| f(&inputs["init_pos"][d]) as f32);
    let v0: [f32; K] = std::array::from_fn(|d| f(&inputs["init_vel"][d]) as f32);
    let mut pos = [[0.0f32; K]; N];
    let mut vel = [[0.0f32; K]; N];
    baked.decode(&params, &y0, &v0, &mut pos, &mut vel).unwrap();
    let query = &case["queries"][0];
    let times = vec_f(&query["times"]);
    let ref_pos = mat_f(&query["pos"]);
    let ref_vel = mat_f(&query["vel"]);
    assert_eq!(times.len(), N);
    let mut worst: f64 = 0.0;
    for t in 0..N {
        assert!((BakedProDmp::<N, P>::query_time(&cfg, t + 1) - times[t]).abs() < 1e-12);
        for d in 0..K {
            let ep = scaled_err(pos[t][d] as f64, ref_pos[t][d]);
            let ev = scaled_err(vel[t][d] as f64, ref_vel[t][d]);
            assert!(
                ep < F32_TOL && ev < F32_TOL,
                "{name} t{t} d{d}: {ep:e} {ev:e}"
            );
            worst = worst.max(ep).max(ev);
        }
    }
    worst
}

#[test]
fn baked_f32_matches_reference_on_policy_form_cases() {
    let doc = load(&repo_copy());
    let a = check_baked::<12, 13, 3>(&doc, "mpd_deflect_spheres_like");
    let b = check_baked::<12, 4, 7>(&doc, "mpd_ligating_loop_like");
    eprintln!("baked f32 worst scaled error: deflect {a:.3e}, ligating {b:.3e}");
}

/// Every case in f32: the f64 linear rows of the case's own times, rounded to f32 and applied with
/// the baked decoder's f32 kernel (`apply_row_f32`), against the float64 reference.
#[test]
fn f32_linear_rows_match_reference_on_all_cases() {
    let doc = load(&repo_copy());
    let mut worst: f64 = 0.0;
    for case in doc["cases"].as_array().unwrap() {
        let name = case["name"].as_str().unwrap();
        let cfg = config_of(case);
        let decoder = ProDmp::new(&cfg).unwrap();
        let width = cfg.num_basis + 1;
        let inputs = &case["inputs"];
        let params: Vec<f32> = vec_f(&inputs["params"]).iter().map(|x| *x as f32).collect();
        let y0: Vec<f32> = vec_f(&inputs["init_pos"])
            .iter()
            .map(|x| *x as f32)
            .collect();
        let v0: Vec<f32> = vec_f(&inputs["init_vel"])
            .iter()
            .map(|x| *x as f32)
            .collect();
        let init_time = f(&inputs["init_time"]);
        for query in case["queries"].as_array().unwrap() {
            let ref_pos = mat_f(&query["pos"]);
            let ref_vel = mat_f(&query["vel"]);
            for (index, time) in vec_f(&query["times"]).iter().enumerate() {
                let (mut pos_row, mut vel_row) = (vec![0.0; width], vec![0.0; width]);
                let c = decoder
                    .linear_row(init_time, *time, &mut pos_row, &mut vel_row)
                    .unwrap();
                let pos32: Vec<f32> = pos_row.iter().map(|x| *x as f32).collect();
                let vel32: Vec<f32> = vel_row.iter().map(|x| *x as f32).collect();
                for dof in 0..cfg.num_dof {
                    let theta = &params[dof * width..(dof + 1) * width];
                    let p = apply_row_f32(
                        &pos32,
                        c.pos_y0 as f32,
                        c.pos_v0 as f32,
                        theta,
                        y0[dof],
                        v0[dof],
                    );
                    let v = apply_row_f32(
                        &vel32,
                        c.vel_y0 as f32,
                        c.vel_v0 as f32,
                        theta,
                        y0[dof],
                        v0[dof],
                    );
                    let ep = scaled_err(p as f64, ref_pos[index][dof]);
                    let ev = scaled_err(v as f64, ref_vel[index][dof]);
                    assert!(
                        ep < F32_TOL && ev < F32_TOL,
                        "{name} t={time} dof {dof}: {ep:e} {ev:e}"
                    );
                    worst = worst.max(ep).max(ev);
                }
            }
        }
    }
    eprintln!("f32 linear rows: worst scaled error {worst:.3e}");
}
