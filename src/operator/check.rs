//! The dot test and the operator-norm estimate.

use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;
use rand_distr::{Distribution, StandardNormal};

use crate::error::{Error, Result};
use crate::linalg::{dot, norm2};
use crate::real::Real;

use super::LinearOperator;

/// ChaCha stream of the dot test's vectors (the bytes of "dot").
pub(crate) const DOT_STREAM: u64 = 0x00646f74;
/// ChaCha stream of the power iteration's start vector (the bytes of "norm").
pub(crate) const NORM_STREAM: u64 = 0x6e6f726d;

/// A ChaCha8 generator for `seed` on its own stream, so that the checks never reuse the random
/// numbers a caller drew from the same seed on the default stream (a start vector built from the
/// matrix's own stream can be orthogonal to its top singular vector).
pub(crate) fn check_rng(seed: u64, stream: u64) -> ChaCha8Rng {
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    rng.set_stream(stream);
    rng
}

/// A seeded vector of i.i.d. standard normal entries (ChaCha8, drawn in `f64`, rounded to `T`).
pub(crate) fn gaussian_vector<T: Real>(len: usize, rng: &mut ChaCha8Rng) -> Vec<T> {
    (0..len)
        .map(|_| {
            let v: f64 = StandardNormal.sample(rng);
            T::of_f64(v)
        })
        .collect()
}

/// What [`DotTest`] measured.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct DotTestReport {
    /// ⟨Ax, y⟩, accumulated in `f64`.
    pub lhs: f64,
    /// ⟨x, A*y⟩, accumulated in `f64`.
    pub rhs: f64,
    /// `|lhs − rhs| / max(‖Ax‖‖y‖, ‖x‖‖A*y‖)`: the gap relative to the size the two inner
    /// products could have (0 when both sides vanish, NaN if an output was not finite).
    pub gap: f64,
    /// The tolerance the gap was compared with.
    pub tolerance: f64,
}

impl DotTestReport {
    /// `true` when the gap is finite and within the tolerance.
    pub fn passed(&self) -> bool {
        self.gap.is_finite() && self.gap <= self.tolerance
    }
}

/// The adjoint check ⟨Ax, y⟩ = ⟨x, A*y⟩ on seeded random vectors (in the spirit of PyLops'
/// `dottest`).
///
/// x and y have i.i.d. standard normal entries drawn from a ChaCha8 generator seeded with
/// [`seed`](Self::seed) (on a stream of its own); inner products are accumulated in `f64` even for `f32` operators. The gap is
/// normalized by `max(‖Ax‖‖y‖, ‖x‖‖A*y‖)` rather than by the inner products themselves, which can be
/// small by cancellation. The default tolerance depends on the scalar type
/// ([`Real::DOT_TEST_TOL`]: 1e-4 for `f32`, 1e-10 for `f64`).
#[derive(Debug, Clone, Copy)]
pub struct DotTest {
    seed: u64,
    tolerance: Option<f64>,
}

impl Default for DotTest {
    fn default() -> Self {
        Self::new()
    }
}

impl DotTest {
    /// Seed 0, the default tolerance of the scalar type.
    pub fn new() -> Self {
        DotTest {
            seed: 0,
            tolerance: None,
        }
    }

    /// Sets the seed of the random vectors.
    pub fn seed(mut self, seed: u64) -> Self {
        self.seed = seed;
        self
    }

    /// Sets the tolerance on the relative gap.
    pub fn tolerance(mut self, tol: f64) -> Self {
        self.tolerance = Some(tol);
        self
    }

    /// Measures the gap without judging it.
    pub fn measure<T: Real, A: LinearOperator<T> + ?Sized>(&self, op: &A) -> DotTestReport {
        let mut rng = check_rng(self.seed, DOT_STREAM);
        let x: Vec<T> = gaussian_vector(op.ncols(), &mut rng);
        let y: Vec<T> = gaussian_vector(op.nrows(), &mut rng);
        let mut ax = vec![T::zero(); op.nrows()];
        let mut aty = vec![T::zero(); op.ncols()];
        let mut scratch = vec![T::zero(); op.scratch_len()];
        op.apply_with_scratch(&x, &mut ax, &mut scratch);
        op.apply_adjoint_with_scratch(&y, &mut aty, &mut scratch);
        let lhs = dot(&ax, &y);
        let rhs = dot(&x, &aty);
        let scale = (norm2(&ax) * norm2(&y)).max(norm2(&x) * norm2(&aty));
        let gap = if !(lhs.is_finite() && rhs.is_finite() && scale.is_finite()) {
            f64::NAN
        } else if scale == 0.0 {
            0.0
        } else {
            (lhs - rhs).abs() / scale
        };
        DotTestReport {
            lhs,
            rhs,
            gap,
            tolerance: self.tolerance.unwrap_or(T::DOT_TEST_TOL),
        }
    }

    /// Measures the gap and fails if it is above the tolerance.
    ///
    /// # Errors
    /// [`Error::DotTestFailed`] if the gap exceeds the tolerance or is not finite.
    pub fn run<T: Real, A: LinearOperator<T> + ?Sized>(&self, op: &A) -> Result<DotTestReport> {
        let r = self.measure(op);
        if r.passed() {
            Ok(r)
        } else {
            Err(Error::DotTestFailed {
                gap: r.gap,
                tolerance: r.tolerance,
            })
        }
    }
}

/// [`DotTest`] with the given seed and the default tolerance of `T`.
///
/// # Errors
/// [`Error::DotTestFailed`] if the adjoint identity does not hold within tolerance.
///
/// # Example
/// ```
/// use rdlidar::operator::{dot_test, Diagonal};
/// let d = Diagonal::new(vec![1.0f32, -2.0, 3.0]).unwrap();
/// let r = dot_test(&d, 42).unwrap();
/// assert!(r.gap < 1e-6);
/// ```
pub fn dot_test<T: Real, A: LinearOperator<T> + ?Sized>(
    op: &A,
    seed: u64,
) -> Result<DotTestReport> {
    DotTest::new().seed(seed).run(op)
}

/// Settings of [`operator_norm`].
#[derive(Debug, Clone, Copy)]
pub struct PowerIteration {
    /// Maximum number of iterations (each one forward and one adjoint application).
    pub max_iter: usize,
    /// Stop when the estimate changes by at most `tol` relative to itself.
    pub tol: f64,
    /// Seed of the random start vector.
    pub seed: u64,
}

impl Default for PowerIteration {
    fn default() -> Self {
        PowerIteration {
            max_iter: 200,
            tol: 1e-6,
            seed: 0,
        }
    }
}

/// Why [`operator_norm`] stopped.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum NormStop {
    /// The relative change of the estimate fell below the tolerance.
    Converged,
    /// The iteration limit was reached first.
    MaxIterations,
    /// A·v = 0 for the start vector or an iterate: the estimate is 0.
    ZeroOperator,
}

/// The result of [`operator_norm`].
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct NormEstimate {
    /// The estimate of ‖A‖₂ (largest singular value), a lower bound up to rounding.
    pub value: f64,
    /// Iterations performed.
    pub iterations: usize,
    /// Why it stopped.
    pub stop: NormStop,
}

/// Estimates ‖A‖₂ by power iteration on A*A.
///
/// Each iteration maps the unit vector v to A*A·v and reports σ = ‖A·v‖ (the square root of the
/// Rayleigh quotient of A*A), which never exceeds ‖A‖₂ and converges to it at the rate
/// (σ₂/σ₁)^{2k} when the top singular value is simple.
///
/// # Errors
/// [`Error::InvalidParameter`] if `max_iter` is zero or `tol` is not a positive finite number;
/// [`Error::NonFinite`] if the operator produced NaN or infinite values.
pub fn operator_norm<T: Real, A: LinearOperator<T> + ?Sized>(
    op: &A,
    params: &PowerIteration,
) -> Result<NormEstimate> {
    if params.max_iter == 0 {
        return Err(Error::param("max_iter", "must be at least 1"));
    }
    if !(params.tol.is_finite() && params.tol > 0.0) {
        return Err(Error::param(
            "tol",
            format!("must be a positive finite number, got {}", params.tol),
        ));
    }
    let (m, n) = (op.nrows(), op.ncols());
    let zero = NormEstimate {
        value: 0.0,
        iterations: 0,
        stop: NormStop::ZeroOperator,
    };
    if m == 0 || n == 0 {
        return Ok(zero);
    }
    let mut rng = check_rng(params.seed, NORM_STREAM);
    let mut v: Vec<T> = gaussian_vector(n, &mut rng);
    let nv = norm2(&v);
    v.iter_mut().for_each(|e| *e = T::of_f64(e.as_f64() / nv));
    let mut av = vec![T::zero(); m];
    let mut scratch = vec![T::zero(); op.scratch_len()];
    let mut prev = 0.0f64;
    for it in 1..=params.max_iter {
        op.apply_with_scratch(&v, &mut av, &mut scratch);
        let sigma = norm2(&av);
        if !sigma.is_finite() {
            return Err(Error::NonFinite {
                what: format!("operator output during power iteration {it}"),
            });
        }
        if sigma == 0.0 {
            return Ok(NormEstimate {
                iterations: it,
                ..zero
            });
        }
        op.apply_adjoint_with_scratch(&av, &mut v, &mut scratch);
        let nu = norm2(&v);
        if !nu.is_finite() || nu == 0.0 {
            return Err(Error::NonFinite {
                what: format!("adjoint output during power iteration {it}"),
            });
        }
        v.iter_mut().for_each(|e| *e = T::of_f64(e.as_f64() / nu));
        if it > 1 && (sigma - prev).abs() <= params.tol * sigma {
            return Ok(NormEstimate {
                value: sigma,
                iterations: it,
                stop: NormStop::Converged,
            });
        }
        prev = sigma;
    }
    Ok(NormEstimate {
        value: prev,
        iterations: params.max_iter,
        stop: NormStop::MaxIterations,
    })
}
