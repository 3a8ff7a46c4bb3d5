//! `frmd bench` times frmd-core's policies of every backbone, not only the MLP's.

use super::*;

#[test]
fn synthetic_transformer_student_gets_its_frmd_core_rows() {
    let cfg = BenchConfig {
        synthetic: true,
        backbone: "transformer:1,2,32".parse().unwrap(),
        calls: 2,
        warmup: 0,
        ..BenchConfig::default()
    };
    let (rows, note) = bench_rows(&cfg).unwrap();
    assert_eq!(note, None, "frmd-core policies missing");
    for label in ["frmd-core int8 1-step", "frmd-core f32 1-step"] {
        let row = rows
            .iter()
            .find(|r| r.label == label)
            .unwrap_or_else(|| panic!("no `{label}` row in {rows:?}"));
        assert_eq!(row.backbone, "transformer 1x2h 32");
        assert!(row.median_us > 0.0 && row.p99_us >= row.median_us);
    }
    assert_eq!(rows[0].label, "frmd-core int8 1-step");
}
