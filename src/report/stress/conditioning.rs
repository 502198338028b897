//! The conditioning group: the extreme singular values of A_S, the lidar operator restricted to
//! the columns of a scene's true support, from compressive to redundant pulse lengths.
//!
//! σ_max comes from the Lanczos iteration on A_SᵀA_S ([`operator_norm`]); σ_min from inverse
//! (subspace) iteration, each step solving A_SᵀA_S z = v by conjugate gradients, when A_S can
//! have full column rank, and otherwise (σ_min = 0) from a null vector v = r − A_S⁺A_S r
//! computed by CGLS. Both are checked against the eigenvalues of the Gram matrix A_SᵀA_S, formed
//! column by column from the `f64` operator and decomposed densely.
//!
//! More samples than support voxels (K > |S|) is not enough for full rank: with a 0/1 pulse, the
//! voxel at depth j reaches only the samples j + t where p[t] = 1, so voxels at nearby depths
//! share few samples. The support is *determined* when its structural rank, the size of a
//! maximum matching of columns to the samples where they are nonzero, is |S|.

use std::ops::ControlFlow;
use std::time::Instant;

use crate::error::{Error, Result};
use crate::lidar::{simulate, Simulation, SimulationSpec};
use crate::linalg::{axpy, dot, norm2, norm2_sq};
use crate::operator::{operator_norm, LinearOperator, PowerIteration};
use crate::real::Real;
use crate::solver::{cgls, CglsParams, Stopping};

use super::{f32_exact_gaussian, stress_rng, Check, Group, Sink, StressConfig, StressRow};

/// The constant part of the tolerance of |σ − σ_ref|/σ_ref, for σ_max and σ_min alike: the
/// stopping rules of the iterations (a relative change of [`POWER_TOL`] or [`INVERSE_TOL`] per
/// step) leave errors up to about 10⁻⁹ in `f64`.
pub const SIGMA_TOL: f64 = 1e-7;

/// The factor of ε·κ² in the tolerance of |σ − σ_ref|/σ_ref (κ = 1 for σ_max): a backward-stable
/// computation in precision ε finds the eigenvalue σ² of A_SᵀA_S to within about ε·σ_max², a
/// relative error of ε·κ² for σ_min²; the norm iteration in `f32` stops at a change of ε/8 per
/// step (the power iteration before the Lanczos iteration, whose error with clustered top
/// singular values is that change divided by 1 − (σ₂/σ₁)², measured up to 4.3·10⁻⁶ = 36ε).
///
/// When the support is not determined (σ_min = 0), σ_min/σ_max of the null vector must be at most
/// `SIGMA_TOL + SIGMA_TOL_EPS·ε·κ₊`, κ₊ the condition number of A_S on its row space (the
/// `kappa_plus` value): the least squares that find the vector are accurate to about ε·κ₊.
pub const SIGMA_TOL_EPS: f64 = 1000.0;

/// Relative change of the norm estimate at which it stops (or ε/8 of the precision,
/// if larger: `f32` estimates fluctuate at that level).
pub const POWER_TOL: f64 = 1e-11;

/// Singular values of A_S below this fraction of σ_max count as zero in the `f64` reference:
/// its Gram matrix holds eigenvalues to about |S|·ε·σ_max², so singular values to about
/// 10⁻⁷·σ_max.
pub const NUMERICAL_ZERO: f64 = 1e-6;

/// Iteration limit of the norm estimate.
pub const POWER_MAX_ITER: usize = 5000;

/// Relative change of the inverse-iteration estimate at which it stops (or ε of the precision,
/// if larger).
pub const INVERSE_TOL: f64 = 1e-10;

/// Iteration limit of the inverse iteration.
pub const INVERSE_MAX_ITER: usize = 500;

/// Vectors of the inverse subspace iteration: plain inverse iteration (one vector) converges like
/// (σ₁/σ₂)² per step for the two smallest singular values σ₁ ≤ σ₂, which stalls when they are
/// close (it did at K_p = 2000 for some seeds); a block of 8 converges like (σ₁/σ₉)².
pub const BLOCK: usize = 8;

/// The rows of every pulse length, f32 then f64.
pub(super) fn run(config: &StressConfig, sink: &mut Sink<'_>) -> Result<ControlFlow<()>> {
    for &kp in &config.conditioning_pulse_lens {
        let spec = SimulationSpec::new(config.conditioning_geometry, kp, config.seed);
        let reference = Reference::new(&spec)?;
        for row in [
            row_of::<f32>(config, &spec, &reference),
            row_of::<f64>(config, &spec, &reference),
        ] {
            if sink(row).is_break() {
                return Ok(ControlFlow::Break(()));
            }
        }
    }
    Ok(ControlFlow::Continue(()))
}

/// The voxels of the scene's support, in increasing order.
fn support<T: Real>(sim: &Simulation<T>) -> Vec<usize> {
    sim.scene
        .as_slice()
        .iter()
        .enumerate()
        .filter(|(_, v)| **v != T::zero())
        .map(|(i, _)| i)
        .collect()
}

/// What the `f64` operator says about A_S: its size, its structural rank and the extreme
/// eigenvalues of its Gram matrix A_SᵀA_S.
struct Reference {
    /// The row label: K_p, its regime, K, |S| and the structural rank.
    case: String,
    /// |S|.
    columns: usize,
    /// The largest number of support columns that can each be given a sample of their own among
    /// those where they are nonzero (a maximum matching): an upper bound on the rank, which
    /// random signs attain unless columns happen to cancel exactly.
    structural_rank: usize,
    /// The eigenvalues of A_SᵀA_S, smallest first.
    lambdas: Vec<f64>,
}

impl Reference {
    fn new(spec: &SimulationSpec) -> Result<Self> {
        let sim = simulate::<f64>(spec)?;
        let op = sim.single_operator()?;
        let cols = support(&sim);
        let s = cols.len();
        if s == 0 {
            return Err(Error::param("size", "the scene has no nonzero voxel"));
        }
        let a = op.restrict_columns(cols)?;
        let mut gram = nalgebra::DMatrix::<f64>::zeros(s, s);
        let mut e = vec![0.0f64; s];
        let mut col = vec![0.0f64; a.nrows()];
        let mut g = vec![0.0f64; s];
        let mut reached: Vec<Vec<usize>> = Vec::with_capacity(s);
        for j in 0..s {
            e[j] = 1.0;
            a.apply(&e, &mut col);
            a.apply_adjoint(&col, &mut g);
            e[j] = 0.0;
            reached.push((0..col.len()).filter(|&k| col[k] != 0.0).collect());
            for (i, &v) in g.iter().enumerate() {
                gram[(i, j)] = v;
            }
        }
        let sym = (&gram + gram.transpose()) * 0.5;
        let mut lambdas: Vec<f64> = nalgebra::SymmetricEigen::new(sym)
            .eigenvalues
            .iter()
            .copied()
            .collect();
        lambdas.sort_by(f64::total_cmp);
        let structural_rank = maximum_matching(&reached, a.nrows());
        let g = spec.geometry;
        let kp = spec.pulse_len;
        Ok(Reference {
            case: format!(
                "K_p = {kp} ({}), K = {}, |S| = {s}, rank ≤ {structural_rank}",
                g.regime(kp),
                a.nrows()
            ),
            columns: s,
            structural_rank,
            lambdas,
        })
    }

    /// Whether A_S can have full column rank: every column matched to a sample of its own.
    fn determined(&self) -> bool {
        self.structural_rank == self.columns
    }

    /// The i-th smallest singular value of A_S.
    fn sigma(&self, i: usize) -> f64 {
        self.lambdas[i].max(0.0).sqrt()
    }

    fn sigma_min(&self) -> f64 {
        self.sigma(0)
    }

    fn sigma_max(&self) -> f64 {
        self.sigma(self.columns - 1)
    }

    /// σ_max over the smallest singular value above [`NUMERICAL_ZERO`]·σ_max: the condition
    /// number of A_S on its row space (the structural rank is only an upper bound on the rank:
    /// with ±1 codes and a 0/1 pulse, columns can cancel exactly).
    fn kappa_plus(&self) -> f64 {
        let top = self.sigma_max();
        let smallest = (0..self.columns)
            .map(|i| self.sigma(i))
            .find(|&s| s > NUMERICAL_ZERO * top)
            .unwrap_or(top);
        top / smallest
    }
}

/// The size of a maximum matching between columns and rows, `reached[c]` listing the rows where
/// column c is nonzero (augmenting paths, Kuhn's algorithm).
fn maximum_matching(reached: &[Vec<usize>], rows: usize) -> usize {
    fn augment(
        c: usize,
        reached: &[Vec<usize>],
        owner: &mut [Option<usize>],
        seen: &mut [bool],
    ) -> bool {
        for &r in &reached[c] {
            if seen[r] {
                continue;
            }
            seen[r] = true;
            if owner[r].is_none_or(|o| augment(o, reached, owner, seen)) {
                owner[r] = Some(c);
                return true;
            }
        }
        false
    }
    let mut owner = vec![None; rows];
    let mut matched = 0;
    for c in 0..reached.len() {
        let mut seen = vec![false; rows];
        if augment(c, reached, &mut owner, &mut seen) {
            matched += 1;
        }
    }
    matched
}

/// One row in precision `T`; a failed computation gives a failed row.
fn row_of<T: Real>(
    config: &StressConfig,
    spec: &SimulationSpec,
    reference: &Reference,
) -> StressRow {
    let start = Instant::now();
    measure::<T>(config, spec, reference, start).unwrap_or_else(|e| {
        StressRow::failed(
            Group::Conditioning,
            reference.case.clone(),
            T::NAME,
            e.to_string(),
            start.elapsed().as_secs_f64(),
        )
    })
}

/// σ_max, σ_min and κ of A_S in precision `T`.
fn measure<T: Real>(
    config: &StressConfig,
    spec: &SimulationSpec,
    reference: &Reference,
    start: Instant,
) -> Result<StressRow> {
    let sim = simulate::<T>(spec)?;
    let op = sim.single_operator()?;
    let a = op.restrict_columns(support(&sim))?;
    let norm = operator_norm(
        &a,
        &PowerIteration {
            max_iter: POWER_MAX_ITER,
            tol: POWER_TOL.max(T::EPS / 8.0),
            seed: config.seed,
        },
    )?;
    let sigma_max = norm.value;
    let determined = reference.determined();
    let (sigma_min, steps) = if determined {
        smallest_singular_value(&*a, config.seed)?
    } else {
        (null_vector_gain(&*a, config.seed)?, 0)
    };
    let kappa = sigma_max / sigma_min;
    let err_max = (sigma_max / reference.sigma_max() - 1.0).abs();
    let mut values = vec![
        ("sigma_max", sigma_max),
        ("sigma_min", sigma_min),
        ("kappa", kappa),
        ("err_max", err_max),
    ];
    let tol = |kappa: f64| SIGMA_TOL + SIGMA_TOL_EPS * T::EPS * kappa * kappa;
    let mut checks = vec![Check::at_most("err_max", err_max, tol(1.0))];
    if determined {
        let err_min = (sigma_min / reference.sigma_min() - 1.0).abs();
        values.push(("err_min", err_min));
        let kappa_ref = reference.sigma_max() / reference.sigma_min();
        checks.push(Check::above("sigma_min", sigma_min, 0.0));
        checks.push(Check::at_most("err_min", err_min, tol(kappa_ref)));
    } else {
        // σ_min = 0: the null vector must be annihilated to the accuracy of the least squares
        // that found it, ε·κ on the row space.
        let ratio = sigma_min / sigma_max;
        let kappa_plus = reference.kappa_plus();
        values.push(("min/max", ratio));
        values.push(("kappa_plus", kappa_plus));
        checks.push(Check::at_most(
            "min/max",
            ratio,
            SIGMA_TOL + SIGMA_TOL_EPS * T::EPS * kappa_plus,
        ));
    }
    values.push(("power_it", norm.iterations as f64));
    if determined {
        values.push(("inverse_it", steps as f64));
    }
    Ok(StressRow::new(
        Group::Conditioning,
        reference.case.clone(),
        T::NAME,
        values,
        checks,
        start.elapsed().as_secs_f64(),
    ))
}

/// Stopping tolerance of the conjugate gradients, relative to the right-hand side: near the
/// precision's floor (ε·κ² of A_SᵀA_S cannot be beaten), at most 10⁻¹².
fn cg_tol<T: Real>() -> f64 {
    (100.0 * T::EPS).max(1e-12)
}

/// σ_min of A (more rows than columns) by inverse subspace iteration on AᵀA: a block of
/// [`BLOCK`] orthonormal vectors V ← orth((AᵀA)⁻¹V), each solve by conjugate gradients
/// warm-started from v/θ (θ its Ritz value), then Rayleigh–Ritz on the block: the eigenvectors of
/// (AV)ᵀ(AV). σ_min is ‖Av‖ for the smallest Ritz vector v (of unit norm). Stops when it changes
/// by at most [`INVERSE_TOL`] relative (ε if larger), or after [`INVERSE_MAX_ITER`] steps;
/// returns σ_min and the steps taken.
fn smallest_singular_value<T: Real>(a: &dyn LinearOperator<T>, seed: u64) -> Result<(f64, usize)> {
    let n = a.ncols();
    let b = n.min(BLOCK);
    let mut rng = stress_rng(seed, 2);
    let mut block: Vec<Vec<T>> = (0..b)
        .map(|_| super::cast(&f32_exact_gaussian(n, &mut rng)))
        .collect();
    orthonormalize(&mut block)?;
    let mut theta = rayleigh_ritz(a, &mut block)?;
    let mut sigma = gain(a, &block[0]);
    let max_cg = 4 * n + 20;
    let tol = INVERSE_TOL.max(T::EPS);
    for step in 1..=INVERSE_MAX_ITER {
        let top = theta.last().copied().unwrap_or(0.0);
        for (v, &t) in block.iter_mut().zip(&theta) {
            // From v/θ, the solution if v were an eigenvector; from zero for a Ritz value at
            // round-off level, whose inverse could overflow `T`.
            let guess = if t > T::EPS * top { 1.0 / t } else { 0.0 };
            let mut z: Vec<T> = v.iter().map(|&e| T::of_f64(e.as_f64() * guess)).collect();
            conjugate_gradients(a, v, &mut z, cg_tol::<T>(), max_cg);
            *v = z;
        }
        orthonormalize(&mut block)?;
        theta = rayleigh_ritz(a, &mut block)?;
        let next = gain(a, &block[0]);
        if !next.is_finite() {
            return Err(Error::NonFinite {
                what: "inverse iteration".to_string(),
            });
        }
        let done = (next - sigma).abs() <= tol * next;
        sigma = next;
        if done {
            return Ok((sigma, step));
        }
    }
    Ok((sigma, INVERSE_MAX_ITER))
}

/// ‖Av‖/‖v‖, accumulated in `f64`.
fn gain<T: Real>(a: &dyn LinearOperator<T>, v: &[T]) -> f64 {
    let mut av = vec![T::zero(); a.nrows()];
    a.apply(v, &mut av);
    norm2(&av) / norm2(v)
}

/// Orthonormalizes the block in place by modified Gram–Schmidt, twice, in `f64`.
fn orthonormalize<T: Real>(block: &mut [Vec<T>]) -> Result<()> {
    let mut w: Vec<Vec<f64>> = block
        .iter()
        .map(|v| v.iter().map(|e| e.as_f64()).collect())
        .collect();
    for _ in 0..2 {
        for i in 0..w.len() {
            let (done, rest) = w.split_at_mut(i);
            let v = &mut rest[0];
            for u in done.iter() {
                let c = dot(u, v);
                axpy(-c, u, v);
            }
            let nv = norm2(v);
            if !(nv.is_finite() && nv > 0.0) {
                return Err(Error::NonFinite {
                    what: format!("block vector {i} of norm {nv} in the inverse iteration"),
                });
            }
            v.iter_mut().for_each(|e| *e /= nv);
        }
    }
    for (v, u) in block.iter_mut().zip(&w) {
        *v = super::cast(u);
    }
    Ok(())
}

/// Rayleigh–Ritz on an orthonormal block V: the eigenpairs (θ, y) of H = (AV)ᵀ(AV), smallest
/// first; V becomes the Ritz vectors V·y. Returns the Ritz values.
fn rayleigh_ritz<T: Real>(a: &dyn LinearOperator<T>, block: &mut [Vec<T>]) -> Result<Vec<f64>> {
    let b = block.len();
    let images: Vec<Vec<T>> = block
        .iter()
        .map(|v| {
            let mut av = vec![T::zero(); a.nrows()];
            a.apply(v, &mut av);
            av
        })
        .collect();
    let h = nalgebra::DMatrix::<f64>::from_fn(b, b, |i, j| dot(&images[i], &images[j]));
    if h.iter().any(|v| !v.is_finite()) {
        return Err(Error::NonFinite {
            what: "the projected Gram matrix of the inverse iteration".to_string(),
        });
    }
    let eig = nalgebra::SymmetricEigen::new(h);
    let mut order: Vec<usize> = (0..b).collect();
    order.sort_by(|&i, &j| eig.eigenvalues[i].total_cmp(&eig.eigenvalues[j]));
    let n = block.first().map_or(0, Vec::len);
    let ritz: Vec<Vec<T>> = order
        .iter()
        .map(|&c| {
            (0..n)
                .map(|e| {
                    let s: f64 = (0..b)
                        .map(|i| eig.eigenvectors[(i, c)] * block[i][e].as_f64())
                        .sum();
                    T::of_f64(s)
                })
                .collect()
        })
        .collect();
    block.clone_from_slice(&ritz);
    Ok(order.iter().map(|&c| eig.eigenvalues[c]).collect())
}

/// Solves AᵀA z = b by conjugate gradients from the given z, until ‖b − AᵀAz‖ ≤ tol·‖b‖, a
/// direction of no curvature, or `max_iter` steps. Curvatures pᵀAᵀAp are computed as ‖Ap‖².
fn conjugate_gradients<T: Real>(
    a: &dyn LinearOperator<T>,
    b: &[T],
    z: &mut [T],
    tol: f64,
    max_iter: usize,
) {
    let n = b.len();
    let mut ap = vec![T::zero(); a.nrows()];
    let mut gp = vec![T::zero(); n];
    a.apply(z, &mut ap);
    a.apply_adjoint(&ap, &mut gp);
    let mut r: Vec<T> = b.iter().zip(&gp).map(|(&bi, &gi)| bi - gi).collect();
    let mut p = r.clone();
    let mut rr = norm2_sq(&r);
    let stop = tol * tol * norm2_sq(b);
    for _ in 0..max_iter {
        if rr <= stop {
            break;
        }
        a.apply(&p, &mut ap);
        let curvature = norm2_sq(&ap);
        if !(curvature.is_finite() && curvature > 0.0) {
            break;
        }
        a.apply_adjoint(&ap, &mut gp);
        let alpha = rr / curvature;
        axpy(T::of_f64(alpha), &p, z);
        axpy(T::of_f64(-alpha), &gp, &mut r);
        let next = norm2_sq(&r);
        let beta = next / rr;
        rr = next;
        for (pi, &ri) in p.iter_mut().zip(&r) {
            *pi = T::of_f64(ri.as_f64() + beta * pi.as_f64());
        }
    }
}

/// ‖Av‖/‖v‖ for a null vector of a matrix with no more rows than columns: v = r − A⁺A r for a
/// random r, A⁺A r the minimum-norm solution of A z = A r, which CGLS from zero reaches.
fn null_vector_gain<T: Real>(a: &dyn LinearOperator<T>, seed: u64) -> Result<f64> {
    let n = a.ncols();
    let mut rng = stress_rng(seed, 3);
    let r: Vec<T> = super::cast(&f32_exact_gaussian(n, &mut rng));
    let mut ar = vec![T::zero(); a.nrows()];
    a.apply(&r, &mut ar);
    let mut z = vec![T::zero(); n];
    let params = CglsParams {
        damp: 0.0,
        stopping: Stopping {
            max_iter: 20 * n + 100,
            rel_residual: Some(cg_tol::<T>()),
            ..Stopping::default()
        },
    };
    cgls(a, &ar, &mut z, &params, &mut ())?;
    let v: Vec<T> = r.iter().zip(&z).map(|(&ri, &zi)| ri - zi).collect();
    let mut av = vec![T::zero(); a.nrows()];
    a.apply(&v, &mut av);
    Ok(norm2(&av) / norm2(&v))
}
