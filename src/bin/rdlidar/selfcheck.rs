//! `rdlidar selfcheck`: the dot test of every operator and combinator.

use std::process::ExitCode;

use rdlidar::operator::dot_test_sweep;
use rdlidar::Real;

use crate::common::{errln, outln, CliResult, Globals};

/// Runs `selfcheck`: prints the sweep; exit status 1 if an operator fails.
pub fn run(globals: &Globals) -> CliResult<ExitCode> {
    let seed = globals.seed();
    let rows = dot_test_sweep(seed)?;
    outln!("dot test |<Ax,y> - <x,A*y>| / max(|Ax||y|, |x||A*y|), seed {seed}");
    outln!("{:<38} {:>12} {:>12}", "operator", "gap f32", "gap f64");
    for r in &rows {
        let flag = if r.passed() { "" } else { "  FAILED" };
        outln!(
            "{:<38} {:>12.2e} {:>12.2e}{flag}",
            r.name,
            r.f32.gap,
            r.f64.gap
        );
    }
    outln!(
        "tolerances: f32 {:.0e}, f64 {:.0e}",
        f32::DOT_TEST_TOL,
        f64::DOT_TEST_TOL
    );
    if rows.iter().all(|r| r.passed()) {
        Ok(ExitCode::SUCCESS)
    } else {
        errln!("error: some operators failed the dot test");
        Ok(ExitCode::FAILURE)
    }
}
