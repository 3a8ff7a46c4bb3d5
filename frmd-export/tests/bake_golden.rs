//! The committed baked module in `tests/baked/` (compiled by `tests/bake_module.rs`) is exactly
//! what `mlp::bake::write_module` produces for the sample policy. Regenerate with
//! `FRMD_BLESS=1 cargo test -p frmd-export --test bake_golden`.

use std::path::PathBuf;

use frmd_export::bake::{MODULE_FILE, WEIGHTS_FILE};
use frmd_export::mlp::bake::write_module;
use frmd_test_support::random_policy::{GOLDEN_SEED, GOLDEN_STEPS};

#[test]
fn committed_baked_module_is_current() {
    let policy = frmd_test_support::random_policy::sample_policy(GOLDEN_SEED, GOLDEN_STEPS);
    let golden = PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("tests/baked");
    if std::env::var_os("FRMD_BLESS").is_some() {
        write_module(&policy, &golden).unwrap();
    }
    let fresh = std::env::temp_dir().join(format!("frmd-bake-{}", std::process::id()));
    write_module(&policy, &fresh).unwrap();
    for file in [MODULE_FILE, WEIGHTS_FILE] {
        let expected = std::fs::read(golden.join(file)).unwrap();
        let actual = std::fs::read(fresh.join(file)).unwrap();
        assert!(
            expected == actual,
            "{file} differs from the committed golden (FRMD_BLESS=1 to update)"
        );
    }
    std::fs::remove_dir_all(&fresh).unwrap();
}

#[test]
fn bake_refuses_non_finite_values() {
    let mut policy = frmd_test_support::random_policy::sample_policy(GOLDEN_SEED, 1);
    policy.prodmp.pos_y0[2] = f32::NAN;
    let dir = std::env::temp_dir().join(format!("frmd-bake-nan-{}", std::process::id()));
    let error = write_module(&policy, &dir).unwrap_err();
    assert!(
        format!("{error:#}").contains("NaN or infinity"),
        "{error:#}"
    );
    assert!(!dir.exists());
}
