//! Each basic operator on its own: the dot test in f32 and f64 over random parameters, and the
//! behaviour its documentation promises.

use std::sync::Arc;

use ndarray::{Array2, ShapeBuilder};
use proptest::prelude::*;
use rdlidar::operator::{
    dot_test, BlockDiag, BoxedOperator, ConvMethod, ConvMode, Convolve1D, DenseMatrix, Diagonal,
    Gradient2D, HStack, Identity, LinearOperator, NalgebraMatrix, OperatorExt, Restriction,
    SparseMatrix, VStack, Zero,
};
use rdlidar::Real;

use crate::common::random_vec;

fn cast<T: Real>(v: &[f64]) -> Vec<T> {
    v.iter().map(|&x| T::of_f64(x)).collect()
}

/// Dot test in both precisions; returns the (f32, f64) gaps.
fn both<F>(make: F, seed: u64) -> (f64, f64)
where
    F: Fn(bool) -> (BoxedOperator<f32>, BoxedOperator<f64>),
{
    let (a32, a64) = make(true);
    let g32 = dot_test(&a32, seed)
        .unwrap_or_else(|e| panic!("f32 {}: {e}", a32.describe()))
        .gap;
    let g64 = dot_test(&a64, seed)
        .unwrap_or_else(|e| panic!("f64 {}: {e}", a64.describe()))
        .gap;
    (g32, g64)
}

proptest! {
    #![proptest_config(crate::common::config(64))]

    #[test]
    fn identity_zero_diagonal(n in 1..=64usize, m in 1..=64usize, seed in any::<u64>()) {
        let d = random_vec(n, seed);
        both(|_| (Identity::<f32>::new(n).boxed(), Identity::<f64>::new(n).boxed()), seed);
        both(|_| (Zero::<f32>::new(m, n).boxed(), Zero::<f64>::new(m, n).boxed()), seed);
        both(|_| (Diagonal::new(cast::<f32>(&d)).unwrap().boxed(), Diagonal::new(d.clone()).unwrap().boxed()), seed);
    }

    #[test]
    fn restriction(n in 1..=64usize, idx in prop::collection::vec(0..64usize, 0..=80), seed in any::<u64>()) {
        let idx: Vec<usize> = idx.into_iter().map(|i| i % n).collect();
        both(|_| (Restriction::<f32>::new(n, idx.clone()).unwrap().boxed(),
                  Restriction::<f64>::new(n, idx.clone()).unwrap().boxed()), seed);
    }

    #[test]
    fn gradient(m in 1..=40usize, n in 1..=40usize, seed in any::<u64>()) {
        both(|_| (Gradient2D::<f32>::new(m, n).unwrap().boxed(), Gradient2D::<f64>::new(m, n).unwrap().boxed()), seed);
    }

    #[test]
    fn convolution(batch in 1..=5usize, len in 1..=200usize, l in 1..=120usize, fft in any::<bool>(), seed in any::<u64>()) {
        let h = random_vec(l, seed);
        let method = if fft { ConvMethod::Fft } else { ConvMethod::Direct };
        for mode in [ConvMode::Full, ConvMode::Same, ConvMode::Valid] {
            if mode == ConvMode::Valid && len < l {
                continue;
            }
            both(|_| (Convolve1D::new(batch, len, cast::<f32>(&h), mode, method).unwrap().boxed(),
                      Convolve1D::new(batch, len, h.clone(), mode, method).unwrap().boxed()), seed);
        }
    }

    #[test]
    fn matrices(m in 1..=40usize, n in 1..=40usize, seed in any::<u64>()) {
        let v = random_vec(m * n, seed);
        both(|_| (DenseMatrix::new(Array2::from_shape_vec((m, n), cast::<f32>(&v)).unwrap()).unwrap().boxed(),
                  DenseMatrix::new(Array2::from_shape_vec((m, n), v.clone()).unwrap()).unwrap().boxed()), seed);
        both(|_| (NalgebraMatrix::new(nalgebra::DMatrix::from_vec(m, n, cast::<f32>(&v))).unwrap().boxed(),
                  NalgebraMatrix::new(nalgebra::DMatrix::from_vec(m, n, v.clone())).unwrap().boxed()), seed);
        let mut t32 = sprs::TriMat::new((m, n));
        let mut t64 = sprs::TriMat::new((m, n));
        for (k, &x) in v.iter().enumerate().filter(|(k, _)| k % 3 == 0) {
            t32.add_triplet(k / n, k % n, x as f32);
            t64.add_triplet(k / n, k % n, x);
        }
        let (c32, c64) = (t32.to_csc(), t64.to_csc());
        both(|_| (SparseMatrix::new(c32.clone()).unwrap().boxed(), SparseMatrix::new(c64.clone()).unwrap().boxed()), seed);
    }
}

#[test]
fn restriction_adjoint_adds_repeated_indices() {
    let r = Restriction::<f64>::new(4, vec![2, 0, 2, 2]).unwrap();
    let mut y = vec![0.0; 4];
    r.apply(&[10.0, 20.0, 30.0, 40.0], &mut y);
    assert_eq!(y, vec![30.0, 10.0, 30.0, 30.0]);
    let mut x = vec![f64::NAN; 4];
    r.apply_adjoint(&[1.0, 2.0, 3.0, 4.0], &mut x);
    assert_eq!(x, vec![2.0, 0.0, 8.0, 0.0]);
}

#[test]
fn gradient_of_a_ramp_and_adjoint_is_negative_divergence() {
    let (m, n) = (4, 6);
    let g = Gradient2D::<f64>::new(m, n).unwrap();
    // x[i, j] = 2i + 3j: vertical differences 2 and horizontal 3, except on the boundary.
    let x: Vec<f64> = (0..m * n)
        .map(|k| (2 * (k / n) + 3 * (k % n)) as f64)
        .collect();
    let mut y = vec![0.0; 2 * m * n];
    g.apply(&x, &mut y);
    for i in 0..m {
        for j in 0..n {
            assert_eq!(y[i * n + j], if i + 1 < m { 2.0 } else { 0.0 });
            assert_eq!(y[m * n + i * n + j], if j + 1 < n { 3.0 } else { 0.0 });
        }
    }
    // −div p for the field p = (p₀, p₁), with the backward-difference divergence of Chambolle (2004).
    let p = random_vec(2 * m * n, 5);
    let mut adj = vec![0.0; m * n];
    g.apply_adjoint(&p, &mut adj);
    for i in 0..m {
        for j in 0..n {
            let k = i * n + j;
            let dv = if i == 0 {
                p[k]
            } else if i + 1 == m {
                -p[k - n]
            } else {
                p[k] - p[k - n]
            };
            let q = &p[m * n..];
            let dh = if j == 0 {
                q[k]
            } else if j + 1 == n {
                -q[k - 1]
            } else {
                q[k] - q[k - 1]
            };
            let div = if m == 1 { 0.0 } else { dv } + if n == 1 { 0.0 } else { dh };
            assert!(
                (adj[k] + div).abs() < 1e-12,
                "at ({i}, {j}): {} vs {}",
                adj[k],
                -div
            );
        }
    }
}

#[test]
fn matrix_wrappers_agree_with_each_other_and_accept_any_layout() {
    let (m, n) = (7, 5);
    let v = random_vec(m * n, 11);
    let a = Array2::from_shape_vec((m, n), v.clone()).unwrap();
    // The same matrix stored column-major.
    let mut af = Array2::<f64>::zeros((m, n).f());
    af.assign(&a);
    let ops: Vec<BoxedOperator<f64>> = vec![
        DenseMatrix::new(a.clone()).unwrap().boxed(),
        DenseMatrix::new(af).unwrap().boxed(),
        DenseMatrix::new(a.t().to_owned())
            .unwrap()
            .adjoint()
            .boxed(),
        NalgebraMatrix::new(nalgebra::DMatrix::from_row_slice(m, n, &v))
            .unwrap()
            .boxed(),
        SparseMatrix::new(sprs::CsMat::csr_from_dense(a.view(), 0.0))
            .unwrap()
            .boxed(),
    ];
    let x = random_vec(n, 1);
    let y = random_vec(m, 2);
    let want = a.dot(&ndarray::Array1::from(x.clone()));
    let want_adj = a.t().dot(&ndarray::Array1::from(y.clone()));
    for op in &ops {
        let mut out = vec![0.0; m];
        op.apply(&x, &mut out);
        let mut out_adj = vec![0.0; n];
        op.apply_adjoint(&y, &mut out_adj);
        for (g, w) in out.iter().zip(&want) {
            assert!((g - w).abs() < 1e-12, "{}", op.describe());
        }
        for (g, w) in out_adj.iter().zip(&want_adj) {
            assert!((g - w).abs() < 1e-12, "{}", op.describe());
        }
    }
}

#[test]
fn f32_matrix_products_accumulate_in_f64() {
    // 10⁵ values near 1 that f32 cannot represent exactly: an f32 running sum would lose their low
    // bits at every step and drift by many ulps; the f64 accumulator rounds once at the end.
    let n = 100_000;
    let row: Vec<f32> = (0..n).map(|k| 1.0 + (k % 7) as f32 * 1e-3).collect();
    let exact: f64 = row.iter().map(|&v| v as f64).sum();
    let a = DenseMatrix::new(Array2::from_shape_vec((1, n), row).unwrap()).unwrap();
    let mut y = [0.0f32];
    a.apply(&vec![1.0f32; n], &mut y);
    assert!(
        ((y[0] as f64) - exact).abs() <= exact * f32::EPSILON as f64,
        "{} vs {exact}",
        y[0]
    );
}

#[test]
fn references_boxes_and_arcs_are_operators() {
    let d = Diagonal::new(vec![2.0f64, 3.0]).unwrap();
    let boxed: Box<dyn LinearOperator<f64>> = Box::new(d.clone());
    let arc: Arc<dyn LinearOperator<f64>> = Arc::new(d.clone());
    let by_ref: &dyn LinearOperator<f64> = &d;
    let stack = VStack::new(vec![boxed, Box::new(arc.clone()), Box::new(d.clone())]).unwrap();
    let mut y = vec![0.0; 6];
    stack.apply(&[1.0, 1.0], &mut y);
    assert_eq!(y, vec![2.0, 3.0, 2.0, 3.0, 2.0, 3.0]);
    let mut z = vec![0.0; 2];
    by_ref.apply(&[1.0, -1.0], &mut z);
    assert_eq!(z, vec![2.0, -3.0]);
    // Expressions can be shared between threads.
    let shared = Arc::new(HStack::new(vec![arc.clone(), arc]).unwrap());
    let handles: Vec<_> = (0..2)
        .map(|t| {
            let s = shared.clone();
            std::thread::spawn(move || {
                let mut y = vec![0.0; 2];
                s.apply(&[t as f64, 1.0, 1.0, 0.0], &mut y);
                y
            })
        })
        .collect();
    let out: Vec<Vec<f64>> = handles.into_iter().map(|h| h.join().unwrap()).collect();
    assert_eq!(out, vec![vec![2.0, 3.0], vec![4.0, 3.0]]);
}

#[test]
fn block_diag_applies_blocks_independently() {
    let a = Diagonal::new(vec![2.0f64]).unwrap().boxed();
    let b = Zero::<f64>::new(2, 3).boxed();
    let c = Identity::<f64>::new(2).boxed();
    let bd = BlockDiag::new(vec![a, b, c]).unwrap();
    assert_eq!((bd.nrows(), bd.ncols()), (5, 6));
    let mut y = vec![f64::NAN; 5];
    bd.apply(&[1.0, 5.0, 5.0, 5.0, 7.0, 8.0], &mut y);
    assert_eq!(y, vec![2.0, 0.0, 0.0, 7.0, 8.0]);
}

#[test]
fn descriptions_name_the_expression() {
    let d = Diagonal::new(vec![1.0f64; 5]).unwrap();
    let e = (&d).compose(Identity::new(5)).unwrap().adjoint();
    assert_eq!(e.describe(), "Adjoint(Compose(Diagonal(5), Identity(5)))");
    let s = (&d).minus(&d).unwrap().scaled(2.0).unwrap();
    assert_eq!(
        s.describe(),
        "Scaled(2, Difference(Diagonal(5), Diagonal(5)))"
    );
}

/// The columns `cols` of `a` (repeats allowed), as a matrix.
fn columns_of(a: &Array2<f64>, cols: &[usize]) -> Array2<f64> {
    Array2::from_shape_fn((a.nrows(), cols.len()), |(i, j)| a[[i, cols[j]]])
}

proptest! {
    #![proptest_config(crate::common::config(64))]

    /// The default restriction of any expression is the matrix's selected columns, passes the dot
    /// test, and restricting it again selects the composed columns.
    #[test]
    fn restricted_columns_of_any_expression(
        spec in crate::common::any_expr(2),
        picks in prop::collection::vec(any::<prop::sample::Index>(), 1..=40),
        again in prop::collection::vec(any::<prop::sample::Index>(), 1..=20),
        seed in any::<u64>(),
    ) {
        let op = crate::common::build::<f64>(&spec);
        let full = crate::common::reference(&spec);
        let cols: Vec<usize> = picks.iter().map(|i| i.index(op.ncols())).collect();
        let r = op.restrict_columns(cols.clone()).unwrap();
        prop_assert_eq!((r.nrows(), r.ncols()), (op.nrows(), cols.len()));
        let expected = columns_of(&full, &cols);
        prop_assert!(crate::common::rel_max_diff(&r.to_dense(), &expected) < 1e-12);
        prop_assert!(dot_test(&r, seed).unwrap().gap < 1e-12);
        let sub: Vec<usize> = again.iter().map(|i| i.index(cols.len())).collect();
        let rr = r.restrict_columns(sub.clone()).unwrap();
        let composed: Vec<usize> = sub.iter().map(|&c| cols[c]).collect();
        prop_assert!(crate::common::rel_max_diff(&rr.to_dense(), &columns_of(&full, &composed)) < 1e-12);
        prop_assert!(r.restrict_columns(vec![cols.len()]).is_err());
        prop_assert!(op.restrict_columns(vec![op.ncols()]).is_err());
    }
}

#[test]
fn counted_operators_count_the_applications_of_their_restrictions() {
    use rdlidar::operator::Counted;
    let a = DenseMatrix::new(Array2::from_shape_fn((3, 5), |(i, j)| (i * 5 + j) as f64)).unwrap();
    let counted = Counted::new(&a);
    let r = counted.restrict_columns(vec![4, 0, 4]).unwrap();
    let mut y = vec![0.0; 3];
    r.apply(&[1.0, 2.0, 3.0], &mut y);
    // Columns 4 (twice, 1 + 3) and 0 (twice): 4·a₄ + 2·a₀.
    assert_eq!(y, vec![16.0, 46.0, 76.0]);
    let mut x = vec![0.0; 3];
    r.apply_adjoint(&[1.0, 0.0, 0.0], &mut x);
    assert_eq!(x, vec![4.0, 0.0, 4.0]);
    let rr = r.restrict_columns(vec![1]).unwrap();
    rr.apply(&[1.0], &mut y);
    assert_eq!(y, vec![0.0, 5.0, 10.0]);
    // Applications of restrictions are support applications, whichever their direction.
    let counts = (
        counted.forward_count(),
        counted.adjoint_count(),
        counted.support_count(),
    );
    assert_eq!(counts, (0, 0, 3));
    counted.apply(&[1.0, 0.0, 0.0, 0.0, 0.0], &mut y);
    counted.apply_adjoint(&[1.0, 0.0, 0.0], &mut [0.0; 5]);
    assert_eq!(counted.forward_count() + counted.adjoint_count(), 2);
    assert!(r.describe().contains("Counted"));
}
