//! [`Method::Auto`]: the cheapest method that explains the data, found by escalating from the
//! data themselves rather than from the regime alone.

use crate::error::Result;
use crate::lidar::LidarOperator;
use crate::operator::{Counted, VoxelOperator};
use crate::real::Real;
use crate::solver::{Observer, Report, Termination};
use crate::space::{self, Space};

use super::detect::normal_tail;
use super::method::{estimate_returns_in, run, Method};
use super::options::ReconstructOptions;
use super::peaks::returns;
use super::pursuit::{
    explained_tolerance, relative_residual, support_pursuit, unexplained_returns, PursuitEnd,
    HIDDEN_RATIO, PURSUIT_ROUNDS,
};
use super::refit::{refit_support, REFIT_MAX_ITER, REFIT_ROUNDS};

/// [`Method::Auto`] keeps TV's one-return-per-pixel scene over the model-based one only if its
/// residual ‖Ax − y‖ is at most this factor times the model-based one (plus 10⁻⁶‖y‖): TV must not
/// buy smoothness with a worse data fit.
pub const TV_RESIDUAL_MARGIN: f64 = 1.05;

/// The Bayesian information criterion of a stage's sparse fit, up to a constant:
/// K·ln(‖r‖²/‖y‖²) + |S|·ln K, lower is better. It weighs the residual a support leaves against
/// the support's size, so that a fit does not win by fitting noise with extra returns.
fn bic(stage: &Stage, k: usize) -> f64 {
    let k = k as f64;
    let rel_sq = (stage.relative_residual * stage.relative_residual).max(f64::MIN_POSITIVE);
    k * rel_sq.ln() + stage.returns as f64 * k.ln()
}

/// Of fits none of which explains the data, the one with the lowest [`bic`]: appends the
/// criterion to every verdict, moves the others' stages to `stages` and returns the kept one.
fn keep_lowest_bic<T>(mut tried: Vec<Tried<T>>, k: usize, stages: &mut Vec<Stage>) -> Tried<T> {
    let scores: Vec<f64> = tried.iter().map(|t| bic(&t.stage, k)).collect();
    let pick = (0..tried.len())
        .min_by(|&a, &b| scores[a].total_cmp(&scores[b]))
        .unwrap_or(0);
    for (t, score) in tried.iter_mut().zip(&scores) {
        t.stage.verdict = format!("{}; information criterion {score:.1}", t.stage.verdict);
    }
    let kept = tried.swap_remove(pick);
    stages.extend(tried.into_iter().map(|t| t.stage));
    kept
}

/// What one stage of [`Method::Auto`] did. Serialized with its fields' names, the method by
/// its name and the report's fields beside the others.
#[derive(Debug, Clone, PartialEq, serde::Serialize)]
pub struct Stage {
    /// The method the stage ran.
    pub method: Method,
    /// ‖y − Ax‖ / ‖y‖ of its estimate (after the returns are extracted); NaN, with no
    /// report, for a stage that could not run (its verdict says why).
    pub relative_residual: f64,
    /// Nonzero voxels (returns) of its estimate.
    pub returns: usize,
    /// Its solver's report.
    #[serde(flatten)]
    pub report: Option<Report>,
    /// Whether its estimate is the one [`reconstruct`](super::reconstruct) returns.
    pub kept: bool,
    /// Why auto stopped or went on after it.
    pub verdict: String,
}

impl std::fmt::Display for Stage {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        if self.report.is_none() && self.relative_residual.is_nan() {
            // A stage that did not run.
            return write!(f, "{}: {}", self.method, self.verdict);
        }
        write!(
            f,
            "{}: residual {:.2e}, {} returns",
            self.method, self.relative_residual, self.returns
        )?;
        if let Some(r) = &self.report {
            write!(
                f,
                ", {} forward + {} adjoint + {} support applies, {:.3} s",
                r.forward_applies,
                r.adjoint_applies,
                r.support_applies,
                r.elapsed.as_secs_f64()
            )?;
        }
        write!(
            f,
            "{}: {}",
            if self.kept { ", kept" } else { "" },
            self.verdict
        )
    }
}

/// What [`auto`] returns.
pub(super) struct Auto<T> {
    pub x: Vec<T>,
    pub method_used: Method,
    pub report: Option<Report>,
    pub stages: Vec<Stage>,
}

/// One candidate estimate and its stage.
struct Tried<T> {
    x: Vec<T>,
    stage: Stage,
}

impl<T> Tried<T> {
    /// Whether its solver stopped on its own residual tolerance.
    fn converged(&self) -> bool {
        self.stage
            .report
            .as_ref()
            .is_some_and(|r| r.termination == Termination::Residual)
    }
}

/// The nonzero voxels of `x` over every part of the unknowns.
fn nonzeros<T: Real>(space: &dyn Space, x: &[T]) -> usize {
    space::count(space, x.iter().filter(|v| **v != T::zero()).count())
}

/// Runs a method and extracts its returns, measuring the residual of what it reports.
fn attempt<T: Real>(
    op: &dyn LidarOperator<T>,
    y: &[T],
    method: Method,
    options: &ReconstructOptions,
    observer: &mut dyn Observer<T>,
) -> Result<Tried<T>> {
    let (x, report) = run(op, y, method, options, observer)?;
    let x = returns(op.space(), &x, op.geometry());
    let mut report = report.expect("iterative methods report");
    let rel = relative_residual(op, y, &x, &mut report);
    Ok(Tried {
        stage: Stage {
            method,
            relative_residual: rel,
            returns: nonzeros(op.space(), &x),
            report: Some(report),
            kept: false,
            verdict: String::new(),
        },
        x,
    })
}

/// The rule of [`Method::Auto`]; see [`reconstruct`](super::reconstruct).
pub(super) fn auto<T: Real>(
    op: &dyn LidarOperator<T>,
    y: &[T],
    options: &ReconstructOptions,
    observer: &mut dyn Observer<T>,
) -> Result<Auto<T>> {
    let tol = explained_tolerance::<T>();
    let explained = |rel: f64| rel <= tol;
    let mut stages: Vec<Stage> = Vec::new();

    // 1. Support pursuit: cheap, and exact wherever the returns are few for the measurements.
    let rounds = options.max_iter.unwrap_or(PURSUIT_ROUNDS);
    let mut p = support_pursuit(op, y, rounds)?;
    p.x = returns(op.space(), &p.x, op.geometry());
    let mut best = Tried {
        stage: Stage {
            method: Method::SupportLs,
            relative_residual: p.relative_residual,
            returns: nonzeros(op.space(), &p.x),
            report: Some(p.report),
            kept: false,
            verdict: String::new(),
        },
        x: p.x,
    };
    if p.end == PursuitEnd::Explained {
        best.stage.verdict = format!("{}; nothing more to run", p.end.describe());
        return Ok(finish(best, stages));
    }
    best.stage.verdict = format!("not explained ({})", p.end.describe());

    let g = op.geometry();
    if op.nrows() >= space::count(op.space(), g.voxels()) {
        // 2a. A has full column rank (critical or redundant regime). The one-reflector fit is
        // cheap and well posed here; least squares on every voxel is exact without noise but
        // slow near the critical length, so it runs only when the two cheap fits disagree.
        let mut mb = attempt(op, y, Method::ModelBased, options, observer)?;
        if explained(mb.stage.relative_residual) {
            mb.stage.verdict = "one reflector per pixel explains the data".to_string();
            stages.push(best.stage);
            return Ok(finish(mb, stages));
        }
        let (r_p, r_mb) = (best.stage.relative_residual, mb.stage.relative_residual);
        let agree = (r_p - r_mb).abs() <= 0.05 * r_p.max(r_mb);
        let mut tried = vec![best, mb];
        if !agree {
            let mut ls = attempt(op, y, Method::Cgls, options, observer)?;
            let refit = refit_support(op, y, &mut ls.x, REFIT_MAX_ITER, REFIT_ROUNDS)?;
            if let (Some(r), Some(rep)) = (refit, ls.stage.report.as_mut()) {
                rep.absorb_applies(&r);
                ls.stage.relative_residual = relative_residual(op, y, &ls.x, rep);
                ls.stage.returns = nonzeros(op.space(), &ls.x);
            }
            if explained(ls.stage.relative_residual) {
                ls.stage.verdict = "least squares on every voxel explains the data".into();
                stages.extend(tried.into_iter().map(|t| t.stage));
                return Ok(finish(ls, stages));
            }
            tried.push(ls);
        }
        // Noise: no fit explains the data; the information criterion weighs each sparse fit's
        // residual against its number of returns.
        for t in tried.iter_mut() {
            let what = match t.stage.method {
                Method::SupportLs => "support pursuit",
                Method::Cgls => "least-squares returns refitted on their support",
                _ => "one reflector per pixel",
            };
            let agreeing = if agree {
                ", agreeing with the other cheap fit within 5%"
            } else {
                ""
            };
            t.stage.verdict = format!("not explained ({what}{agreeing})");
        }
        let kept = keep_lowest_bic(tried, op.nrows(), &mut stages);
        return Ok(finish(kept, stages));
    }

    // 2b. Compressive. A pursuit that finds several returns in many of its pixels has seen a
    // scene one reflector per pixel cannot explain: the one-reflector fits are skipped.
    let share = several_returns_share(op.space(), &best.x, g.ks);
    if share >= SEVERAL_RETURNS_SHARE {
        best.stage.verdict = format!(
            "{}; {:.0}% of its lit pixels hold several returns",
            best.stage.verdict,
            100.0 * share
        );
        return several_returns(op, y, options, observer, (best, p.end), Vec::new(), stages);
    }
    // TV on the depth map, whose first fit is the model-based one (so that it costs little more
    // where that fit explains the data already); the model-based fit alone only when TV neither
    // explains the data nor leaves only noise, as a scene need not be piecewise smooth.
    let mut tv = attempt(op, y, Method::Tv, options, observer)?;
    if explained(tv.stage.relative_residual) || tv.converged() {
        tv.stage.verdict = "TV on the depth map explains the data".to_string();
        stages.push(best.stage);
        return Ok(finish(tv, stages));
    }
    let (mut one, other, left) = match one_reflector(op, y, options, observer, tv)? {
        Chosen::Explained { mb, tv } => {
            stages.extend([best.stage, tv.stage]);
            return Ok(finish(mb, stages));
        }
        Chosen::Compared { one, other, left } => (one, other, left),
    };
    // The pursuit (no per-pixel model) is kept over the one-reflector fits when it explains the
    // data markedly better: a sign of several returns per pixel.
    if best.stage.relative_residual < 0.5 * one.stage.relative_residual {
        best.stage.verdict = format!(
            "{}; it fits better than one reflector per pixel can (residual {:.2e} against {:.2e})",
            best.stage.verdict, best.stage.relative_residual, one.stage.relative_residual
        );
        stages.extend(other.map(|t| t.stage));
        stages.push(one.stage);
        return Ok(finish(best, stages));
    }
    // Does the residual of the one-reflector fit still hold returns in its lit pixels?
    // (A fit without a lit pixel has no returns to hide.)
    let ResidualReturns { hidden, lit, .. } = match left {
        Some(left) => left,
        None => hidden_returns(op, y, &one.x, one.stage.report.as_mut()),
    };
    if lit == 0 || (hidden as f64) < HIDDEN_FRACTION * lit as f64 {
        one.stage.verdict = format!(
            "{}; its residual holds no further return in {} of {lit} lit pixels",
            one.stage.verdict,
            lit - hidden
        );
        stages.push(best.stage);
        stages.extend(other.map(|t| t.stage));
        return coarse_stage(op, y, options, observer, one, stages);
    }
    one.stage.verdict = format!(
        "{}; its residual still holds returns in {hidden} of {lit} lit pixels",
        one.stage.verdict
    );
    stages.extend(other.map(|t| t.stage));
    several_returns(op, y, options, observer, (best, p.end), vec![one], stages)
}

/// The one-reflector fit [`auto`] goes on with in the compressive regime, after TV did not
/// explain the data.
enum Chosen<T> {
    /// The model-based fit explains the data.
    Explained { mb: Tried<T>, tv: Tried<T> },
    /// The kept fit, the other one if it ran, and where the kept fit's residual shows returns
    /// (if already known).
    Compared {
        one: Tried<T>,
        other: Option<Tried<T>>,
        left: Option<ResidualReturns>,
    },
}

/// TV's fit, or the model-based one where it fits markedly better: the model-based solver runs
/// unless TV's residual is at the noise ([`ResidualReturns::at_the_noise`]), since no
/// one-reflector fit can then explain the data markedly better than by fitting noise.
fn one_reflector<T: Real>(
    op: &dyn LidarOperator<T>,
    y: &[T],
    options: &ReconstructOptions,
    observer: &mut dyn Observer<T>,
    mut tv: Tried<T>,
) -> Result<Chosen<T>> {
    let tv_returns = hidden_returns(op, y, &tv.x, tv.stage.report.as_mut());
    if tv_returns.at_the_noise(op.nrows(), op.geometry().ks) {
        tv.stage.verdict = format!(
            "TV does not explain the data, but its residual is at the noise (about {:.0} returns' \
             energy, no return standing out of it in {} of {} empty pixels): the model-based fit \
             is not run",
            tv_returns.unexplained,
            tv_returns.empty - tv_returns.missed,
            tv_returns.empty
        );
        return Ok(Chosen::Compared {
            one: tv,
            other: None,
            left: Some(tv_returns),
        });
    }
    let tol = explained_tolerance::<T>();
    let mut mb = attempt(op, y, Method::ModelBased, options, observer)?;
    if mb.stage.relative_residual <= tol || mb.converged() {
        tv.stage.verdict = "TV on the depth map does not explain the data".to_string();
        mb.stage.verdict = "one reflector per pixel explains the data".to_string();
        return Ok(Chosen::Explained { mb, tv });
    }
    let y_norm = crate::linalg::norm2(y);
    let (r_mb, r_tv) = (mb.stage.relative_residual, tv.stage.relative_residual);
    let tv_fits = r_tv * y_norm <= TV_RESIDUAL_MARGIN * r_mb * y_norm + 1e-6 * y_norm;
    mb.stage.verdict = "one reflector per pixel does not explain the data".to_string();
    Ok(if tv_fits {
        tv.stage.verdict = "TV fits about as well as the model-based scene (within 5%)".to_string();
        Chosen::Compared {
            one: tv,
            other: Some(mb),
            left: Some(tv_returns),
        }
    } else {
        tv.stage.verdict = "TV fits worse than the model-based scene".to_string();
        Chosen::Compared {
            one: mb,
            other: Some(tv),
            left: None,
        }
    })
}

/// The end of auto's one-return branch: the kept one-reflector fit `one`, or, where it leaves
/// more than [`COARSE_RESIDUAL`] of the data unexplained (fewer measurements than lit pixels, or
/// heavy noise) and the codes are whole, [`Method::CoarseToFine`] if it fits better.
fn coarse_stage<T: Real>(
    op: &dyn LidarOperator<T>,
    y: &[T],
    options: &ReconstructOptions,
    observer: &mut dyn Observer<T>,
    mut one: Tried<T>,
    mut stages: Vec<Stage>,
) -> Result<Auto<T>> {
    if one.stage.relative_residual <= COARSE_RESIDUAL {
        return Ok(finish(one, stages));
    }
    // An optional stage: if it cannot run or fails (other than by cancellation), the fit stands
    // and a stage says why.
    let skipped = |why: String| Stage {
        method: Method::CoarseToFine,
        relative_residual: f64::NAN,
        returns: 0,
        report: None,
        kept: false,
        verdict: format!("not run: {why}"),
    };
    let mut fine = match attempt(op, y, Method::CoarseToFine, options, observer) {
        Ok(fine) => fine,
        Err(e @ crate::error::Error::Cancelled { .. }) => return Err(e),
        Err(e) => {
            stages.push(skipped(e.to_string()));
            return Ok(finish(one, stages));
        }
    };
    // Its amplitudes are tied along surfaces (better amplitudes for a little more residual); its
    // support is judged as the other fits' are, by least squares on it (where it holds at most
    // half as many voxels as measurements).
    let mut free = fine.x.clone();
    let r_fine = match refit_support(op, y, &mut free, REFIT_MAX_ITER, 1)
        .ok()
        .flatten()
    {
        Some(refit) => {
            let rep = fine
                .stage
                .report
                .as_mut()
                .expect("iterative methods report");
            rep.absorb_applies(&refit);
            relative_residual(op, y, &free, rep)
        }
        None => fine.stage.relative_residual,
    };
    let r_one = one.stage.relative_residual;
    let how = format!(
        "by least squares on its support where it holds at most K/2 voxels: residual \
         {r_fine:.2e} against {r_one:.2e}"
    );
    if r_fine < r_one {
        one.stage.verdict = format!(
            "{}; it leaves more than {COARSE_RESIDUAL} of the data unexplained",
            one.stage.verdict
        );
        fine.stage.verdict = format!("fits better ({how})");
        stages.push(one.stage);
        return Ok(finish(fine, stages));
    }
    fine.stage.verdict = format!("fits no better ({how})");
    stages.push(fine.stage);
    Ok(finish(one, stages))
}

/// [`Method::Auto`] runs [`Method::CoarseToFine`] after the one-reflector fits in the compressive
/// regime when the kept fit leaves more than this share of ‖y‖ unexplained (relative residual),
/// and keeps it if it fits better (its support judged by least squares on it, as the others'
/// estimates are, where it holds at most K/2 voxels). A fit at 20 dB SNR leaves about 0.08, one
/// at 15 dB about 0.14, one at 10 dB about 0.3, one with fewer measurements than lit pixels 0.6
/// and more. Between 12 and 15 dB a one-reflector fit that misses a fifth of the lit pixels
/// leaves 0.2–0.25, no more than noise alone would at 10 dB: a bar at 0.25 kept such fits (71%
/// of the depths exact on the paper scene at 2.4 measurements per lit pixel, 12 dB and photon
/// noise, where the coarse grid finds 96–99%).
pub const COARSE_RESIDUAL: f64 = 0.12;

/// [`Method::Auto`] takes a compressive scene for one with several returns per pixel, and skips the
/// one-reflector fits, when at least this share of the support pursuit's lit pixels hold more
/// than one return. The pursuit's spurious returns on an opaque scene stay far below it (at most
/// 9% of the paper scene's lit pixels down to 10 dB SNR at 32×32×40); on the semi-transparent
/// scene, once the pursuit finds returns at all, the share is 50–70%.
pub const SEVERAL_RETURNS_SHARE: f64 = 0.25;

/// The share of the lit pixels of `x` (K_s voxels per pixel) that hold more than one return.
fn several_returns_share<T: Real>(space: &dyn Space, x: &[T], ks: usize) -> f64 {
    let (mut lit, mut several) = (0.0, 0.0);
    for col in x.chunks(ks.max(1)) {
        let n = col.iter().filter(|v| **v != T::zero()).count();
        lit += f64::from(u8::from(n > 0));
        several += f64::from(u8::from(n > 1));
    }
    let [lit, several] = space::sums(space, [lit, several]);
    if lit == 0.0 {
        0.0
    } else {
        several / lit
    }
}

/// The last step of [`auto`], for several returns per pixel: the model-based fit with as many
/// returns per pixel as the pursuit suggests; then the convex solver, debiased, unless the
/// pursuit stopped because nothing more stood out of its residual (not on its round limit) and
/// the residual of the better of the two fits holds no further returns. Of fits none of which
/// explains the data, the lowest [`bic`] of the pursuit, the one-reflector fit `others` and
/// these is kept.
fn several_returns<T: Real>(
    op: &dyn LidarOperator<T>,
    y: &[T],
    options: &ReconstructOptions,
    observer: &mut dyn Observer<T>,
    (pursuit, end): (Tried<T>, PursuitEnd),
    others: Vec<Tried<T>>,
    mut stages: Vec<Stage>,
) -> Result<Auto<T>> {
    let tol = explained_tolerance::<T>();
    let k = estimate_returns_in(op.space(), &pursuit.x, op.geometry().ks).max(2);
    let several = ReconstructOptions {
        max_returns: Some(k),
        ..options.clone()
    };
    let mut mbk = attempt(op, y, Method::ModelBased, &several, observer)?;
    if mbk.stage.relative_residual <= tol {
        mbk.stage.verdict = format!("up to {k} returns per pixel explain the data");
        stages.push(pursuit.stage);
        stages.extend(others.into_iter().map(|t| t.stage));
        return Ok(finish(mbk, stages));
    }
    mbk.stage.verdict = format!("up to {k} returns per pixel do not explain the data");
    let mut tried = vec![pursuit];
    tried.extend(others);
    tried.push(mbk);
    // The better fit of the pursuit and the model-based one with k returns: is anything left in
    // its residual for the convex solver to find?
    let last = tried.len() - 1;
    let better = if tried[last].stage.relative_residual < tried[0].stage.relative_residual {
        last
    } else {
        0
    };
    let b = &mut tried[better];
    let ResidualReturns { hidden, lit, .. } = hidden_returns(op, y, &b.x, b.stage.report.as_mut());
    let exhausted = matches!(end, PursuitEnd::NoCandidate | PursuitEnd::Stalled);
    if exhausted && (hidden as f64) < HIDDEN_FRACTION * lit as f64 {
        b.stage.verdict = format!(
            "{}; its residual holds no further return in {} of {lit} lit pixels",
            b.stage.verdict,
            lit - hidden
        );
        let kept = keep_lowest_bic(tried, op.nrows(), &mut stages);
        return Ok(finish(kept, stages));
    }
    b.stage.verdict = if exhausted {
        format!(
            "{}; its residual still holds returns in {hidden} of {lit} lit pixels",
            b.stage.verdict
        )
    } else {
        format!(
            "{}; the pursuit stopped before it ran out of returns",
            b.stage.verdict
        )
    };
    let mut fista = attempt(op, y, Method::Fista, options, observer)?;
    if fista.stage.relative_residual <= tol {
        fista.stage.verdict = "the debiased lasso explains the data".to_string();
        stages.extend(tried.into_iter().map(|t| t.stage));
        return Ok(finish(fista, stages));
    }
    fista.stage.verdict = "the debiased lasso does not explain the data".to_string();
    tried.push(fista);
    let kept = keep_lowest_bic(tried, op.nrows(), &mut stages);
    Ok(finish(kept, stages))
}

/// [`auto`] turns to the multi-return solvers when the residual of the one-reflector fit still
/// shows a return in at least this fraction of its lit pixels.
const HIDDEN_FRACTION: f64 = 0.05;

/// How far above the median, in robust standard deviations, a residual correlation must stand to
/// show a hidden return.
const HIDDEN_Z: f64 = 3.5;

/// Where the residual of a one-return-per-pixel estimate still shows returns: its correlation with
/// every voxel (one adjoint with the zero-mean pulse) standing [`HIDDEN_Z`] robust standard
/// deviations above the median.
struct ResidualReturns {
    /// Lit pixels with such a voxel other than their return: returns the fit has no room for.
    hidden: usize,
    lit: usize,
    /// Empty pixels with such a voxel: returns the fit missed.
    missed: usize,
    empty: usize,
    /// The residual's energy in returns of the estimate's mean energy.
    unexplained: f64,
}

impl ResidualReturns {
    /// Whether the residual is at the noise. Were it made of n returns of the estimate's mean
    /// energy (amplitude² times column norm²), each would stand about √(K/n) deviations out of
    /// the others' cross-talk: with n at most K/[`HIDDEN_RATIO`], each would stand out by ten,
    /// and the test would see it. So: that little energy, and no more pixels with a correlation
    /// standing out, lit or empty, than white noise makes (each of K_s voxels beyond
    /// [`HIDDEN_Z`] deviations with probability Q(3.5) ≈ 2.3·10⁻⁴; one pixel in about a hundred
    /// at K_s = 40), with three deviations (the square root of the expected count) and one pixel
    /// to spare, and in fewer than [`HIDDEN_FRACTION`] of the lit pixels (the bar at which
    /// [`auto`] looks for several returns per pixel). With more energy, unexplained returns hide
    /// in each other's cross-talk, and only another fit can tell them from noise.
    fn at_the_noise(&self, k: usize, ks: usize) -> bool {
        let q = 1.0 - (1.0 - normal_tail(HIDDEN_Z)).powi(ks as i32);
        let within = |count: usize, of: usize| {
            let expected = q * of as f64;
            count as f64 <= expected + 3.0 * expected.sqrt() + 1.0
        };
        self.unexplained * HIDDEN_RATIO <= k as f64
            && within(self.hidden, self.lit)
            && (self.hidden as f64) < HIDDEN_FRACTION * self.lit as f64
            && within(self.missed, self.empty)
    }
}

/// [`ResidualReturns`] of the estimate `x`; its applications (the sparse forward, the adjoint and
/// the column norms) go into `report`.
fn hidden_returns<T: Real>(
    op: &dyn LidarOperator<T>,
    y: &[T],
    x: &[T],
    report: Option<&mut Report>,
) -> ResidualReturns {
    let ks = op.geometry().ks;
    let op = Counted::new(op);
    let mut ax = vec![T::zero(); y.len()];
    op.apply_sparse(x, &mut ax);
    let r: Vec<T> = y.iter().zip(&ax).map(|(&a, &b)| a - b).collect();
    let mut u = vec![T::zero(); x.len()];
    op.correlate(&r, &mut u);
    let unexplained = unexplained_returns(&op, x, &r);
    if let Some(rep) = report {
        rep.add_applies(op.applies());
    }
    let space = crate::LinearOperator::space(&op);
    let mut all: Vec<f64> = u.iter().map(|v| v.as_f64()).collect();
    let med = space::median(space, &mut all);
    let level = med + HIDDEN_Z * space::robust_sigma(space, &mut all, med);
    let [mut hidden, mut lit, mut missed, mut empty] = [0usize; 4];
    for (col, cu) in x.chunks(ks).zip(u.chunks(ks)) {
        let stands = col
            .iter()
            .zip(cu)
            .any(|(v, c)| *v == T::zero() && c.as_f64() > 0.0 && c.as_f64() >= level);
        if col.iter().all(|v| *v == T::zero()) {
            empty += 1;
            missed += usize::from(stands);
        } else {
            lit += 1;
            hidden += usize::from(stands);
        }
    }
    let [hidden, lit, missed, empty] =
        space::sums(space, [hidden, lit, missed, empty].map(|c| c as f64)).map(|c| c as usize);
    ResidualReturns {
        hidden,
        lit,
        missed,
        empty,
        unexplained,
    }
}

/// The stages in the order they ran, the kept one marked; the reports are summed.
fn finish<T: Real>(mut kept: Tried<T>, mut stages: Vec<Stage>) -> Auto<T> {
    kept.stage.kept = true;
    let method_used = kept.stage.method;
    stages.push(kept.stage);
    stages.sort_by_key(|s| order(s.method));
    let mut report: Option<Report> = None;
    for s in &stages {
        if let Some(r) = &s.report {
            match &mut report {
                Some(t) => t.absorb(r.clone()),
                None => report = Some(r.clone()),
            }
        }
    }
    if let Some(r) = report.as_mut() {
        if let Some(k) = stages
            .iter()
            .find(|s| s.kept)
            .and_then(|s| s.report.as_ref())
        {
            r.solver = k.solver;
            r.termination = k.termination;
        }
    }
    Auto {
        x: kept.x,
        method_used,
        report,
        stages,
    }
}

/// The order in which [`auto`] runs its stages.
fn order(m: Method) -> usize {
    [
        Method::SupportLs,
        Method::Tv,
        Method::ModelBased,
        Method::CoarseToFine,
        Method::Cgls,
        Method::Fista,
    ]
    .iter()
    .position(|&x| x == m)
    .unwrap_or(usize::MAX)
}
