//! The Cramér–Rao bound on continuous depths: how well any unbiased estimate can place a
//! return, for a given scene, system response, operator and noise level.
//!
//! The model is y = A x(θ) + n with n white Gaussian noise of standard deviation σ per sample
//! and every return r of pixel p filling the voxels a_r·g(k − d_r). With every other pixel
//! known, the Fisher information of pixel p's parameters θ_p = (a_0, d_0, a_1, d_1, …) is
//! JᵀJ/σ², J's columns being A_p·g(· − d_r) and −a_r·A_p·g′(· − d_r): in voxel space CᵀG_pC/σ²
//! with G_p = A_pᵀA_p the pixel's Gram block (so a pixel costs O(K_s²), not an application of
//! A). The bound on d_r is the standard deviation σ·√[(CᵀG_pC)⁻¹]_{d_r d_r}, in bins.
//!
//! Knowing the other pixels makes this the smallest error any unbiased estimate can have:
//! with them unknown (and, in the compressive regime, fewer measurements than unknowns) the
//! bound can only rise, so an RMSE/bound ratio near 1 is the best a method can show. At a
//! kink of the response (the triangle's integer depths) the slope is the right derivative.

use ndarray::Array3;

use crate::error::{Error, Result};
use crate::lidar::{LidarOperator, Response, Returns};
use crate::real::Real;

/// The per-return Cramér–Rao bound on the depth, in bins (a standard deviation), of the
/// returns `truth` under `response`, the operator `op` and white Gaussian noise of standard
/// deviation `sigma` per sample: (R, M, N) as `truth`, NaN where there is no return, +∞ where a
/// pixel's returns cannot be told apart from the data (its Fisher information is singular:
/// an unobserved pixel, two returns at one depth). Every other pixel is taken as known (see
/// the module's notes); the pixels are independent and run in parallel.
///
/// # Errors
/// [`Error::ShapeMismatch`] if `truth` is not on `op`'s M × N grid; [`Error::InvalidParameter`]
/// (`sigma`) unless σ is finite and ≥ 0, (`kernel`) for the delta response (depths on the grid
/// have no slope), (`depth`) for a return whose depth is outside the column.
pub fn depth_bound<T: Real>(
    op: &dyn LidarOperator<T>,
    truth: &Returns,
    response: &Response,
    sigma: f64,
) -> Result<Array3<f64>> {
    use rayon::prelude::*;
    let g = op.geometry();
    let (layers, m, n) = truth.depth.dim();
    check(op, truth, response, sigma)?;
    // The Gram block where every pixel shares it; otherwise each pixel's columns.
    let uniform = op.uniform_pixel_gram().then(|| op.pixel_gram(0));
    let pixels: Vec<Vec<f64>> = (0..m * n)
        .into_par_iter()
        .map(|p| {
            let (i, j) = (p / n, p % n);
            let rets: Vec<(f64, f64)> = (0..layers)
                .map(|r| (truth.amplitude[[r, i, j]], truth.depth[[r, i, j]]))
                .filter(|(_, d)| !d.is_nan())
                .collect();
            if rets.is_empty() {
                return Vec::new();
            }
            match &uniform {
                Some(gram) => pixel_bound(gram, g.ks, &rets, response, sigma),
                None => {
                    let cols = parameter_columns(&rets, response, g.ks);
                    bounds_of(fisher_by_columns(op, p, &cols), rets.len(), sigma)
                }
            }
        })
        .collect();
    let mut bound = Array3::from_elem((layers, m, n), f64::NAN);
    for (p, b) in pixels.into_iter().enumerate() {
        for (r, v) in b.into_iter().enumerate() {
            bound[[r, p / n, p % n]] = v;
        }
    }
    Ok(bound)
}

/// The most multiply-adds, samples × (2·returns)², that [`joint_depth_bound`] spends on one
/// operator's Fisher information (about ten seconds on two cores).
pub const JOINT_BOUND_MAX_WORK: f64 = 5e10;

/// Whether [`joint_depth_bound`] takes `returns` returns over `samples` measurements
/// (samples × (2·returns)² ≤ [`JOINT_BOUND_MAX_WORK`]).
pub fn joint_bound_fits(samples: usize, returns: usize) -> bool {
    samples as f64 * (2.0 * returns as f64).powi(2) <= JOINT_BOUND_MAX_WORK
}

/// The per-return Cramér–Rao bound on the depths of `truth` with **every** return's amplitude
/// and depth unknown at once (the support known), as a method that fits all returns to the
/// data faces: the Fisher information is JᵀJ/σ² over all returns, J's columns A·g(· − d_r)
/// and −a_r·A·g′(· − d_r) across pixels, and the bound on d_r is σ·√[(JᵀJ)⁻¹]_{d_r d_r}.
/// It is never below [`depth_bound`]'s (which holds the other pixels known), and rises above
/// it as measurements per return fall: in the compressive regime the pixels share the few
/// measurements and their errors add. (R, M, N) as `truth`, NaN where there is no return;
/// +∞ for every return where the returns together cannot be told apart from the data.
///
/// # Errors
/// As [`depth_bound`]; [`Error::InvalidParameter`] (`returns`) where samples × (2·returns)²
/// exceeds [`JOINT_BOUND_MAX_WORK`] ([`joint_bound_fits`]); [`Error::TooLarge`] where the
/// Jacobian and the Fisher information do not fit in memory.
pub fn joint_depth_bound<T: Real>(
    op: &dyn LidarOperator<T>,
    truth: &Returns,
    response: &Response,
    sigma: f64,
) -> Result<Array3<f64>> {
    check(op, truth, response, sigma)?;
    let g = op.geometry();
    let n = truth.depth.dim().2;
    let rets: Vec<(usize, usize, f64, f64)> = truth
        .depth
        .indexed_iter()
        .filter(|(_, d)| !d.is_nan())
        .map(|((r, i, j), &d)| (r, i * n + j, truth.amplitude[[r, i, j]], d))
        .collect();
    let mut bound = Array3::from_elem(truth.depth.dim(), f64::NAN);
    if rets.is_empty() {
        return Ok(bound);
    }
    let (k, q) = (op.nrows(), 2 * rets.len());
    if !joint_bound_fits(k, rets.len()) {
        return Err(Error::param(
            "returns",
            format!(
                "the joint bound of {} returns over {k} samples needs {:.1e} multiply-adds, \
                 more than {JOINT_BOUND_MAX_WORK:.0e}: bound a part (a tile) or hold the other \
                 pixels known (depth_bound)",
                rets.len(),
                k as f64 * (q as f64).powi(2)
            ),
        ));
    }
    crate::limits::MemoryPlan::new()
        .add("Jacobian", (k * q) as u128, 8)
        .add("Fisher information and its inverse", 2 * (q * q) as u128, 8)
        .check(
            &format!("the joint bound of {} returns", rets.len()),
            "bound a part (a tile) or hold the other pixels known (depth_bound)",
        )?;
    let mut jacobian = nalgebra::DMatrix::<f64>::zeros(k, q);
    for (c, &(_, p, a, d)) in rets.iter().enumerate() {
        let cols = parameter_columns(&[(a, d)], response, g.ks);
        for (which, image) in images(op, p, &cols).into_iter().enumerate() {
            jacobian.column_mut(c * 2 + which).copy_from_slice(&image);
        }
    }
    let fisher = jacobian.tr_mul(&jacobian);
    drop(jacobian);
    for (&(r, p, _, _), b) in rets.iter().zip(bounds_of(fisher, rets.len(), sigma)) {
        bound[[r, p / n, p % n]] = b;
    }
    Ok(bound)
}

/// The checks of [`depth_bound`] and [`joint_depth_bound`].
fn check<T: Real>(
    op: &dyn LidarOperator<T>,
    truth: &Returns,
    response: &Response,
    sigma: f64,
) -> Result<()> {
    let g = op.geometry();
    let (_, m, n) = truth.depth.dim();
    if (m, n) != (g.m, g.n) {
        return Err(Error::shape(
            "returns vs the operator's pixels",
            g.m * g.n,
            m * n,
        ));
    }
    if !(sigma.is_finite() && sigma >= 0.0) {
        return Err(Error::param(
            "sigma",
            format!("must be finite and >= 0, got {sigma}"),
        ));
    }
    if response.is_delta() {
        return Err(Error::param(
            "kernel",
            "the bound on a continuous depth needs a response with a slope (triangle, gaussian:S \
             or measured), not delta",
        ));
    }
    if let Some(d) = truth
        .depth
        .iter()
        .find(|d| !d.is_nan() && (**d < 0.0 || **d > (g.ks - 1) as f64))
    {
        return Err(Error::param(
            "depth",
            format!(
                "a true depth of {d} bins is outside the column of {} bins",
                g.ks
            ),
        ));
    }
    Ok(())
}

/// The columns of C in voxel space: g(· − d_r) and −a_r·g′(· − d_r) for each return `(a, d)`.
fn parameter_columns(rets: &[(f64, f64)], response: &Response, ks: usize) -> Vec<Vec<f64>> {
    rets.iter()
        .flat_map(|&(a, d)| {
            let (mut value, mut slope) = (vec![0.0; ks], vec![0.0; ks]);
            for k in response.voxels(d, ks) {
                let (v, s) = response.eval(k as f64 - d);
                value[k] = v;
                slope[k] = -a * s;
            }
            [value, slope]
        })
        .collect()
}

/// Each pixel's Gram block: computed once where every pixel shares it, per pixel otherwise.
pub(super) struct Grams<'a, T> {
    op: &'a dyn LidarOperator<T>,
    uniform: Option<Vec<f64>>,
}

impl<'a, T: Real> Grams<'a, T> {
    pub(super) fn new(op: &'a dyn LidarOperator<T>) -> Self {
        let uniform = op.uniform_pixel_gram().then(|| op.pixel_gram(0));
        Grams { op, uniform }
    }

    /// Pixel `p`'s Gram block, K_s × K_s by rows.
    pub(super) fn of(&self, p: usize) -> std::borrow::Cow<'_, [f64]> {
        match &self.uniform {
            Some(g) => std::borrow::Cow::Borrowed(g),
            None => std::borrow::Cow::Owned(self.op.pixel_gram(p)),
        }
    }
}

/// The bound on the depth of each of one pixel's returns `(a, d)` from its Gram block `gram`
/// (ks × ks, row-major), the other pixels held.
pub(super) fn pixel_bound(
    gram: &[f64],
    ks: usize,
    rets: &[(f64, f64)],
    response: &Response,
    sigma: f64,
) -> Vec<f64> {
    let cols = parameter_columns(rets, response, ks);
    bounds_of(fisher_by_gram(gram, ks, &cols), rets.len(), sigma)
}

/// CᵀGC from a pixel's Gram block `gram` (ks × ks, row-major).
fn fisher_by_gram(gram: &[f64], ks: usize, cols: &[Vec<f64>]) -> nalgebra::DMatrix<f64> {
    let gc: Vec<Vec<f64>> = cols
        .iter()
        .map(|c| {
            (0..ks)
                .map(|k| (0..ks).map(|l| gram[k * ks + l] * c[l]).sum())
                .collect()
        })
        .collect();
    let q = cols.len();
    nalgebra::DMatrix::from_fn(q, q, |i, j| {
        cols[i].iter().zip(&gc[j]).map(|(a, b)| a * b).sum()
    })
}

/// (A_pC)ᵀ(A_pC) from pixel `p`'s columns of `op`, exact whatever its codes.
fn fisher_by_columns<T: Real>(
    op: &dyn LidarOperator<T>,
    p: usize,
    cols: &[Vec<f64>],
) -> nalgebra::DMatrix<f64> {
    let image = images(op, p, cols);
    let q = cols.len();
    nalgebra::DMatrix::from_fn(q, q, |i, j| crate::linalg::dot(&image[i], &image[j]))
}

/// A_p·c for each of pixel `p`'s voxel-space columns `cols`, each of `op`'s voxel columns
/// read once.
fn images<T: Real>(op: &dyn LidarOperator<T>, p: usize, cols: &[Vec<f64>]) -> Vec<Vec<f64>> {
    let ks = op.column_len();
    let mut image = vec![vec![0.0; op.nrows()]; cols.len()];
    for k in 0..ks {
        if cols.iter().all(|c| c[k] == 0.0) {
            continue;
        }
        let (start, values) = op.column(p * ks + k);
        for (c, out) in cols.iter().zip(image.iter_mut()) {
            if c[k] != 0.0 {
                for (o, v) in out[start..start + values.len()].iter_mut().zip(&values) {
                    *o += c[k] * v;
                }
            }
        }
    }
    image
}

/// σ·√[F⁻¹]_{d_r d_r} for each of `returns` returns of the Fisher information `fisher` (σ
/// factored out): +∞ where `fisher` is singular or too ill-conditioned for its inverse to mean
/// anything.
fn bounds_of(fisher: nalgebra::DMatrix<f64>, returns: usize, sigma: f64) -> Vec<f64> {
    let scale = fisher.diagonal().iter().fold(0.0f64, |s, v| s.max(v.abs()));
    let inverse = (scale > 0.0)
        .then(|| fisher.cholesky())
        .flatten()
        .filter(|c| {
            let smallest = c
                .l_dirty()
                .diagonal()
                .iter()
                .fold(f64::INFINITY, |s, v| s.min(v.abs()));
            smallest * smallest > 1e-12 * scale
        })
        .map(|c| c.inverse());
    (0..returns)
        .map(|r| match &inverse {
            Some(inv) => sigma * inv[(2 * r + 1, 2 * r + 1)].max(0.0).sqrt(),
            None => f64::INFINITY,
        })
        .collect()
}

/// The noise's standard deviation per sample that a fit's residual `r` shows, with `unknowns`
/// parameters fitted: ‖r‖/√(K − unknowns); `None` when the fit has no degree of freedom left.
pub fn residual_sigma(residual_norm: f64, samples: usize, unknowns: usize) -> Option<f64> {
    (samples > unknowns && residual_norm.is_finite())
        .then(|| residual_norm / ((samples - unknowns) as f64).sqrt())
}

#[cfg(test)]
mod tests {
    use std::sync::Arc;

    use ndarray::Array3;
    use rand::SeedableRng;
    use rand_distr::{Distribution, Normal};

    use super::*;
    use crate::lidar::{Codes, Geometry, RdOperator};
    use crate::operator::LinearOperator;

    fn operator(g: Geometry, kp: usize, ternary: bool) -> RdOperator<f64> {
        let pulse: Vec<f64> = (0..kp)
            .map(|i| ((i * 7 + 3) % 5 < 3) as u8 as f64)
            .collect();
        let codes = if ternary {
            Codes::random_ternary(g.pixels(), g.samples(kp), 0.3, 5)
        } else {
            Codes::random_binary(g.pixels(), g.samples(kp), 5)
        };
        RdOperator::new(g, pulse, Arc::new(codes.unwrap())).unwrap()
    }

    /// The measurements of `returns` under `response`.
    fn measure(op: &RdOperator<f64>, returns: &Returns, response: &Response) -> Vec<f64> {
        let g = op.geometry();
        let x = returns.render::<f64>(g.ks, response).unwrap();
        let mut y = vec![0.0; op.nrows()];
        op.apply(x.data().as_slice().unwrap(), &mut y);
        y
    }

    #[test]
    fn the_bound_inverts_the_fisher_information_of_the_measurements() {
        // Ternary codes (a Gram block per pixel), two returns in one pixel, one in another;
        // the Jacobian from central differences of whole applications.
        let g = Geometry::new(2, 3, 12).unwrap();
        let op = operator(g, 40, true);
        let mut depth = Array3::from_elem((2, 2, 3), f64::NAN);
        let mut amplitude = Array3::zeros((2, 2, 3));
        for (r, i, j, a, d) in [
            (0, 0, 1, 1.5, 3.3),
            (1, 0, 1, 0.7, 7.6),
            (0, 1, 2, 2.0, 5.45),
        ] {
            depth[[r, i, j]] = d;
            amplitude[[r, i, j]] = a;
        }
        let truth = Returns::new(depth, amplitude).unwrap();
        let sigma = 0.3;
        for response in [Response::gaussian(0.8).unwrap(), Response::Triangle] {
            let bound = depth_bound(&op, &truth, &response, sigma).unwrap();
            let pixel = [(0usize, 1usize, vec![0usize, 1]), (1, 2, vec![0])];
            for (i, j, layers) in pixel {
                let h = 1e-6;
                let mut jac = Vec::new();
                for &r in &layers {
                    for field in 0..2 {
                        let mut plus = truth.clone();
                        let mut minus = truth.clone();
                        let (p, q) = if field == 0 {
                            (
                                &mut plus.amplitude[[r, i, j]],
                                &mut minus.amplitude[[r, i, j]],
                            )
                        } else {
                            (&mut plus.depth[[r, i, j]], &mut minus.depth[[r, i, j]])
                        };
                        *p += h;
                        *q -= h;
                        let (yp, ym) = (
                            measure(&op, &plus, &response),
                            measure(&op, &minus, &response),
                        );
                        jac.push(
                            yp.iter()
                                .zip(&ym)
                                .map(|(a, b)| (a - b) / (2.0 * h))
                                .collect::<Vec<_>>(),
                        );
                    }
                }
                let q = jac.len();
                let fisher = nalgebra::DMatrix::from_fn(q, q, |a, b| {
                    jac[a].iter().zip(&jac[b]).map(|(u, v)| u * v).sum::<f64>() / (sigma * sigma)
                });
                let inv = fisher.try_inverse().unwrap();
                for (k, &r) in layers.iter().enumerate() {
                    let want = inv[(2 * k + 1, 2 * k + 1)].sqrt();
                    let got = bound[[r, i, j]];
                    assert!(
                        (got - want).abs() <= 1e-5 * want,
                        "{response} ({r},{i},{j}): {got} vs {want}"
                    );
                }
            }
            assert!(bound[[0, 0, 0]].is_nan() && bound[[1, 1, 2]].is_nan());
            // Linear in σ.
            let twice = depth_bound(&op, &truth, &response, 2.0 * sigma).unwrap();
            assert!((twice[[0, 1, 2]] - 2.0 * bound[[0, 1, 2]]).abs() < 1e-12);
        }
    }

    #[test]
    fn the_maximum_likelihood_depth_of_one_pixel_spreads_as_the_bound_says() {
        // The other pixels known (empty): Gauss–Newton on (a, d) from the truth, over many
        // noise draws; the spread of the depth is the bound within the Monte Carlo error.
        let g = Geometry::new(2, 2, 10).unwrap();
        let op = operator(g, 30, false);
        let response = Response::gaussian(0.8).unwrap();
        let (a0, d0) = (1.0, 4.37);
        let one = |a: f64, d: f64| {
            let mut depth = Array3::from_elem((1, 2, 2), f64::NAN);
            let mut amplitude = Array3::zeros((1, 2, 2));
            depth[[0, 1, 0]] = d;
            amplitude[[0, 1, 0]] = a;
            Returns::new(depth, amplitude).unwrap()
        };
        let clean = measure(&op, &one(a0, d0), &response);
        let sigma = 0.15;
        let bound = depth_bound(&op, &one(a0, d0), &response, sigma).unwrap()[[0, 1, 0]];
        assert!(bound > 0.02 && bound < 0.2, "bound {bound}");
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(11);
        let noise = Normal::new(0.0, sigma).unwrap();
        let draws = 400;
        let mut errors = Vec::new();
        for _ in 0..draws {
            let y: Vec<f64> = clean.iter().map(|v| v + noise.sample(&mut rng)).collect();
            let (mut a, mut d) = (a0, d0);
            for _ in 0..20 {
                let f = measure(&op, &one(a, d), &response);
                let h = 1e-6;
                let ja: Vec<f64> = measure(&op, &one(a + h, d), &response)
                    .iter()
                    .zip(&f)
                    .map(|(p, q)| (p - q) / h)
                    .collect();
                let jd: Vec<f64> = measure(&op, &one(a, d + h), &response)
                    .iter()
                    .zip(&f)
                    .map(|(p, q)| (p - q) / h)
                    .collect();
                let r: Vec<f64> = y.iter().zip(&f).map(|(u, v)| u - v).collect();
                let dot = |u: &[f64], v: &[f64]| u.iter().zip(v).map(|(p, q)| p * q).sum::<f64>();
                let (aa, ad, dd) = (dot(&ja, &ja), dot(&ja, &jd), dot(&jd, &jd));
                let (ba, bd) = (dot(&ja, &r), dot(&jd, &r));
                let det = aa * dd - ad * ad;
                a += (dd * ba - ad * bd) / det;
                d += (aa * bd - ad * ba) / det;
            }
            errors.push(d - d0);
        }
        let rmse = (errors.iter().map(|e| e * e).sum::<f64>() / draws as f64).sqrt();
        // 400 draws: the RMSE's relative standard error is about 1/√800 ≈ 3.5%.
        assert!(
            (rmse / bound - 1.0).abs() < 0.12,
            "RMSE {rmse} vs bound {bound}"
        );
    }

    /// A 2×2×6 operator and two returns on its diagonal.
    fn two_returns() -> (RdOperator<f64>, Returns) {
        let op = operator(Geometry::new(2, 2, 6).unwrap(), 20, false);
        let truth = Returns::single(
            ndarray::arr2(&[[1.5, f64::NAN], [f64::NAN, 2.0]]),
            ndarray::arr2(&[[1.0, 0.0], [0.0, 1.0]]),
        )
        .unwrap();
        (op, truth)
    }

    #[test]
    fn bad_requests_are_refused_by_name() {
        let (op, truth) = two_returns();
        let name = |r: Result<Array3<f64>>| match r {
            Err(Error::InvalidParameter { name, .. }) => name,
            other => panic!("{other:?}"),
        };
        assert_eq!(
            name(depth_bound(&op, &truth, &Response::Triangle, f64::NAN)),
            "sigma"
        );
        assert_eq!(
            name(depth_bound(&op, &truth, &Response::Delta, 1.0)),
            "kernel"
        );
        let mut far = truth.clone();
        far.depth[[0, 0, 0]] = 6.5;
        assert_eq!(
            name(depth_bound(&op, &far, &Response::Triangle, 1.0)),
            "depth"
        );
        let wide = Returns::single(
            Array3::<f64>::from_elem((1, 3, 2), 1.0)
                .index_axis(ndarray::Axis(0), 0)
                .to_owned(),
            ndarray::Array2::ones((3, 2)),
        )
        .unwrap();
        assert!(matches!(
            depth_bound(&op, &wide, &Response::Triangle, 1.0),
            Err(Error::ShapeMismatch { .. })
        ));
        // Noise-free: a zero bound.
        let zero = depth_bound(&op, &truth, &Response::Triangle, 0.0).unwrap();
        assert_eq!(zero[[0, 0, 0]], 0.0);
    }

    /// A scene of `lit` pixels of a 4×4 grid at depths between bins.
    fn scattered(lit: usize) -> Returns {
        let mut depth = Array3::from_elem((1, 4, 4), f64::NAN);
        let mut amplitude = Array3::zeros((1, 4, 4));
        for p in 0..lit {
            let q = (p * 7) % 16;
            depth[[0, q / 4, q % 4]] = 2.3 + 0.61 * p as f64;
            amplitude[[0, q / 4, q % 4]] = 1.0 + 0.1 * p as f64;
        }
        Returns::new(depth, amplitude).unwrap()
    }

    #[test]
    fn the_joint_bound_is_the_pixels_bound_for_one_return_and_above_it_when_pixels_share() {
        let g = Geometry::new(4, 4, 10).unwrap();
        let response = Response::gaussian(0.8).unwrap();
        for ternary in [false, true] {
            let op = operator(g, 40, ternary);
            let one = scattered(1);
            let (alone, joint) = (
                depth_bound(&op, &one, &response, 0.1).unwrap(),
                joint_depth_bound(&op, &one, &response, 0.1).unwrap(),
            );
            for (a, j) in alone.iter().zip(&joint) {
                assert!(a.is_nan() == j.is_nan());
                assert!(a.is_nan() || (a - j).abs() <= 1e-9 * a, "{a} vs {j}");
            }
            // Eight returns over 49 samples: the joint bound is never below the pixels' own,
            // and well above it on average.
            let eight = scattered(8);
            let alone = depth_bound(&op, &eight, &response, 0.1).unwrap();
            let joint = joint_depth_bound(&op, &eight, &response, 0.1).unwrap();
            let pairs: Vec<(f64, f64)> = alone
                .iter()
                .zip(&joint)
                .filter(|(a, _)| !a.is_nan())
                .map(|(a, j)| (*a, *j))
                .collect();
            assert_eq!(pairs.len(), 8);
            assert!(
                pairs.iter().all(|(a, j)| *j >= a * (1.0 - 1e-9)),
                "{pairs:?}"
            );
            let mean = pairs.iter().map(|(a, j)| j / a).sum::<f64>() / 8.0;
            assert!(mean > 1.1, "joint/alone {mean} ({pairs:?})");
        }
    }

    #[test]
    fn the_joint_fit_of_every_return_spreads_as_the_joint_bound_says() {
        // Eight returns, 16 unknowns, 39 samples: Gauss–Newton on all (a, d) at once from the
        // truth over many noise draws. Its RMS depth error is the joint bound's within the
        // Monte Carlo error, and clearly above the bound with the other pixels known.
        let g = Geometry::new(4, 4, 10).unwrap();
        let op = operator(g, 30, false);
        let response = Response::gaussian(0.8).unwrap();
        let truth = scattered(8);
        let clean = measure(&op, &truth, &response);
        let sigma = 0.02;
        let rms = |b: &Array3<f64>| {
            let v: Vec<f64> = b.iter().filter(|v| !v.is_nan()).copied().collect();
            (v.iter().map(|x| x * x).sum::<f64>() / v.len() as f64).sqrt()
        };
        let joint = rms(&joint_depth_bound(&op, &truth, &response, sigma).unwrap());
        let alone = rms(&depth_bound(&op, &truth, &response, sigma).unwrap());
        assert!(joint > 1.2 * alone, "joint {joint} vs alone {alone}");
        let start: Vec<super::super::subbin::Ret> = truth
            .depth
            .indexed_iter()
            .filter(|(_, d)| !d.is_nan())
            .map(|((_, i, j), &d)| super::super::subbin::Ret {
                pixel: i * 4 + j,
                a: truth.amplitude[[0, i, j]],
                d,
            })
            .collect();
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(12);
        let noise = Normal::new(0.0, sigma).unwrap();
        let draws = 300;
        let mut squares = 0.0;
        for _ in 0..draws {
            let y: Vec<f64> = clean.iter().map(|v| v + noise.sample(&mut rng)).collect();
            let mut applies = crate::operator::Applies::default();
            let (fit, _) =
                super::super::subbin::refine(&op, &y, start.clone(), &response, 30, &mut applies)
                    .unwrap();
            assert_eq!(fit.len(), 8);
            for (f, t) in fit.iter().zip(&start) {
                assert_eq!(f.pixel, t.pixel);
                squares += (f.d - t.d).powi(2);
            }
        }
        let rmse = (squares / (8 * draws) as f64).sqrt();
        assert!(
            (rmse / joint - 1.0).abs() < 0.12,
            "RMSE {rmse} vs joint bound {joint} (alone {alone})"
        );
    }

    #[test]
    fn the_joint_bound_refuses_what_is_beyond_its_work_limit() {
        assert!(joint_bound_fits(2000, 2000));
        assert!(!joint_bound_fits(100_000, 1000));
        let (op, truth) = two_returns();
        assert!(matches!(
            joint_depth_bound(&op, &truth, &Response::Delta, 1.0),
            Err(Error::InvalidParameter { name: "kernel", .. })
        ));
        let none = Returns::single(
            ndarray::Array2::from_elem((2, 2), f64::NAN),
            ndarray::Array2::zeros((2, 2)),
        )
        .unwrap();
        assert!(joint_depth_bound(&op, &none, &Response::Triangle, 1.0)
            .unwrap()
            .iter()
            .all(|v| v.is_nan()));
    }
}
