//! Random operator expressions for property tests, and an independent dense reference for each.
//!
//! `spec(m, n, depth)` generates the description of an expression of shape `m × n` (nesting depth up
//! to `depth`); `build::<T>` turns it into an operator through the crate's algebra, and
//! `reference` computes its matrix in `f64` from naive definitions of the parts, without using any
//! operator kernel.

use ndarray::{s, Array2};
use proptest::prelude::*;
use rdlidar::operator::{
    BlockDiag, BoxedOperator, ConvMethod, ConvMode, Convolve1D, DenseMatrix, Diagonal, Gradient2D,
    HStack, Identity, NalgebraMatrix, OperatorExt, Restriction, SparseMatrix, VStack, Zero,
};
use rdlidar::{LinearOperator, Real};

/// Largest dimension of a generated expression.
pub const MAX_DIM: usize = 32;

#[derive(Debug, Clone)]
pub enum Spec {
    Dense {
        m: usize,
        n: usize,
        vals: Vec<f64>,
    },
    Nalgebra {
        m: usize,
        n: usize,
        vals: Vec<f64>,
    },
    Sparse {
        m: usize,
        n: usize,
        trip: Vec<(usize, usize, f64)>,
    },
    Zero {
        m: usize,
        n: usize,
    },
    Identity {
        n: usize,
    },
    Diagonal {
        d: Vec<f64>,
    },
    Restriction {
        n: usize,
        idx: Vec<usize>,
    },
    /// Restriction (rows `idx` of the 2ab gradient outputs) ∘ Gradient2D(a, b).
    Gradient {
        a: usize,
        b: usize,
        idx: Vec<usize>,
    },
    /// Restriction (rows `idx`) ∘ Convolve1D(batch, len, kernel, mode, method).
    Conv {
        batch: usize,
        len: usize,
        kernel: Vec<f64>,
        mode: ConvMode,
        fft: bool,
        idx: Vec<usize>,
    },
    Compose(Box<Spec>, Box<Spec>),
    Adjoint(Box<Spec>),
    Scaled(f64, Box<Spec>),
    Sum(Box<Spec>, Box<Spec>),
    Diff(Box<Spec>, Box<Spec>),
    Normal(Box<Spec>),
    VStack(Vec<Spec>),
    HStack(Vec<Spec>),
    BlockDiag(Vec<Spec>),
    Counted(Box<Spec>),
}

fn values(len: usize) -> impl Strategy<Value = Vec<f64>> {
    prop::collection::vec(-2.0f64..2.0, len)
}

fn indices(count: usize, bound: usize) -> impl Strategy<Value = Vec<usize>> {
    prop::collection::vec(0..bound, count)
}

fn divisors(n: usize) -> Vec<usize> {
    (1..=n).filter(|d| n.is_multiple_of(*d)).collect()
}

fn conv_out(len: usize, l: usize, mode: ConvMode) -> Option<usize> {
    match mode {
        ConvMode::Full => Some(len + l - 1),
        ConvMode::Same => Some(len),
        ConvMode::Valid => (len >= l).then(|| len - l + 1),
    }
}

/// A leaf of shape `m × n`.
pub fn leaf(m: usize, n: usize) -> BoxedStrategy<Spec> {
    let mut options: Vec<BoxedStrategy<Spec>> = vec![
        values(m * n)
            .prop_map(move |vals| Spec::Dense { m, n, vals })
            .boxed(),
        values(m * n)
            .prop_map(move |vals| Spec::Nalgebra { m, n, vals })
            .boxed(),
        prop::collection::vec((0..m, 0..n, -2.0f64..2.0), 0..=2 * (m + n))
            .prop_map(move |trip| Spec::Sparse { m, n, trip })
            .boxed(),
        Just(Spec::Zero { m, n }).boxed(),
        indices(m, n)
            .prop_map(move |idx| Spec::Restriction { n, idx })
            .boxed(),
        prop::sample::select(divisors(n))
            .prop_flat_map(move |a| {
                let b = n / a;
                indices(m, 2 * n).prop_map(move |idx| Spec::Gradient { a, b, idx })
            })
            .boxed(),
        (
            prop::sample::select(divisors(n)),
            1usize..=9,
            prop::sample::select(vec![ConvMode::Full, ConvMode::Same, ConvMode::Valid]),
            any::<bool>(),
        )
            .prop_flat_map(move |(batch, l, mode, fft)| {
                let len = n / batch;
                let (l, mode) = match conv_out(len, l, mode) {
                    Some(_) => (l, mode),
                    None => (l, ConvMode::Full),
                };
                let out = batch * conv_out(len, l, mode).unwrap();
                (values(l), indices(m, out)).prop_map(move |(kernel, idx)| Spec::Conv {
                    batch,
                    len,
                    kernel,
                    mode,
                    fft,
                    idx,
                })
            })
            .boxed(),
    ];
    if m == n {
        options.push(Just(Spec::Identity { n }).boxed());
        options.push(values(n).prop_map(|d| Spec::Diagonal { d }).boxed());
    }
    let count = options.len();
    (0..count)
        .prop_flat_map(move |k| options[k].clone())
        .boxed()
}

/// An expression of shape `m × n` and nesting depth at most `depth`.
pub fn spec(m: usize, n: usize, depth: u32) -> BoxedStrategy<Spec> {
    if depth == 0 {
        return leaf(m, n);
    }
    let d = depth - 1;
    // Choose the kind first and build only the chosen branch, so that strategies are created
    // lazily (an eager tree of all branches would grow exponentially with the depth).
    (0u8..12)
        .prop_flat_map(move |kind| -> BoxedStrategy<Spec> {
            match kind {
                0 | 1 => leaf(m, n),
                2 => (1..=MAX_DIM)
                    .prop_flat_map(move |p| (spec(m, p, d), spec(p, n, d)))
                    .prop_map(|(a, b)| Spec::Compose(Box::new(a), Box::new(b)))
                    .boxed(),
                3 => spec(n, m, d)
                    .prop_map(|a| Spec::Adjoint(Box::new(a)))
                    .boxed(),
                4 => (-3.0f64..3.0, spec(m, n, d))
                    .prop_map(|(al, a)| Spec::Scaled(al, Box::new(a)))
                    .boxed(),
                5 => (spec(m, n, d), spec(m, n, d))
                    .prop_map(|(a, b)| Spec::Sum(Box::new(a), Box::new(b)))
                    .boxed(),
                6 => (spec(m, n, d), spec(m, n, d))
                    .prop_map(|(a, b)| Spec::Diff(Box::new(a), Box::new(b)))
                    .boxed(),
                7 if m == n => (1..=MAX_DIM)
                    .prop_flat_map(move |p| spec(p, n, d))
                    .prop_map(|a| Spec::Normal(Box::new(a)))
                    .boxed(),
                8 if m >= 2 => (1..m)
                    .prop_flat_map(move |m1| (spec(m1, n, d), spec(m - m1, n, d)))
                    .prop_map(|(a, b)| Spec::VStack(vec![a, b]))
                    .boxed(),
                9 if n >= 2 => (1..n)
                    .prop_flat_map(move |n1| (spec(m, n1, d), spec(m, n - n1, d)))
                    .prop_map(|(a, b)| Spec::HStack(vec![a, b]))
                    .boxed(),
                10 if m >= 2 && n >= 2 => (1..m, 1..n)
                    .prop_flat_map(move |(m1, n1)| (spec(m1, n1, d), spec(m - m1, n - n1, d)))
                    .prop_map(|(a, b)| Spec::BlockDiag(vec![a, b]))
                    .boxed(),
                11 => spec(m, n, d)
                    .prop_map(|a| Spec::Counted(Box::new(a)))
                    .boxed(),
                _ => spec(m, n, d)
                    .prop_map(|a| Spec::Adjoint(Box::new(Spec::Adjoint(Box::new(a)))))
                    .boxed(),
            }
        })
        .boxed()
}

/// A random shape and an expression of that shape, nested at most `depth` deep.
pub fn any_expr(depth: u32) -> BoxedStrategy<Spec> {
    (1..=MAX_DIM, 1..=MAX_DIM)
        .prop_flat_map(move |(m, n)| spec(m, n, depth))
        .boxed()
}

fn cast<T: Real>(v: &[f64]) -> Vec<T> {
    v.iter().map(|&x| T::of_f64(x)).collect()
}

fn conv_mode_method(fft: bool) -> ConvMethod {
    if fft {
        ConvMethod::Fft
    } else {
        ConvMethod::Direct
    }
}

/// The operator described by `spec`, built with the crate's algebra.
pub fn build<T: Real>(spec: &Spec) -> BoxedOperator<T> {
    match spec {
        Spec::Dense { m, n, vals } => {
            DenseMatrix::new(Array2::from_shape_vec((*m, *n), cast::<T>(vals)).unwrap())
                .unwrap()
                .boxed()
        }
        Spec::Nalgebra { m, n, vals } => {
            // vals are row-major; nalgebra's from_row_slice reads them in that order.
            NalgebraMatrix::new(nalgebra::DMatrix::from_row_slice(*m, *n, &cast::<T>(vals)))
                .unwrap()
                .boxed()
        }
        Spec::Sparse { m, n, trip } => {
            let mut t = sprs::TriMat::new((*m, *n));
            for &(i, j, v) in trip {
                t.add_triplet(i, j, T::of_f64(v));
            }
            SparseMatrix::new(t.to_csr()).unwrap().boxed()
        }
        Spec::Zero { m, n } => Zero::<T>::new(*m, *n).boxed(),
        Spec::Identity { n } => Identity::<T>::new(*n).boxed(),
        Spec::Diagonal { d } => Diagonal::new(cast::<T>(d)).unwrap().boxed(),
        Spec::Restriction { n, idx } => Restriction::<T>::new(*n, idx.clone()).unwrap().boxed(),
        Spec::Gradient { a, b, idx } => {
            let g = Gradient2D::<T>::new(*a, *b).unwrap();
            Restriction::<T>::new(2 * a * b, idx.clone())
                .unwrap()
                .compose(g)
                .unwrap()
                .boxed()
        }
        Spec::Conv {
            batch,
            len,
            kernel,
            mode,
            fft,
            idx,
        } => {
            let c = Convolve1D::new(
                *batch,
                *len,
                cast::<T>(kernel),
                *mode,
                conv_mode_method(*fft),
            )
            .unwrap();
            let r = Restriction::<T>::new(c.nrows(), idx.clone()).unwrap();
            r.compose(c).unwrap().boxed()
        }
        Spec::Compose(a, b) => build::<T>(a).compose(build::<T>(b)).unwrap().boxed(),
        Spec::Adjoint(a) => build::<T>(a).adjoint().boxed(),
        Spec::Scaled(al, a) => build::<T>(a).scaled(T::of_f64(*al)).unwrap().boxed(),
        Spec::Sum(a, b) => build::<T>(a).plus(build::<T>(b)).unwrap().boxed(),
        Spec::Diff(a, b) => build::<T>(a).minus(build::<T>(b)).unwrap().boxed(),
        Spec::Normal(a) => build::<T>(a).normal().boxed(),
        Spec::VStack(v) => VStack::new(v.iter().map(build::<T>).collect())
            .unwrap()
            .boxed(),
        Spec::HStack(v) => HStack::new(v.iter().map(build::<T>).collect())
            .unwrap()
            .boxed(),
        Spec::BlockDiag(v) => BlockDiag::new(v.iter().map(build::<T>).collect())
            .unwrap()
            .boxed(),
        Spec::Counted(a) => build::<T>(a).counted().boxed(),
    }
}

fn restriction_matrix(n: usize, idx: &[usize]) -> Array2<f64> {
    let mut r = Array2::zeros((idx.len(), n));
    for (i, &j) in idx.iter().enumerate() {
        r[[i, j]] = 1.0;
    }
    r
}

/// The matrix of the 2-D forward-difference gradient, from its definition.
pub fn gradient_matrix(a: usize, b: usize) -> Array2<f64> {
    let n = a * b;
    let mut g = Array2::zeros((2 * n, n));
    for i in 0..a {
        for j in 0..b {
            let k = i * b + j;
            if i + 1 < a {
                g[[k, k + b]] = 1.0;
                g[[k, k]] = -1.0;
            }
            if j + 1 < b {
                g[[n + k, k + 1]] = 1.0;
                g[[n + k, k]] = -1.0;
            }
        }
    }
    g
}

/// The matrix of a batched convolution, from `z[k] = Σⱼ x[j] h[k−j]` cropped by `mode`.
pub fn conv_matrix(batch: usize, len: usize, h: &[f64], mode: ConvMode) -> Array2<f64> {
    let l = h.len();
    let (off, out) = match mode {
        ConvMode::Full => (0, len + l - 1),
        ConvMode::Same => ((l - 1) / 2, len),
        ConvMode::Valid => (l - 1, len - l + 1),
    };
    let mut c = Array2::zeros((batch * out, batch * len));
    for r in 0..batch {
        for i in 0..out {
            for j in 0..len {
                let k = i + off;
                if k >= j && k - j < l {
                    c[[r * out + i, r * len + j]] = h[k - j];
                }
            }
        }
    }
    c
}

/// The matrix of `spec` in `f64`, from naive definitions of the parts.
pub fn reference(spec: &Spec) -> Array2<f64> {
    match spec {
        Spec::Dense { m, n, vals } | Spec::Nalgebra { m, n, vals } => {
            Array2::from_shape_vec((*m, *n), vals.clone()).unwrap()
        }
        Spec::Sparse { m, n, trip } => {
            let mut a = Array2::zeros((*m, *n));
            for &(i, j, v) in trip {
                a[[i, j]] += v;
            }
            a
        }
        Spec::Zero { m, n } => Array2::zeros((*m, *n)),
        Spec::Identity { n } => Array2::eye(*n),
        Spec::Diagonal { d } => Array2::from_diag(&ndarray::Array1::from(d.clone())),
        Spec::Restriction { n, idx } => restriction_matrix(*n, idx),
        Spec::Gradient { a, b, idx } => {
            restriction_matrix(2 * a * b, idx).dot(&gradient_matrix(*a, *b))
        }
        Spec::Conv {
            batch,
            len,
            kernel,
            mode,
            idx,
            ..
        } => {
            let c = conv_matrix(*batch, *len, kernel, *mode);
            restriction_matrix(c.nrows(), idx).dot(&c)
        }
        Spec::Compose(a, b) => reference(a).dot(&reference(b)),
        Spec::Adjoint(a) => reference(a).t().to_owned(),
        Spec::Scaled(al, a) => reference(a) * *al,
        Spec::Sum(a, b) => reference(a) + reference(b),
        Spec::Diff(a, b) => reference(a) - reference(b),
        Spec::Normal(a) => {
            let r = reference(a);
            r.t().dot(&r)
        }
        Spec::VStack(v) => {
            let parts: Vec<Array2<f64>> = v.iter().map(reference).collect();
            let views: Vec<_> = parts.iter().map(|p| p.view()).collect();
            ndarray::concatenate(ndarray::Axis(0), &views).unwrap()
        }
        Spec::HStack(v) => {
            let parts: Vec<Array2<f64>> = v.iter().map(reference).collect();
            let views: Vec<_> = parts.iter().map(|p| p.view()).collect();
            ndarray::concatenate(ndarray::Axis(1), &views).unwrap()
        }
        Spec::BlockDiag(v) => {
            let parts: Vec<Array2<f64>> = v.iter().map(reference).collect();
            let m: usize = parts.iter().map(|p| p.nrows()).sum();
            let n: usize = parts.iter().map(|p| p.ncols()).sum();
            let mut out = Array2::zeros((m, n));
            let (mut r, mut c) = (0, 0);
            for p in &parts {
                out.slice_mut(s![r..r + p.nrows(), c..c + p.ncols()])
                    .assign(p);
                r += p.nrows();
                c += p.ncols();
            }
            out
        }
        Spec::Counted(a) => reference(a),
    }
}

/// Seeded vector of uniform entries in [−1, 1).
pub fn random_vec(len: usize, seed: u64) -> Vec<f64> {
    use rand::{RngExt, SeedableRng};
    let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(seed);
    (0..len).map(|_| rng.random_range(-1.0..1.0)).collect()
}

/// Max |a − b| over max(1, max |b|).
pub fn rel_max_diff(a: &Array2<f64>, b: &Array2<f64>) -> f64 {
    assert_eq!(a.dim(), b.dim());
    let scale = b.iter().fold(1.0f64, |m, v| m.max(v.abs()));
    a.iter()
        .zip(b)
        .fold(0.0f64, |m, (x, y)| m.max((x - y).abs()))
        / scale
}

/// Proptest settings with a fixed generator seed, so that every run tests the same cases
/// (failures are reproducible; `PROPTEST_CASES` still scales the count). Failing cases are kept
/// beside each test file (`tests/NAME.proptest-regressions`) and replayed first.
pub fn config(cases: u32) -> ProptestConfig {
    ProptestConfig {
        cases,
        rng_seed: proptest::test_runner::RngSeed::Fixed(0x0072_646c_6964_6172),
        failure_persistence: Some(Box::new(
            proptest::test_runner::FileFailurePersistence::WithSource("proptest-regressions"),
        )),
        ..ProptestConfig::default()
    }
}
