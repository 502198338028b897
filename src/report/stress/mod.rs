//! The numerical stress suite behind `rdlidar stress`: checks that the operator and the solvers
//! stay accurate where round-off, conditioning and noise are at their worst.
//!
//! Four groups of rows (docs/stress.md has the measurements and the reasons for each tolerance):
//!
//! * [`Group::Precision`]: the `f32` operator against the `f64` one on the same pulse, codes and
//!   inputs, as the number of samples K grows from 10⁴ to 10⁷ (a tiny pixel grid keeps the codes
//!   small): ‖A₃₂x − A₆₄x‖/‖A₆₄x‖ for both forward paths, and the same for the adjoint, beside what
//!   a naive `f32` sum would give.
//! * [`Group::DotTest`]: the dot-test gap |⟨Ax, y⟩ − ⟨x, A*y⟩| / max(‖Ax‖‖y‖, ‖x‖‖A*y‖) of the
//!   same operators ([`DotTest`](crate::operator::DotTest)), in `f32` and `f64`.
//! * [`Group::Conditioning`]: the extreme singular values of A restricted to the columns of a
//!   scene's true support, from compressive to redundant pulse lengths, by the Lanczos iteration
//!   and inverse iteration, checked against the eigenvalues of the dense Gram matrix.
//! * [`Group::Solvers`]: every [`Method`] through [`reconstruct`](crate::recon::reconstruct) and
//!   [`compare`](crate::recon::compare) on the paper scene under hard conditions: amplitudes
//!   spanning 10⁻⁶…1, a pulse of duty cycle 0.05, ternary codes with P(0) = 0.9, and Gaussian
//!   noise from 40 down to 0 dB SNR.
//!
//! Every random draw comes from the one seed of [`StressConfig`], so one seed gives one table
//! (apart from the times) on a given machine and thread count.
//!
//! ```no_run
//! use rdlidar::report::stress::{run_stress, StressConfig};
//!
//! # fn main() -> rdlidar::Result<()> {
//! let rows = run_stress(&StressConfig::quick(0), |_| std::ops::ControlFlow::Continue(()))?;
//! assert!(rows.iter().all(|r| r.passed));
//! # Ok(())
//! # }
//! ```

mod conditioning;
mod precision;
mod solvers;

use std::ops::ControlFlow;

use serde::ser::SerializeMap;
use serde::{Serialize, Serializer};

use crate::error::Result;
use crate::lidar::Geometry;
use crate::recon::Method;

pub use conditioning::{
    BLOCK, INVERSE_MAX_ITER, INVERSE_TOL, NUMERICAL_ZERO, POWER_MAX_ITER, POWER_TOL, SIGMA_TOL,
    SIGMA_TOL_EPS,
};
pub use precision::{ADJOINT_TOL_EPS, DOT_TOL_EPS, FORWARD_TOL_EPS};
pub use solvers::{
    ceiling, solver_tolerance, SolverCase, AMP_TOL, COARSE_DYNAMIC_TOL, COARSE_LOW_DUTY_TOL,
    EXACT_TOL, FLOOR_MARGIN, LOW_DUTY, LOW_DUTY_TOL, NOISE_FACTOR, PEAK_FLOOR, TERNARY_TOL,
    TERNARY_ZERO_PROB, WEAKEST_AMPLITUDE,
};

/// Which sizes the suite runs at.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize)]
#[serde(rename_all = "lowercase")]
pub enum Preset {
    /// The small suite the tests run (about 3 s on two cores in a release build).
    Quick,
    /// The suite of docs/stress.md (about 12 s on two cores; 1.6 GB of memory at K = 10⁷).
    Full,
}

impl Preset {
    /// "quick" or "full".
    pub fn name(self) -> &'static str {
        match self {
            Preset::Quick => "quick",
            Preset::Full => "full",
        }
    }
}

/// What the suite runs.
#[derive(Debug, Clone, PartialEq)]
pub struct StressConfig {
    /// The preset these settings come from.
    pub preset: Preset,
    /// The base seed of every draw: pulses and codes as [`Seeds`](crate::lidar::Seeds) derives
    /// them, test vectors and start vectors on streams of their own.
    pub seed: u64,
    /// The grid of the precision and dot-test groups.
    pub precision_geometry: Geometry,
    /// The numbers of samples K of the precision and dot-test groups (each at least K_s).
    pub samples: Vec<usize>,
    /// The grid of the conditioning group (the paper scene's support on it).
    pub conditioning_geometry: Geometry,
    /// The pulse lengths of the conditioning group.
    pub conditioning_pulse_lens: Vec<usize>,
    /// The grid and the pulse length of the solver group.
    pub solver_geometry: Geometry,
    /// The pulse length of the solver group.
    pub solver_pulse_len: usize,
    /// The conditions of the solver group.
    pub solver_cases: Vec<SolverCase>,
    /// The methods of the solver group.
    pub methods: Vec<Method>,
}

impl StressConfig {
    /// The quick preset: K = 10⁴, 10⁵, 10⁶ on 4×4×8; conditioning of the 8×8×8 paper scene at
    /// K_p = 24, 100, 505 (critical), 2000; every method and every solver case at 8×8×8,
    /// K_p = 300.
    pub fn quick(seed: u64) -> Self {
        StressConfig {
            preset: Preset::Quick,
            seed,
            precision_geometry: Geometry { m: 4, n: 4, ks: 8 },
            samples: vec![10_000, 100_000, 1_000_000],
            conditioning_geometry: Geometry { m: 8, n: 8, ks: 8 },
            conditioning_pulse_lens: vec![24, 100, 505, 2000],
            solver_geometry: Geometry { m: 8, n: 8, ks: 8 },
            solver_pulse_len: 300,
            solver_cases: SolverCase::all(),
            methods: Method::ALL.to_vec(),
        }
    }

    /// The full preset: the quick one with K up to 10⁷ and K_p = 24 … 4000 (nine lengths) for
    /// the conditioning.
    pub fn full(seed: u64) -> Self {
        StressConfig {
            preset: Preset::Full,
            samples: vec![10_000, 100_000, 1_000_000, 10_000_000],
            conditioning_pulse_lens: vec![24, 40, 60, 100, 200, 505, 1000, 2000, 4000],
            ..StressConfig::quick(seed)
        }
    }

    /// The settings of `preset`.
    pub fn preset(preset: Preset, seed: u64) -> Self {
        match preset {
            Preset::Quick => StressConfig::quick(seed),
            Preset::Full => StressConfig::full(seed),
        }
    }
}

/// The groups of rows.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize)]
#[serde(rename_all = "kebab-case")]
pub enum Group {
    /// The `f32` operator against the `f64` one.
    Precision,
    /// The dot test as K grows.
    DotTest,
    /// The conditioning of A on a scene's support.
    Conditioning,
    /// The solvers under hard conditions.
    Solvers,
}

impl Group {
    /// "precision", "dot-test", "conditioning" or "solvers".
    pub fn name(self) -> &'static str {
        match self {
            Group::Precision => "precision",
            Group::DotTest => "dot-test",
            Group::Conditioning => "conditioning",
            Group::Solvers => "solvers",
        }
    }
}

/// The bound a measured value must satisfy.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
#[serde(rename_all = "snake_case")]
pub enum Bound {
    /// Finite and at most this.
    AtMost(f64),
    /// Finite and strictly above this.
    Above(f64),
}

impl Bound {
    /// Whether `v` satisfies the bound (never for NaN or an infinity).
    pub fn holds(self, v: f64) -> bool {
        v.is_finite()
            && match self {
                Bound::AtMost(b) => v <= b,
                Bound::Above(b) => v > b,
            }
    }
}

/// One pass/fail criterion of a row.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct Check {
    /// The name of the value checked (one of the row's values).
    pub value: &'static str,
    /// The value.
    pub measured: f64,
    /// Its bound.
    pub bound: Bound,
    /// Whether the value satisfies the bound.
    pub passed: bool,
}

impl Check {
    /// `value` at most `bound`.
    pub fn at_most(value: &'static str, measured: f64, bound: f64) -> Self {
        Check::new(value, measured, Bound::AtMost(bound))
    }

    /// `value` strictly above `bound`.
    pub fn above(value: &'static str, measured: f64, bound: f64) -> Self {
        Check::new(value, measured, Bound::Above(bound))
    }

    fn new(value: &'static str, measured: f64, bound: Bound) -> Self {
        Check {
            value,
            measured,
            bound,
            passed: bound.holds(measured),
        }
    }

    /// `name ≤ 1.2e-6` or `name > 0`.
    pub fn text(&self) -> String {
        match self.bound {
            Bound::AtMost(b) => format!("{} ≤ {}", self.value, sci(b)),
            Bound::Above(b) => format!("{} > {}", self.value, sci(b)),
        }
    }
}

/// One row of the suite.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct StressRow {
    /// Its group.
    pub group: Group,
    /// What was measured, e.g. `"adjoint, K = 10^6"`.
    pub case: String,
    /// `"f32"`, `"f64"`, or `"f32 vs f64"` for a comparison of the two.
    pub precision: &'static str,
    /// The measured values, by name (written as a JSON object).
    #[serde(serialize_with = "values_as_map")]
    pub values: Vec<(&'static str, f64)>,
    /// The criteria; the row passes when every one holds.
    pub checks: Vec<Check>,
    /// Whether every check passed (and nothing failed to run).
    pub passed: bool,
    /// Why the row could not be measured (an error of the computation), if so.
    pub error: Option<String>,
    /// Wall-clock time of the row's computation, in seconds.
    pub seconds: f64,
}

fn values_as_map<S: Serializer>(
    values: &[(&'static str, f64)],
    s: S,
) -> std::result::Result<S::Ok, S::Error> {
    let mut map = s.serialize_map(Some(values.len()))?;
    for (k, v) in values {
        map.serialize_entry(k, v)?;
    }
    map.end()
}

impl StressRow {
    /// A row whose verdict is its checks'.
    pub fn new(
        group: Group,
        case: String,
        precision: &'static str,
        values: Vec<(&'static str, f64)>,
        checks: Vec<Check>,
        seconds: f64,
    ) -> Self {
        let passed = !checks.is_empty() && checks.iter().all(|c| c.passed);
        StressRow {
            group,
            case,
            precision,
            values,
            checks,
            passed,
            error: None,
            seconds,
        }
    }

    /// A failed row: the computation itself returned `error`.
    pub fn failed(
        group: Group,
        case: String,
        precision: &'static str,
        error: String,
        seconds: f64,
    ) -> Self {
        StressRow {
            group,
            case,
            precision,
            values: Vec::new(),
            checks: Vec::new(),
            passed: false,
            error: Some(error),
            seconds,
        }
    }

    /// The value called `name`, if measured.
    pub fn value(&self, name: &str) -> Option<f64> {
        self.values
            .iter()
            .find(|(k, _)| *k == name)
            .map(|(_, v)| *v)
    }

    /// The measured values as text: `name value, …` (or the error).
    pub fn measured_text(&self) -> String {
        match &self.error {
            Some(e) => format!("error: {e}"),
            None => self
                .values
                .iter()
                .map(|(k, v)| format!("{k} {}", sci(*v)))
                .collect::<Vec<_>>()
                .join(", "),
        }
    }

    /// The criteria as text, `; `-separated.
    pub fn tolerance_text(&self) -> String {
        self.checks
            .iter()
            .map(Check::text)
            .collect::<Vec<_>>()
            .join("; ")
    }
}

/// A number in four significant digits: an integer as such (below 10⁷), plain between 0.01 and
/// 1000, scientific otherwise.
pub fn sci(v: f64) -> String {
    let a = v.abs();
    if v == 0.0 || !v.is_finite() {
        format!("{v}")
    } else if v.fract() == 0.0 && a < 1e7 {
        format!("{v:.0}")
    } else if (0.01..1000.0).contains(&a) {
        let digits = if a >= 100.0 {
            1
        } else if a >= 10.0 {
            2
        } else if a >= 1.0 {
            3
        } else {
            4
        };
        format!("{v:.digits$}")
    } else {
        format!("{v:.2e}")
    }
}

/// The header lines of the Markdown table that [`table_line`] continues.
pub fn table_header() -> [String; 2] {
    [
        format!(
            "| {:<12} | {:<52} | {:<10} | {:<100} | {:<44} | {:<4} | {:>8} |",
            "group", "case", "precision", "measured", "tolerance", "pass", "time (s)"
        ),
        format!(
            "|{}|{}|{}|{}|{}|{}|{}:|",
            "-".repeat(14),
            "-".repeat(54),
            "-".repeat(12),
            "-".repeat(102),
            "-".repeat(46),
            "-".repeat(6),
            "-".repeat(9)
        ),
    ]
}

/// One row of the Markdown table.
pub fn table_line(row: &StressRow) -> String {
    format!(
        "| {:<12} | {:<52} | {:<10} | {:<100} | {:<44} | {:<4} | {:>8.2} |",
        row.group.name(),
        row.case,
        row.precision,
        row.measured_text(),
        row.tolerance_text(),
        if row.passed { "yes" } else { "NO" },
        row.seconds
    )
}

/// Runs the suite: every group in turn, calling `each` on every row as soon as it is measured
/// (return [`ControlFlow::Break`] to stop early). Returns the rows measured.
///
/// A computation that fails (an error of a solver, say) gives a failed row, not an error.
///
/// # Errors
/// [`Error::InvalidParameter`](crate::Error::InvalidParameter) for settings that cannot be run
/// (a K below K_s, a zero pulse length); the generators' errors.
pub fn run_stress<F>(config: &StressConfig, mut each: F) -> Result<Vec<StressRow>>
where
    F: FnMut(&StressRow) -> ControlFlow<()>,
{
    let mut rows = Vec::new();
    let mut sink = |row: StressRow| {
        let flow = each(&row);
        rows.push(row);
        flow
    };
    let flow = precision::run(config, &mut sink)?;
    if flow.is_continue() && conditioning::run(config, &mut sink)?.is_continue() {
        // The last group: whether it was stopped early no longer matters.
        let _ = solvers::run(config, &mut sink)?;
    }
    Ok(rows)
}

/// The rows of a group go through this: it returns `Break` when the caller wants to stop.
pub(crate) type Sink<'a> = dyn FnMut(StressRow) -> ControlFlow<()> + 'a;

/// The number of failed rows.
pub fn failures(rows: &[StressRow]) -> usize {
    rows.iter().filter(|r| !r.passed).count()
}

/// `"10^4"` for powers of ten, the number otherwise.
pub(crate) fn count_text(k: usize) -> String {
    let mut p = 0;
    let mut v = k;
    while v >= 10 && v.is_multiple_of(10) {
        v /= 10;
        p += 1;
    }
    if v == 1 && p >= 3 {
        format!("10^{p}")
    } else {
        k.to_string()
    }
}

/// A ChaCha8 generator for `seed` on a stream of the suite's own ("stress" and a tag), so that
/// its test vectors never repeat the numbers the pulse or the codes drew from the same seed.
pub(crate) fn stress_rng(seed: u64, tag: u8) -> rand_chacha::ChaCha8Rng {
    use rand::SeedableRng;
    let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(seed);
    rng.set_stream(0x7374_7265_7373_0000 | u64::from(tag));
    rng
}

/// Standard normal entries drawn in `f64` and rounded to `f32`, so that both precisions see
/// exactly the same values.
pub(crate) fn f32_exact_gaussian(len: usize, rng: &mut rand_chacha::ChaCha8Rng) -> Vec<f64> {
    use rand_distr::{Distribution, StandardNormal};
    (0..len)
        .map(|_| {
            let v: f64 = StandardNormal.sample(rng);
            f64::from(v as f32)
        })
        .collect()
}

/// `v` converted to `T` (exactly, for values that [`f32_exact_gaussian`] drew).
pub(crate) fn cast<T: crate::Real>(v: &[f64]) -> Vec<T> {
    v.iter().map(|&x| T::of_f64(x)).collect()
}
