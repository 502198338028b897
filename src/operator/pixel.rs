//! The per-pixel column capability: operators whose columns come in pixels of `column_len`
//! consecutive voxels (one depth column per lidar pixel), as the pixelwise solvers need them.

use crate::error::{Error, Result};
use crate::linalg::dot;
use crate::real::Real;

use super::LinearOperator;

/// An operator whose columns come in pixels of `column_len` consecutive voxels, as the
/// model-based solvers need it: restricted to a set of columns, correlated with a residual, and
/// with known column norms.
///
/// Any operator can be used through [`PixelColumns`]; the lidar operator implements it with a
/// support operator whose cost is proportional to the support and with the debiased correlation.
pub trait VoxelOperator<T: Real>: LinearOperator<T> {
    /// Number of consecutive columns that make one pixel (K_s).
    fn column_len(&self) -> usize;

    /// Columns per depth bin (default 1): a pixel's column c lies at depth c / `columns_per_bin`
    /// bins. The per-pixel solvers' surface rules (neighbours within one bin, windows of a few
    /// bins) count in bins through it, so that a dictionary of responses shifted by a fraction
    /// of a bin keeps the meaning of a bin.
    fn columns_per_bin(&self) -> usize {
        1
    }

    /// The correlation that proposes candidate depths: u = Aᵀr by default. An operator may use a
    /// better matched filter (the lidar operator correlates with the zero-mean pulse).
    fn correlate(&self, r: &[T], u: &mut [T]) {
        self.apply_adjoint(r, u)
    }

    /// For each voxel c of `voxels`, the correlations ([`correlate`](Self::correlate)) of the
    /// `column_len` columns of c's pixel with column c: the pixel's own contribution to its
    /// correlations, which lets a solver judge a pixel's depth with its current reflector added
    /// back. Returned row by row (`voxels.len() · column_len` values).
    fn self_correlations(&self, voxels: &[usize]) -> Vec<f64> {
        self_correlations_by_applies(self, voxels)
    }

    /// The Gram block AₚᵀAₚ of pixel `pixel`'s `column_len` columns, row-major, in f64 (the
    /// plain inner products, whatever [`correlate`](Self::correlate) uses). By default from
    /// `column_len` forward applications.
    fn pixel_gram(&self, pixel: usize) -> Vec<f64> {
        pixel_gram_by_applies(self, pixel)
    }

    /// Whether every pixel has the same Gram block, so that [`pixel_gram`](Self::pixel_gram)
    /// need only be asked for pixel 0 (default `false`).
    fn uniform_pixel_gram(&self) -> bool {
        false
    }

    /// ‖A e_c‖ for each of `columns`.
    fn column_norms(&self, columns: &[usize]) -> Vec<f64> {
        column_norms_by_applies(self, columns)
    }

    /// Column c as the span of rows it may touch: the first row and the values from there on
    /// (`op.apply(e_c)[start..start + values.len()]`, zero elsewhere). By default from one
    /// forward application, trimmed to its nonzero rows.
    fn column(&self, c: usize) -> (usize, Vec<f64>) {
        column_by_apply(self, c)
    }

    /// Whether [`self_correlations`](Self::self_correlations), [`pixel_gram`](Self::pixel_gram)
    /// and [`column_norms`](Self::column_norms) come from the operator's structure, each call
    /// costing about one application restricted to the columns asked for (`true`), or from
    /// applications of the whole operator, as the defaults do (`false`, the default). A counting
    /// wrapper ([`Counted`](super::Counted)) counts the first kind as one support application
    /// per call and the second kind application by application.
    fn structured_columns(&self) -> bool {
        false
    }
}

/// A reference to a per-pixel operator, or a box of one, is one (so that wrappers such as
/// [`Counted`](super::Counted) can hold a borrowed or boxed operator).
macro_rules! forward_voxel {
    ($($ty:ty),*) => {$(
        impl<T: Real, A: VoxelOperator<T> + ?Sized> VoxelOperator<T> for $ty {
            fn column_len(&self) -> usize {
                (**self).column_len()
            }
            fn columns_per_bin(&self) -> usize {
                (**self).columns_per_bin()
            }
            fn correlate(&self, r: &[T], u: &mut [T]) {
                (**self).correlate(r, u)
            }
            fn self_correlations(&self, voxels: &[usize]) -> Vec<f64> {
                (**self).self_correlations(voxels)
            }
            fn pixel_gram(&self, pixel: usize) -> Vec<f64> {
                (**self).pixel_gram(pixel)
            }
            fn uniform_pixel_gram(&self) -> bool {
                (**self).uniform_pixel_gram()
            }
            fn column_norms(&self, columns: &[usize]) -> Vec<f64> {
                (**self).column_norms(columns)
            }
            fn column(&self, c: usize) -> (usize, Vec<f64>) {
                (**self).column(c)
            }
            fn structured_columns(&self) -> bool {
                (**self).structured_columns()
            }
        }
    )*};
}
forward_voxel!(&A, Box<A>);

/// [`VoxelOperator::self_correlations`] from applications of `op`: one forward application and
/// one correlation per voxel.
pub(crate) fn self_correlations_by_applies<T: Real, A: VoxelOperator<T> + ?Sized>(
    op: &A,
    voxels: &[usize],
) -> Vec<f64> {
    let ks = op.column_len();
    let mut e = vec![T::zero(); op.ncols()];
    let mut a = vec![T::zero(); op.nrows()];
    let mut u = vec![T::zero(); op.ncols()];
    let mut out = Vec::with_capacity(voxels.len() * ks);
    for &c in voxels {
        e[c] = T::one();
        op.apply(&e, &mut a);
        e[c] = T::zero();
        op.correlate(&a, &mut u);
        let p0 = c / ks * ks;
        out.extend(u[p0..p0 + ks].iter().map(|v| v.as_f64()));
    }
    out
}

/// [`VoxelOperator::column`] from one forward application of `op`.
pub(crate) fn column_by_apply<T: Real, A: VoxelOperator<T> + ?Sized>(
    op: &A,
    c: usize,
) -> (usize, Vec<f64>) {
    let mut e = vec![T::zero(); op.ncols()];
    e[c] = T::one();
    let mut a = vec![T::zero(); op.nrows()];
    op.apply(&e, &mut a);
    let first = a.iter().position(|v| *v != T::zero()).unwrap_or(0);
    let last = a
        .iter()
        .rposition(|v| *v != T::zero())
        .map_or(first, |l| l + 1);
    (first, a[first..last].iter().map(|v| v.as_f64()).collect())
}

/// [`VoxelOperator::pixel_gram`] from `column_len` forward applications of `op`.
pub(crate) fn pixel_gram_by_applies<T: Real, A: VoxelOperator<T> + ?Sized>(
    op: &A,
    pixel: usize,
) -> Vec<f64> {
    let ks = op.column_len();
    let mut e = vec![T::zero(); op.ncols()];
    let cols: Vec<Vec<T>> = (0..ks)
        .map(|j| {
            let mut a = vec![T::zero(); op.nrows()];
            e[pixel * ks + j] = T::one();
            op.apply(&e, &mut a);
            e[pixel * ks + j] = T::zero();
            a
        })
        .collect();
    let mut g = vec![0.0; ks * ks];
    for i in 0..ks {
        for j in i..ks {
            let v = dot(&cols[i], &cols[j]);
            g[i * ks + j] = v;
            g[j * ks + i] = v;
        }
    }
    g
}

/// [`VoxelOperator::column_norms`] from one forward application of `op` per column.
pub(crate) fn column_norms_by_applies<T: Real, A: VoxelOperator<T> + ?Sized>(
    op: &A,
    columns: &[usize],
) -> Vec<f64> {
    let mut e = vec![T::zero(); op.ncols()];
    let mut a = vec![T::zero(); op.nrows()];
    columns
        .iter()
        .map(|&c| {
            e[c] = T::one();
            op.apply(&e, &mut a);
            e[c] = T::zero();
            dot(&a, &a).sqrt()
        })
        .collect()
}

/// Any operator seen as pixels of `column_len` columns: restriction through the operator algebra
/// and the plain adjoint as correlation.
#[derive(Debug, Clone, Copy)]
pub struct PixelColumns<A> {
    op: A,
    column_len: usize,
}

impl<A> PixelColumns<A> {
    /// `op`, whose columns are pixels of `column_len` voxels.
    ///
    /// # Errors
    /// [`Error::InvalidParameter`] if `column_len` is 0 or does not divide the number of columns.
    pub fn new<T: Real>(op: A, column_len: usize) -> Result<Self>
    where
        A: LinearOperator<T>,
    {
        if column_len == 0 || op.ncols() % column_len != 0 {
            return Err(Error::param(
                "column_len",
                format!(
                    "must be ≥ 1 and divide the {} columns, got {column_len}",
                    op.ncols()
                ),
            ));
        }
        Ok(PixelColumns { op, column_len })
    }
}

impl<T: Real, A: LinearOperator<T>> LinearOperator<T> for PixelColumns<A> {
    fn nrows(&self) -> usize {
        self.op.nrows()
    }
    fn ncols(&self) -> usize {
        self.op.ncols()
    }
    fn scratch_len(&self) -> usize {
        self.op.scratch_len()
    }
    fn forward_kernel(&self, x: &[T], y: &mut [T], scratch: &mut [T]) {
        self.op.forward_kernel(x, y, scratch)
    }
    fn adjoint_kernel(&self, y: &[T], x: &mut [T], scratch: &mut [T]) {
        self.op.adjoint_kernel(y, x, scratch)
    }
    fn restrict_columns(&self, columns: Vec<usize>) -> Result<Box<dyn LinearOperator<T> + '_>> {
        self.op.restrict_columns(columns)
    }
    fn describe(&self) -> String {
        format!("PixelColumns({}, {})", self.op.describe(), self.column_len)
    }
    fn space(&self) -> &dyn crate::space::Space {
        self.op.space()
    }
}

impl<T: Real, A: LinearOperator<T>> VoxelOperator<T> for PixelColumns<A> {
    fn column_len(&self) -> usize {
        self.column_len
    }
}

/// Checks that `ks` columns make a pixel of an operator with `n` columns and that the depth
/// windows, if any, give one valid window `lo..=hi` per pixel; returns the number of pixels.
pub fn check_pixels(
    solver: &'static str,
    n: usize,
    ks: usize,
    windows: Option<&[(usize, usize)]>,
) -> Result<usize> {
    if ks == 0 || !n.is_multiple_of(ks) {
        return Err(Error::param(
            "column_len",
            format!("must be ≥ 1 and divide the {n} columns, got {ks}"),
        ));
    }
    let pixels = n / ks;
    if let Some(w) = windows {
        if w.len() != pixels {
            return Err(Error::shape(
                format!("{solver}: depth windows vs pixels"),
                pixels,
                w.len(),
            ));
        }
        if let Some(p) = w.iter().position(|&(lo, hi)| lo > hi || hi >= ks) {
            return Err(Error::param(
                "windows",
                format!("pixel {p}: window {:?} is not within 0..{ks}", w[p]),
            ));
        }
    }
    Ok(pixels)
}
