//! Continuous depths under the system's response: every return's amplitude a and depth d
//! (in bins, continuous) for voxels a·g(k − d).
//!
//! Two steps. A pursuit places each return within 1/(2Q) bin: the per-pixel model-based
//! solver picks one column per pixel from the dictionary of the response shifted by 1/Q bin
//! ([`Atoms`], Q = [`ATOMS_PER_BIN`]), or another method's voxel estimate is fitted pixel by
//! pixel. Then Gauss–Newton on all (a, d) at once fits the data: each step solves the least
//! squares of the Jacobian (columns A·g(· − d) and −a·A·g′(· − d) per return, restricted to the
//! voxels the returns reach, at O(returns·K_p) per application) and is halved until the
//! residual falls.

use crate::error::Result;
use crate::lidar::{LidarOperator, Response, Returns};
use crate::linalg::dot;
use crate::operator::{Applies, LinearOperator, OperatorExt, SparseMatrix};
use crate::real::Real;
use crate::solver::{
    cgls, model_based, tv_depth, CglsParams, Observer, Report, Stopping, TvDepthParams,
};

use super::atoms::{Atoms, Dictionary};
use super::auto::Stage;
use super::method::Method;
use super::options::{model_params, ReconstructOptions};

/// Atoms per bin of the pursuit's dictionary: a return is placed within 1/16 bin before the
/// continuous fit.
pub const ATOMS_PER_BIN: usize = 8;

/// Gauss–Newton steps at most.
pub(super) const GN_STEPS: usize = 30;

/// Each Gauss–Newton step solves its least squares inexactly: CGLS to this share of its first
/// normal-equation residual, in at most [`GN_SOLVE_ITERATIONS`] iterations. The steps still
/// converge (each is checked to lower the residual), and cost a fifth of solves to 10⁻¹⁰: on the
/// sphere of the test set at 48×48×32, gaussian:0.8, 20 dB, 3 measurements per lit pixel, the
/// same squared misfit to 6 digits.
const GN_SOLVE_TOLERANCE: f64 = 1e-3;

/// CGLS iterations per Gauss–Newton step at most.
const GN_SOLVE_ITERATIONS: usize = 50;

/// The Gauss–Newton steps end when one lowers the squared residual by less than this share of
/// the noise variance per sample that the residual implies (‖r‖²/(K − 2R) for R returns): under
/// noise the last steps of a slow tail gain less than the fit of one parameter to noise alone
/// would. Noise-free, the residual falls towards round-off and the rule does not bind.
const GN_NOISE_GAIN: f64 = 0.05;

/// Halvings of a step that does not lower the residual before the fit stops.
const HALVINGS: usize = 6;

/// One return: its pixel, amplitude and depth in bins.
#[derive(Debug, Clone, Copy, PartialEq)]
pub(crate) struct Ret {
    pub pixel: usize,
    pub a: f64,
    pub d: f64,
}

/// What the continuous estimate is: the returns, their voxels, the work, and the squared
/// misfit of the fit.
pub(crate) struct Continuous<T> {
    pub x: Vec<T>,
    pub returns: Returns,
    pub report: Report,
    found: Vec<Ret>,
    misfit: f64,
}

/// How [`pursue`] picks each pixel's atom.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(crate) enum AtomStart {
    /// The model-based pursuit, pixel by pixel (one return per pixel unless the options allow
    /// more).
    Pursuit,
    /// TV on the depth map over the atoms ([`tv_depth`]): message passing with every pixel's
    /// prior from its neighbours' posteriors, windows around the regularized depths, the
    /// surface rules; a bin is `ATOMS_PER_BIN` atoms
    /// ([`VoxelOperator::columns_per_bin`](crate::operator::VoxelOperator::columns_per_bin)).
    Surfaces,
}

/// One atom per pixel picked from the response's atoms (`start`), then the continuous fit.
pub(crate) fn pursue<T: Real>(
    op: &dyn LidarOperator<T>,
    y: &[T],
    options: &ReconstructOptions,
    start: AtomStart,
    observer: &mut dyn Observer<T>,
) -> Result<Continuous<T>> {
    let g = op.geometry();
    let dict = Dictionary::new(&options.response, g.ks, ATOMS_PER_BIN);
    let atoms = Atoms::new(op, &dict)?;
    let mut params = model_params(options);
    params.max_returns = options.max_returns.unwrap_or(1);
    let mut z = vec![T::zero(); atoms.ncols()];
    let mut report = match start {
        AtomStart::Pursuit => model_based(&atoms, y, &mut z, &params, observer)?,
        AtomStart::Surfaces => {
            let params = TvDepthParams {
                model: params,
                ..TvDepthParams::default()
            };
            tv_depth(&atoms, (g.m, g.n), y, &mut z, &params, observer)?
        }
    };
    let l = dict.len();
    let found: Vec<Ret> = z
        .iter()
        .enumerate()
        .filter(|(_, v)| v.as_f64() > 0.0)
        .map(|(c, v)| Ret {
            pixel: c / l,
            a: dict.amplitude(c % l, v.as_f64()),
            d: dict.depth(c % l),
        })
        .collect();
    fit(op, y, found, &options.response, &mut report)
}

/// Per pixel of the voxel estimate `x` (a method's on the grid), the response's atom that best
/// explains its column (largest ⟨g_d, col⟩²/‖g_d‖² over depths 1/Q bin apart) and its weight;
/// none for a pixel with no voxel or none that correlates positively.
fn best_atoms<T: Real>(dict: &Dictionary, x: &[T]) -> Vec<Option<(usize, f64)>> {
    let mut col = vec![0.0f64; dict.ks];
    x.chunks(dict.ks)
        .map(|xp| {
            if xp.iter().all(|v| *v == T::zero()) {
                return None;
            }
            for (c, v) in col.iter_mut().zip(xp) {
                *c = v.as_f64();
            }
            // Unit atoms: the best has the largest inner product.
            (0..dict.len())
                .map(|c| {
                    let (start, v) = dict.atom(c);
                    (c, dot(v, &col[start..start + v.len()]))
                })
                .max_by(|a, b| a.1.total_cmp(&b.1))
                .filter(|b| b.1 > 0.0)
        })
        .collect()
}

/// Each pixel's returns of the voxel estimate `x` (a method's on the grid) as continuous ones
/// ([`best_atoms`]), then the continuous fit.
pub(crate) fn from_voxels<T: Real>(
    op: &dyn LidarOperator<T>,
    y: &[T],
    x: &[T],
    response: &Response,
    mut report: Report,
) -> Result<Continuous<T>> {
    let found = returns_in(x, response, op.geometry().ks)
        .into_iter()
        .flatten()
        .collect();
    fit(op, y, found, response, &mut report)
}

/// Each pixel's return in the voxel estimate `x` (a method's on the grid): the response's atom
/// that best explains its column ([`best_atoms`]); none where the pixel has no return.
pub(crate) fn returns_in<T: Real>(x: &[T], response: &Response, ks: usize) -> Vec<Option<Ret>> {
    let dict = Dictionary::new(response, ks, ATOMS_PER_BIN);
    best_atoms(&dict, x)
        .into_iter()
        .enumerate()
        .map(|(p, b)| {
            b.map(|(c, ip)| Ret {
                pixel: p,
                a: dict.amplitude(c, ip),
                d: dict.depth(c),
            })
        })
        .collect()
}

/// Each pixel's depth in `c` (its first return's), none where it has no return.
pub(crate) fn depths_by_pixel<T>(c: &Continuous<T>, pixels: usize) -> Vec<Option<f64>> {
    let mut out = vec![None; pixels];
    for r in c.found.iter().rev() {
        out[r.pixel] = Some(r.d);
    }
    out
}

/// TV's fit is filled from another estimate when that one has returns in more
/// than this share of TV's lit pixels' count where TV has none.
const FILL_SHARE: f64 = 0.01;

/// The fit `c` with the returns of `other` (per pixel, [`returns_in`]) added in the pixels where
/// `c` has none, fitted, those the data do not hold above the noise taken out and the rest
/// fitted again, and the number added; none when they are at most [`FILL_SHARE`] of `c`'s
/// returns (then proposed one by one in [`settle`], which judges each against the noise) or
/// none holds.
pub(crate) fn filled<T: Real>(
    op: &dyn LidarOperator<T>,
    y: &[T],
    c: &Continuous<T>,
    other: &[Option<Ret>],
    response: &Response,
) -> Result<Option<(Continuous<T>, usize)>> {
    let mut lit = vec![false; other.len()];
    for r in &c.found {
        lit[r.pixel] = true;
    }
    let extra: Vec<Ret> = other
        .iter()
        .flatten()
        .filter(|r| !lit[r.pixel])
        .copied()
        .collect();
    if extra.len() as f64 <= FILL_SHARE * c.found.len() as f64 {
        return Ok(None);
    }
    let mut report = c.report.clone();
    let mut applies = Applies::default();
    let mut found = c.found.clone();
    found.extend(extra.iter().copied());
    found.sort_by_key(|r| r.pixel);
    let (mut found, mut misfit) = refine(op, y, found, response, GN_STEPS, &mut applies)?;
    // The added returns the data do not hold: those whose column A·a·g(· − d) is not above the
    // noise by the margin the proposals ask of a change (the noise from the filled fit's
    // residual, which no longer holds the returns TV missed).
    let dof = y.len().saturating_sub(2 * found.len()).max(1);
    let sigma = (misfit / dof as f64).sqrt();
    let ks = op.geometry().ks;
    let grams = super::bound::Grams::new(op);
    let weak = |r: &Ret| {
        let gram = grams.of(r.pixel);
        let mut col = vec![0.0; ks];
        response.add_to(r.a, r.d, &mut col);
        let energy: f64 = (0..ks)
            .map(|k| col[k] * dot(&gram[k * ks..(k + 1) * ks], &col))
            .sum();
        energy.max(0.0).sqrt() <= 2.0 * super::reseat::NOISE_MARGIN * sigma
    };
    let before = found.len();
    found.retain(|r| lit[r.pixel] || !weak(r));
    if found.len() < before {
        (found, misfit) = refine(op, y, found, response, GN_STEPS, &mut applies)?;
    }
    let added = found.iter().filter(|r| !lit[r.pixel]).count();
    report.add_applies(applies);
    if added == 0 {
        return Ok(None);
    }
    Ok(Some((
        continuous_of(op, found, misfit, response, report)?,
        added,
    )))
}

/// Whether `a`'s squared misfit is below `b`'s.
pub(crate) fn fits_better<T>(a: &Continuous<T>, b: &Continuous<T>) -> bool {
    a.misfit < b.misfit
}

/// The fit of the returns `found` ([`refine`]), then their voxels and [`Returns`].
fn fit<T: Real>(
    op: &dyn LidarOperator<T>,
    y: &[T],
    found: Vec<Ret>,
    response: &Response,
    report: &mut Report,
) -> Result<Continuous<T>> {
    let mut applies = Applies::default();
    let (found, misfit) = refine(op, y, found, response, GN_STEPS, &mut applies)?;
    report.add_applies(applies);
    continuous_of(op, found, misfit, response, report.clone())
}

fn continuous_of<T: Real>(
    op: &dyn LidarOperator<T>,
    found: Vec<Ret>,
    misfit: f64,
    response: &Response,
    report: Report,
) -> Result<Continuous<T>> {
    let g = op.geometry();
    let returns = returns_of(&found, g.m, g.n);
    let x = returns.render::<T>(g.ks, response)?.as_slice().to_vec();
    Ok(Continuous {
        x,
        returns,
        report,
        found,
        misfit,
    })
}

/// The fitted estimate `c` after rounds of proposals
/// ([`refine_with_neighbours`](super::reseat::refine_with_neighbours): the depths its
/// neighbours suggest, and each pixel's depth in `hints`, another estimate's, where given),
/// then refitted with the prior on the depth map ([`with_prior`](super::prior::with_prior)).
pub(crate) fn settle<T: Real>(
    op: &dyn LidarOperator<T>,
    y: &[T],
    c: Continuous<T>,
    response: &Response,
    hints: Option<&[Option<f64>]>,
) -> Result<Continuous<T>> {
    let mut applies = Applies::default();
    let settled = super::reseat::refine_with_neighbours(
        op,
        y,
        (c.found, c.misfit),
        response,
        hints,
        &mut applies,
    )?;
    let (found, misfit) = super::prior::with_prior(op, y, settled, response, &mut applies)?;
    let mut report = c.report;
    report.add_applies(applies);
    continuous_of(op, found, misfit, response, report)
}

/// The returns `found` moved by `scale` times `step` (amplitudes kept nonnegative, depths within
/// [0, top]).
pub(super) fn stepped(found: &[Ret], step: &[(f64, f64)], scale: f64, top: f64) -> Vec<Ret> {
    found
        .iter()
        .zip(step)
        .map(|(r, (da, dd))| Ret {
            pixel: r.pixel,
            a: (r.a + scale * da).max(0.0),
            d: (r.d + scale * dd).clamp(0.0, top),
        })
        .collect()
}

/// The least-squares fit of the returns `found` under `response` (the triangle's pair fit,
/// then Gauss–Newton), without the returns whose amplitude fell to zero, and its squared
/// residual.
pub(super) fn refine<T: Real>(
    op: &dyn LidarOperator<T>,
    y: &[T],
    mut found: Vec<Ret>,
    response: &Response,
    steps: usize,
    applies: &mut Applies,
) -> Result<(Vec<Ret>, f64)> {
    let g = op.geometry();
    let top = (g.ks - 1) as f64;
    let yy: f64 = dot(y, y);
    if *response == Response::Triangle {
        found = super::pairs::fit_pairs(op, y, found, g.ks, applies)?;
    }
    let mut rr = residual(op, y, &found, response, g.ks, applies)?;
    for _ in 0..steps {
        if found.is_empty() || rr <= 1e-30 * yy {
            break;
        }
        let step = gauss_newton_step(op, y, &found, response, g.ks, applies)?;
        let mut scale = 1.0;
        let mut accepted = None;
        for _ in 0..=HALVINGS {
            let trial = stepped(&found, &step, scale, top);
            let t = residual(op, y, &trial, response, g.ks, applies)?;
            if t < rr {
                accepted = Some((trial, t));
                break;
            }
            scale *= 0.5;
        }
        let Some((trial, t)) = accepted else { break };
        let moved = found
            .iter()
            .zip(&trial)
            .map(|(a, b)| (a.d - b.d).abs())
            .fold(0.0, f64::max);
        let gain = rr - t;
        found = trial;
        rr = t;
        let dof = y.len().saturating_sub(2 * found.len());
        if moved < 1e-9
            || gain <= 1e-14 * yy
            || (dof > 0 && gain <= GN_NOISE_GAIN * rr / dof as f64)
        {
            break;
        }
    }
    // Amplitudes at round-off of the largest are no return.
    let largest = found.iter().map(|r| r.a).fold(0.0, f64::max);
    found.retain(|r| r.a > 1e-9 * largest);
    Ok((found, rr))
}

/// y − A·w.
pub(super) fn residual_through<T: Real>(a: &dyn LinearOperator<T>, y: &[T], w: &[T]) -> Vec<T> {
    let mut r = vec![T::zero(); y.len()];
    a.apply(w, &mut r);
    for (ri, yi) in r.iter_mut().zip(y) {
        *ri = *yi - *ri;
    }
    r
}

/// The voxels the returns reach, sorted, and each return's (voxel index, g, g′) entries.
type Spread = (Vec<usize>, Vec<Vec<(usize, f64, f64)>>);

fn spread(found: &[Ret], response: &Response, ks: usize) -> Spread {
    let mut voxels: Vec<usize> = found
        .iter()
        .flat_map(|r| response.voxels(r.d, ks).map(move |k| r.pixel * ks + k))
        .collect();
    voxels.sort_unstable();
    voxels.dedup();
    let entries = found
        .iter()
        .map(|r| {
            response
                .voxels(r.d, ks)
                .map(|k| {
                    let (v, s) = response.eval(k as f64 - r.d);
                    let i = voxels
                        .binary_search(&(r.pixel * ks + k))
                        .expect("a listed voxel");
                    (i, v, s)
                })
                .collect()
        })
        .collect();
    (voxels, entries)
}

/// The operator on the voxels the returns reach ([`spread`]), with their entries, and the
/// residual y − A·x(returns).
type Misfit<'a, T> = (Box<dyn LinearOperator<T> + 'a>, Spread, Vec<T>);

fn misfit<'a, T: Real>(
    op: &'a dyn LidarOperator<T>,
    y: &[T],
    found: &[Ret],
    response: &Response,
    ks: usize,
) -> Result<Misfit<'a, T>> {
    let (voxels, entries) = spread(found, response, ks);
    let mut xv = vec![0.0f64; voxels.len()];
    for (r, e) in found.iter().zip(&entries) {
        for &(i, v, _) in e {
            xv[i] += r.a * v;
        }
    }
    let xv: Vec<T> = xv.into_iter().map(T::of_f64).collect();
    let a = op.restrict_columns(voxels.clone())?;
    let r = residual_through(&*a, y, &xv);
    Ok((a, (voxels, entries), r))
}

/// ‖y − A·x(returns)‖².
pub(super) fn residual<T: Real>(
    op: &dyn LidarOperator<T>,
    y: &[T],
    found: &[Ret],
    response: &Response,
    ks: usize,
    applies: &mut Applies,
) -> Result<f64> {
    if found.is_empty() {
        return Ok(dot(y, y));
    }
    let (_, _, r) = misfit(op, y, found, response, ks)?;
    applies.support += 1;
    Ok(dot(&r, &r))
}

/// The Jacobian of the returns' measurements in the step variables (Δa, a·Δd) of each return
/// (columns A·g(· − d) and −A·g′(· − d): the depth's column taken as −A·g′, the step in a·d, so
/// that both columns of a return have the scale of its response), and the residual
/// y − A·x(returns).
pub(super) type Jacobian<'a, T> = (Box<dyn LinearOperator<T> + 'a>, Vec<T>);

pub(super) fn jacobian<'a, T: Real>(
    op: &'a dyn LidarOperator<T>,
    y: &[T],
    found: &[Ret],
    response: &Response,
    ks: usize,
) -> Result<Jacobian<'a, T>> {
    let (a, (voxels, entries), r) = misfit(op, y, found, response, ks)?;
    let n = found.len();
    let mut tri = sprs::TriMat::new((voxels.len(), 2 * n));
    for (j, e) in entries.iter().enumerate() {
        for &(i, v, s) in e {
            tri.add_triplet(i, 2 * j, T::of_f64(v));
            // ∂(a·g(k − d))/∂d = −a·g′(k − d): the column −g′ for the step a·Δd.
            tri.add_triplet(i, 2 * j + 1, T::of_f64(-s));
        }
    }
    let j: Box<dyn LinearOperator<T> + 'a> = Box::new(a.compose(SparseMatrix::new(tri.to_csr())?)?);
    Ok((j, r))
}

/// The CGLS settings of a Gauss–Newton step's least squares.
pub(super) fn step_solve() -> CglsParams {
    CglsParams {
        damp: 0.0,
        stopping: Stopping {
            max_iter: GN_SOLVE_ITERATIONS,
            rel_residual: Some(GN_SOLVE_TOLERANCE),
            ..Stopping::default()
        },
    }
}

/// The step variables (Δa, a·Δd) of every return as (Δa, Δd).
pub(super) fn step_of<T: Real>(found: &[Ret], delta: &[T]) -> Vec<(f64, f64)> {
    found
        .iter()
        .enumerate()
        .map(|(i, ret)| {
            let da = delta[2 * i].as_f64();
            let ad = delta[2 * i + 1].as_f64();
            (da, if ret.a > 0.0 { ad / ret.a } else { 0.0 })
        })
        .collect()
}

/// The Gauss–Newton step (Δa, Δd) of every return: the least squares of the [`jacobian`]
/// against the residual.
fn gauss_newton_step<T: Real>(
    op: &dyn LidarOperator<T>,
    y: &[T],
    found: &[Ret],
    response: &Response,
    ks: usize,
    applies: &mut Applies,
) -> Result<Vec<(f64, f64)>> {
    let (j, r) = jacobian(op, y, found, response, ks)?;
    let mut delta = vec![T::zero(); 2 * found.len()];
    let rep = cgls(&j, &r, &mut delta, &step_solve(), &mut ())?;
    applies.support += 1 + rep.forward_applies + rep.adjoint_applies;
    Ok(step_of(found, &delta))
}

/// The returns as [`Returns`] on an `m`×`n` grid, each pixel's returns nearest first.
pub(crate) fn returns_of(found: &[Ret], m: usize, n: usize) -> Returns {
    let mut per: Vec<Vec<(f64, f64)>> = vec![Vec::new(); m * n];
    for r in found {
        per[r.pixel].push((r.d, r.a));
    }
    let layers = per.iter().map(Vec::len).max().unwrap_or(0).max(1);
    let mut depth = ndarray::Array3::from_elem((layers, m, n), f64::NAN);
    let mut amplitude = ndarray::Array3::zeros((layers, m, n));
    for (p, rs) in per.iter_mut().enumerate() {
        rs.sort_by(|a, b| a.0.total_cmp(&b.0));
        for (q, (d, a)) in rs.iter().enumerate() {
            depth[[q, p / n, p % n]] = *d;
            amplitude[[q, p / n, p % n]] = *a;
        }
    }
    Returns { depth, amplitude }
}

/// `auto`'s stages under a response: TV over the response's atoms (`atoms`, its fit), then,
/// where that left the data unexplained, the grid methods' stages (`grid`, with the method auto
/// chose among them), whose returns the settling proposes, none of them kept as they are.
pub(crate) fn atom_stages<T: Real>(
    y: &[T],
    atoms: &Continuous<T>,
    grid: Option<(Vec<Stage>, Method, &Continuous<T>, bool)>,
    added: usize,
) -> Vec<Stage> {
    let over = "continuous depths from TV on the depth map over the response's atoms";
    let from_grid = grid.as_ref().is_some_and(|g| g.3);
    let verdict = match &grid {
        Some((_, used, ..)) if added > 0 => format!(
            "{over}, with the grid methods' {} returns added in the {added} pixels it left \
             empty and proposed where they differ",
            used.name()
        ),
        Some((_, used, ..)) => format!(
            "{over}, with the grid methods' {} returns proposed where they differ",
            used.name()
        ),
        None => format!("{over} explain the data: no grid method"),
    };
    let mut stages = vec![Stage {
        method: Method::Tv,
        relative_residual: relative_misfit(y, atoms),
        returns: atoms.returns.depth.iter().filter(|d| !d.is_nan()).count(),
        report: Some(atoms.report.clone()),
        kept: !from_grid,
        verdict,
    }];
    if let Some((grid, used, alone, _)) = grid {
        stages.extend(grid.into_iter().map(|mut s| {
            s.kept &= from_grid;
            s
        }));
        stages.push(Stage {
            method: used,
            relative_residual: relative_misfit(y, alone),
            returns: alone.returns.depth.iter().filter(|d| !d.is_nan()).count(),
            report: Some(alone.report.clone()),
            kept: from_grid,
            verdict: "continuous depths fitted from the grid methods' returns alone, with \
                      TV's proposed where they differ"
                .to_string(),
        });
    }
    stages
}

/// ‖y − A·x‖/‖y‖ of a fitted estimate.
fn relative_misfit<T: Real>(y: &[T], c: &Continuous<T>) -> f64 {
    (c.misfit / dot(y, y).max(f64::MIN_POSITIVE)).sqrt()
}

/// Whether a fitted estimate explains the data to round-off.
pub(crate) fn explains<T: Real>(y: &[T], c: &Continuous<T>) -> bool {
    relative_misfit(y, c) <= 1e-9
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn returns_group_by_pixel_nearest_first() {
        let found = [
            Ret {
                pixel: 1,
                a: 1.0,
                d: 4.5,
            },
            Ret {
                pixel: 1,
                a: 0.5,
                d: 1.25,
            },
            Ret {
                pixel: 3,
                a: 2.0,
                d: 0.0,
            },
        ];
        let r = returns_of(&found, 2, 2);
        assert_eq!(r.layers(), 2);
        assert_eq!(r.depth[[0, 0, 1]], 1.25);
        assert_eq!(r.depth[[1, 0, 1]], 4.5);
        assert_eq!(r.amplitude[[0, 1, 1]], 2.0);
        assert!(r.depth[[0, 0, 0]].is_nan());
    }
}
