//! `frmd prodmp check`: compares the ProDMP decoder with reference vectors.
use crate::prodmp_vectors::{self, check_case, Tolerances};
use clap::Subcommand;
use std::path::PathBuf;
use std::process::ExitCode;

#[derive(Subcommand, Debug)]
pub enum ProdmpCommand {
    /// Decode every case of a vectors file with the f64 decoder and with f32 linear rows (the
    /// baked decoder's arithmetic) and report errors; exits 1 if any case is above tolerance.
    Check {
        /// Vectors file in the schema of frmd-core/tests/data/prodmp_vectors.json.
        #[arg(long)]
        vectors: PathBuf,
        /// Pass threshold of the f64 path, error |ours - ref| / max(|ref|, 1).
        #[arg(long, default_value_t = Tolerances::default().f64_err)]
        f64_tol: f64,
        /// Pass threshold of the f32 path, same error measure.
        #[arg(long, default_value_t = Tolerances::default().f32_err)]
        f32_tol: f64,
    },
}

pub fn run(cmd: ProdmpCommand) -> anyhow::Result<ExitCode> {
    match cmd {
        ProdmpCommand::Check {
            vectors,
            f64_tol,
            f32_tol,
        } => check(
            &vectors,
            Tolerances {
                f64_err: f64_tol,
                f32_err: f32_tol,
            },
        ),
    }
}

fn check(path: &std::path::Path, tol: Tolerances) -> anyhow::Result<ExitCode> {
    if !(tol.f64_err >= 0.0 && tol.f32_err >= 0.0) {
        anyhow::bail!("tolerances must be non-negative numbers");
    }
    let file = prodmp_vectors::load(path)?;
    println!(
        "{}: {} cases{}",
        path.display(),
        file.cases.len(),
        file.library
            .as_deref()
            .map(|l| format!(" from {l}"))
            .unwrap_or_default()
    );
    println!("error = |ours - ref| / max(|ref|, 1) over pos and vel; f64 also covers pos_H_unscaled and \
         derived values (relative); f32 = f64 linear rows rounded to f32 (baked decoder arithmetic); \
         float32 references are held to the f32 tolerance");
    println!(
        "{:<36} {:<58} {:<34} {:>10} {:>10}  result",
        "case", "config", "query set", "f64 err", "f32 err"
    );
    let (mut failed, mut worst64, mut worst32) = (0usize, 0.0f64, 0.0f64);
    for (index, case) in file.cases.iter().enumerate() {
        let report = check_case(case, index, &tol);
        let pass = report.pass();
        if !pass {
            failed += 1;
        }
        let derived = report.derived_err.unwrap_or(0.0);
        worst64 = worst64.max(derived);
        for (q, query) in report.queries.iter().enumerate() {
            worst64 = worst64.max(query.f64_err);
            worst32 = worst32.max(query.f32_err);
            let f64_err = query.f64_err.max(derived);
            let verdict = if query.pass && f64_err <= report.f64_tol && report.error.is_none() {
                "PASS"
            } else {
                "FAIL"
            };
            let summary = if query.policy_form {
                format!("{} policy", query.summary)
            } else {
                query.summary.clone()
            };
            let (label, config) = if q == 0 {
                (report.label.as_str(), report.config_summary.as_str())
            } else {
                ("", "")
            };
            println!(
                "{label:<36} {config:<58} {summary:<34} {f64_err:>10.2e} {:>10.2e}  {verdict}",
                query.f32_err
            );
        }
        if report.queries.is_empty() {
            println!(
                "{:<36} {:<58} {:<34} {:>10} {:>10}  FAIL",
                report.label, report.config_summary, "-", "-", "-"
            );
        }
        if let Some(error) = &report.error {
            println!("    error: {error}");
        }
    }
    println!(
        "{} of {} cases pass (f64 tol {:.0e}, f32 tol {:.0e}); worst f64 err {worst64:.2e}, worst f32 err {worst32:.2e}",
        file.cases.len() - failed,
        file.cases.len(),
        tol.f64_err,
        tol.f32_err
    );
    Ok(if failed == 0 {
        ExitCode::SUCCESS
    } else {
        ExitCode::FAILURE
    })
}
