//! Checking operators: the dot test, and a public catalogue of one instance of every operator
//! and combinator with the sweep of dot tests over it that `rdlidar selfcheck` prints.

use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;
use rand_distr::{Distribution, StandardNormal};

use crate::error::{Error, Result};
use crate::linalg::{dot, norm2, norm2_sq};
use crate::real::Real;

use super::LinearOperator;

/// ChaCha stream of the dot test's vectors (the bytes of "dot").
pub(crate) const DOT_STREAM: u64 = 0x00646f74;
/// ChaCha stream of the norm estimate's start vector (the bytes of "norm").
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
        // Over split unknowns, x is drawn whole (the vector one process would draw) and each
        // part takes its own entries; inner products over the unknowns combine the parts.
        let space = op.space();
        let (total, first) = if space.parts() > 1 {
            (
                crate::space::count(space, op.ncols()),
                space.offset(op.ncols()),
            )
        } else {
            (op.ncols(), 0)
        };
        let mut x: Vec<T> = gaussian_vector(total, &mut rng);
        x.truncate(first + op.ncols());
        x.drain(..first);
        let y: Vec<T> = gaussian_vector(op.nrows(), &mut rng);
        let mut ax = vec![T::zero(); op.nrows()];
        let mut aty = vec![T::zero(); op.ncols()];
        let mut scratch = vec![T::zero(); op.scratch_len()];
        op.apply_with_scratch(&x, &mut ax, &mut scratch);
        op.apply_adjoint_with_scratch(&y, &mut aty, &mut scratch);
        let lhs = dot(&ax, &y);
        let rhs = crate::space::dot(space, &x, &aty);
        let [xx, aa] = crate::space::sums(space, [norm2_sq(&x), norm2_sq(&aty)]);
        let scale = (norm2(&ax) * norm2(&y)).max(xx.sqrt() * aa.sqrt());
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

/// One row of [`dot_test_sweep`]: an operator of the [`catalogue`] and its dot tests in both
/// precisions.
#[derive(Debug, Clone, PartialEq)]
pub struct SweepRow {
    /// The operator's name in the catalogue.
    pub name: &'static str,
    /// The dot test in `f32`.
    pub f32: DotTestReport,
    /// The dot test in `f64`.
    pub f64: DotTestReport,
}

impl SweepRow {
    /// Whether both dot tests passed.
    pub fn passed(&self) -> bool {
        self.f32.passed() && self.f64.passed()
    }
}

/// One instance of every operator and combinator of this module, named, with entries drawn from
/// `seed`: the basic operators, the three convolution modes by both methods, the three matrix
/// types, and every combinator over a dense matrix.
///
/// # Errors
/// None in practice: the sizes are fixed and valid; an error here is a bug of a constructor.
pub fn catalogue<T: Real>(seed: u64) -> Result<Vec<(&'static str, super::BoxedOperator<T>)>> {
    use super::{
        BlockDiag, ConvMethod, ConvMode, Convolve1D, DenseMatrix, Diagonal, Gradient2D, HStack,
        Identity, NalgebraMatrix, OperatorExt, Restriction, SparseMatrix, VStack, Zero,
    };
    let mut rng = check_rng(seed, DOT_STREAM);
    let mut values = |len: usize| gaussian_vector::<T>(len, &mut rng);
    let (m, n) = (23, 17);
    let entries = values(m * n);
    let dense = || -> Result<DenseMatrix<T>> {
        let a = ndarray::Array2::from_shape_vec((m, n), entries.clone())
            .map_err(|e| Error::param("catalogue", e.to_string()))?;
        DenseMatrix::new(a)
    };
    let mut sp = sprs::TriMat::new((m, n));
    for (k, v) in values(m * n)
        .into_iter()
        .enumerate()
        .filter(|(k, _)| k % 4 == 0)
    {
        sp.add_triplet(k / n, k % n, v);
    }
    let pulse: Vec<T> = values(300)
        .into_iter()
        .map(|v| if v > T::zero() { T::one() } else { T::zero() })
        .collect();
    let taps = values(9);
    let conv = |len: usize, taps: &[T], mode: ConvMode, method: ConvMethod| {
        Convolve1D::new(7, len, taps.to_vec(), mode, method)
    };
    let (direct, fft) = (ConvMethod::Direct, ConvMethod::Fft);
    Ok(vec![
        ("Identity", Identity::<T>::new(n).boxed()),
        ("Zero", Zero::<T>::new(m, n).boxed()),
        ("Diagonal", Diagonal::new(values(n))?.boxed()),
        (
            "Restriction (repeated indices)",
            Restriction::<T>::new(n, vec![3, 1, 3, 16, 0, 3])?.boxed(),
        ),
        ("Gradient2D 12x9", Gradient2D::<T>::new(12, 9)?.boxed()),
        (
            "Convolve1D direct, full",
            conv(40, &taps, ConvMode::Full, direct)?.boxed(),
        ),
        (
            "Convolve1D direct, same",
            conv(40, &taps, ConvMode::Same, direct)?.boxed(),
        ),
        (
            "Convolve1D direct, valid",
            conv(40, &taps, ConvMode::Valid, direct)?.boxed(),
        ),
        (
            "Convolve1D FFT, full (0/1 pulse 300)",
            conv(40, &pulse, ConvMode::Full, fft)?.boxed(),
        ),
        (
            "Convolve1D FFT, same",
            conv(400, &pulse, ConvMode::Same, fft)?.boxed(),
        ),
        (
            "Convolve1D FFT, valid",
            conv(400, &pulse, ConvMode::Valid, fft)?.boxed(),
        ),
        ("DenseMatrix", dense()?.boxed()),
        (
            "NalgebraMatrix",
            NalgebraMatrix::new(nalgebra::DMatrix::from_vec(m, n, values(m * n)))?.boxed(),
        ),
        ("SparseMatrix", SparseMatrix::new(sp.to_csr())?.boxed()),
        (
            "Compose",
            dense()?.compose(Diagonal::new(values(n))?)?.boxed(),
        ),
        ("Adjoint", dense()?.adjoint().boxed()),
        ("Scaled", dense()?.scaled(T::of_f64(-2.5))?.boxed()),
        ("Sum", dense()?.plus(Zero::new(m, n))?.boxed()),
        ("Difference", dense()?.minus(dense()?)?.boxed()),
        ("Normal", dense()?.normal().boxed()),
        (
            "VStack",
            VStack::new(vec![dense()?.boxed(), Identity::new(n).boxed()])?.boxed(),
        ),
        (
            "HStack",
            HStack::new(vec![dense()?.boxed(), Identity::new(m).boxed()])?.boxed(),
        ),
        (
            "BlockDiag",
            BlockDiag::new(vec![dense()?.boxed(), Gradient2D::new(3, 4)?.boxed()])?.boxed(),
        ),
        ("Counted", dense()?.counted().boxed()),
    ])
}

/// The dot test of every operator of the [`catalogue`], in `f32` and `f64`, with test vectors
/// and operator entries drawn from `seed`.
///
/// # Errors
/// Those of [`catalogue`].
pub fn dot_test_sweep(seed: u64) -> Result<Vec<SweepRow>> {
    let ops32 = catalogue::<f32>(seed)?;
    let ops64 = catalogue::<f64>(seed)?;
    let test = DotTest::new().seed(seed);
    Ok(ops32
        .iter()
        .zip(&ops64)
        .map(|((name, a32), (_, a64))| SweepRow {
            name,
            f32: test.measure(a32),
            f64: test.measure(a64),
        })
        .collect())
}
