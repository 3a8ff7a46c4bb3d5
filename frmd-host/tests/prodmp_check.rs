//! `frmd prodmp check` and the vectors schema (frmd_host::prodmp_vectors).
use frmd_host::prodmp_vectors::{self, check_case, Tolerances, VectorsError};
use serde_json::Value;
use std::path::{Path, PathBuf};
use std::process::Command;

fn vectors_path() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../frmd-core/tests/data/prodmp_vectors.json")
}

fn vectors_json() -> Value {
    serde_json::from_str(&std::fs::read_to_string(vectors_path()).unwrap()).unwrap()
}

fn parse(value: &Value) -> Result<prodmp_vectors::VectorsFile, VectorsError> {
    prodmp_vectors::parse(&value.to_string(), Path::new("test.json"))
}

/// Moves one reference value by 1e-6.
fn nudge(value: &mut Value) {
    *value = (value.as_f64().unwrap() + 1e-6).into();
}

fn frmd_check(path: &Path) -> (i32, String) {
    let out = Command::new(env!("CARGO_BIN_EXE_frmd"))
        .args(["prodmp", "check", "--vectors"])
        .arg(path)
        .output()
        .unwrap();
    let text =
        String::from_utf8_lossy(&out.stdout).to_string() + &String::from_utf8_lossy(&out.stderr);
    (out.status.code().unwrap_or(-1), text)
}

#[test]
fn all_reference_cases_pass() {
    let file = prodmp_vectors::load(&vectors_path()).unwrap();
    assert_eq!(file.cases.len(), 18);
    let tol = Tolerances::default();
    for (index, case) in file.cases.iter().enumerate() {
        let report = check_case(case, index, &tol);
        assert!(report.pass(), "{report:?}");
        assert!(report.derived_err.is_some(), "derived values are checked");
    }
}

#[test]
fn corrupted_reference_fails() {
    let mut json = vectors_json();
    nudge(&mut json["cases"][3]["queries"][1]["vel"][17][4]);
    let file = parse(&json).unwrap();
    let tol = Tolerances::default();
    let report = check_case(&file.cases[3], 3, &tol);
    assert!(!report.pass());
    assert!(report.queries[1].f64_err > 1e-7 && report.queries[1].f64_err < 1e-5);
    // The other cases are unaffected.
    assert!(check_case(&file.cases[2], 2, &tol).pass());
}

#[test]
fn per_basis_weights_scale_is_applied_per_column() {
    // weights_scale s_k with params theta_k / s_k decodes like scale 1 with theta_k.
    let mut json = vectors_json();
    let case = &mut json["cases"][0];
    let scales = [1.0, 2.0, 0.5, 4.0, 0.25];
    case["config"]["weights_scale"] = serde_json::json!(scales);
    for (k, s) in scales.iter().enumerate() {
        let theta = case["inputs"]["params"][k].as_f64().unwrap();
        case["inputs"]["params"][k] = (theta / s).into();
    }
    case.as_object_mut().unwrap().remove("derived");
    let file = parse(&json).unwrap();
    let tol = Tolerances::default();
    let report = check_case(&file.cases[0], 0, &tol);
    assert!(report.pass(), "{report:?}");
}

#[test]
fn malformed_files_give_named_errors() {
    let base = vectors_json();
    // Not JSON at all / JSON of another kind.
    let err = prodmp_vectors::parse("hello", Path::new("x.json")).unwrap_err();
    assert!(matches!(err, VectorsError::Malformed { .. }), "{err}");
    let err = parse(&serde_json::json!({"weights": [1, 2]})).unwrap_err();
    assert!(
        matches!(err, VectorsError::Malformed { .. }) && err.to_string().contains("cases"),
        "{err}"
    );
    // NaN written by Python's json module is not JSON.
    let err =
        prodmp_vectors::parse(r#"{"cases": [{"name": NaN}]}"#, Path::new("x.json")).unwrap_err();
    assert!(matches!(err, VectorsError::Malformed { .. }), "{err}");
    assert!(matches!(
        parse(&serde_json::json!({"cases": []})).unwrap_err(),
        VectorsError::NoCases
    ));
    // Missing field.
    let mut json = base.clone();
    json["cases"][1]["config"]
        .as_object_mut()
        .unwrap()
        .remove("tau");
    let err = parse(&json).unwrap_err();
    assert!(
        matches!(err, VectorsError::Malformed { .. }) && err.to_string().contains("tau"),
        "{err}"
    );
    // Wrong lengths name the case and field.
    let mut json = base.clone();
    json["cases"][2]["inputs"]["params"]
        .as_array_mut()
        .unwrap()
        .pop();
    match parse(&json).unwrap_err() {
        VectorsError::WrongLength {
            case,
            field,
            expected,
            found,
        } => {
            assert_eq!(
                (case.as_str(), field.as_str(), expected, found),
                ("#2 d7_b20_tau3_relgoal", "inputs.params", 147, 146)
            );
        }
        other => panic!("unexpected {other}"),
    }
    let mut json = base.clone();
    json["cases"][0]["queries"][0]["pos"][3]
        .as_array_mut()
        .unwrap()
        .push(1.0.into());
    let err = parse(&json).unwrap_err();
    assert!(
        matches!(&err, VectorsError::WrongLength { field, .. } if field == "queries[0].pos[3]"),
        "{err}"
    );
    // Unsupported options.
    let mut json = base.clone();
    json["cases"][0]["config"]["mp_type"] = "promp".into();
    assert!(matches!(
        parse(&json).unwrap_err(),
        VectorsError::Unsupported { .. }
    ));
    let mut json = base;
    json["cases"][0]["config"]["learn_tau"] = true.into();
    assert!(matches!(
        parse(&json).unwrap_err(),
        VectorsError::Unsupported { .. }
    ));
}

#[test]
fn invalid_config_or_time_is_a_failing_case_not_a_crash() {
    let mut json = vectors_json();
    json["cases"][0]["config"]["alpha"] = (-1.0).into();
    json["cases"][1]["queries"][0]["times"][5] = 7.5.into(); // beyond 6 tau
    let file = parse(&json).unwrap();
    let tol = Tolerances::default();
    let r0 = check_case(&file.cases[0], 0, &tol);
    assert!(
        !r0.pass() && r0.error.as_deref().unwrap_or("").contains("alpha"),
        "{r0:?}"
    );
    let r1 = check_case(&file.cases[1], 1, &tol);
    assert!(
        !r1.pass() && r1.error.as_deref().unwrap_or("").contains("pre-computed"),
        "{r1:?}"
    );
}

#[test]
fn float32_reference_uses_the_f32_tolerance() {
    let mut json = vectors_json();
    nudge(&mut json["cases"][4]["queries"][0]["pos"][6][1]);
    let tol = Tolerances::default();
    assert!(!check_case(&parse(&json).unwrap().cases[4], 4, &tol).pass());
    json["cases"][4]["config"]["dtype"] = "float32".into();
    let report = check_case(&parse(&json).unwrap().cases[4], 4, &tol);
    assert!(report.pass() && report.f64_tol == tol.f32_err, "{report:?}");
    assert!(report.config_summary.contains("ref float32"));
}

#[test]
fn cli_exit_codes() {
    let dir = std::env::temp_dir().join(format!("frmd-prodmp-check-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let (code, text) = frmd_check(&vectors_path());
    assert_eq!(code, 0, "{text}");
    assert!(text.contains("18 of 18 cases pass"), "{text}");
    let mut json = vectors_json();
    json["cases"][5]["queries"][0]["pos"][2][1] = 0.5.into();
    let bad = dir.join("bad.json");
    std::fs::write(&bad, json.to_string()).unwrap();
    let (code, text) = frmd_check(&bad);
    assert_eq!(code, 1, "{text}");
    assert!(text.contains("FAIL") && text.contains("17 of 18"), "{text}");
    let garbage = dir.join("garbage.json");
    std::fs::write(&garbage, "[1, 2, 3]").unwrap();
    let (code, text) = frmd_check(&garbage);
    assert_eq!(code, 2, "{text}");
    assert!(text.contains("not a ProDMP vectors file"), "{text}");
    let (code, text) = frmd_check(&dir.join("missing.json"));
    assert_eq!(code, 2, "{text}");
    assert!(text.contains("cannot read"), "{text}");
    std::fs::remove_dir_all(&dir).ok();
}

#[test]
fn model_vectors_cover_the_remaining_options() {
    // Pure-Python model of the reference (tests/data/gen_prodmp_model_vectors.py), not mp_pytorch:
    // length factors 3/4, per-basis weights_scale, disable_weights/disable_goal, b = 1/2 with
    // delays and init times, times up to the end of the pre-computed range.
    let path =
        PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("tests/data/prodmp_model_vectors.json");
    let file = prodmp_vectors::load(&path).unwrap();
    assert_eq!(file.cases.len(), 14);
    let c = |i: usize| &file.cases[i].config;
    assert!(c(5).disable_weights && c(8).disable_goal && c(1).pre_compute_length_factor == 3);
    let tol = Tolerances::default();
    for (index, case) in file.cases.iter().enumerate() {
        let report = check_case(case, index, &tol);
        assert!(report.pass(), "{report:?}");
    }
}
