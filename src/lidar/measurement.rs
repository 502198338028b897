//! What the lidar reconstructions need of a measurement operator, and the operator of G ADCs.
//!
//! [`LidarOperator`] is the interface of `recon`: a [`VoxelOperator`] over an M×N×K_s grid that
//! knows its pulse, applies sparse scenes cheaply and backprojects with the zero-mean pulse.
//! [`RdOperator`] (one ADC) implements it, and so does [`MultiAdcOperator`]: G ADCs, each
//! pixel modulated by G code sets, y = [A₁x; …; A_Gx] with G·K measurements.

use std::sync::{Arc, OnceLock};

use crate::error::{Error, Result};
use crate::operator::{Counted, LinearOperator, Part, VStack, VoxelOperator};
use crate::real::Real;
use crate::space::Space;

use super::codes::{packed_len, CodeAlphabet, Codes};
use super::geometry::{Geometry, Regime};
use super::pulse::single_pulse;
use super::rdop::RdOperator;

/// A lidar measurement operator over an M×N×K_s grid of voxels (pixel-major, depth fastest):
/// what reconstruction needs beyond a [`VoxelOperator`].
///
/// # Split unknowns
/// An operator whose unknowns are one part of a scene split across processes
/// ([`space`](LinearOperator::space)), such as a [`Part`] whose block is the operator of a
/// band of rows alone, holds whole consecutive rows of the image: its
/// [`geometry`](Self::geometry) is that of its rows (M_part × N × K_s), the parts' rows in part
/// order make the image, and it answers the column queries of [`VoxelOperator`] for its own
/// columns without applying the operator of the whole. The reconstructions then run on it
/// unchanged, and give every part its rows of the whole scene's reconstruction.
pub trait LidarOperator<T: Real>: VoxelOperator<T> {
    /// The scene grid (this part's rows when the unknowns are split).
    fn geometry(&self) -> Geometry;

    /// The transmitted pulse p (K_p samples).
    fn pulse(&self) -> &[T];

    /// How many code sets modulate every pixel (G ADCs sampling the same pulse): 1 for one
    /// ADC. Every column of the operator is the pulse modulated by that many code sets, so
    /// the backprojection's matched-filter gain is that many times the one-ADC gain.
    fn code_sets(&self) -> usize {
        1
    }

    /// y = A·x through the nonzero entries of x only (O(nnz·K_p)), for sparse iterates.
    ///
    /// # Panics
    /// On wrong buffer lengths.
    fn apply_sparse(&self, x: &[T], y: &mut [T]);

    /// The same operator with the zero-mean pulse p − mean(p): its adjoint is the debiased
    /// backprojection, without the floor the pulse's mean puts under every bin of a lit pixel
    /// (docs/math.md §4).
    fn zero_mean_operator(&self) -> Box<dyn LinearOperator<T> + '_>;

    /// Per pixel, whether it reaches an ADC (some code of it is nonzero); `None` when every
    /// pixel does. Pixels that reach none (blocked by a coded aperture) cannot be
    /// reconstructed: their depth is [`UNOBSERVED`](super::UNOBSERVED).
    fn observed_pixels(&self) -> Option<Vec<bool>> {
        None
    }

    /// The ±1 (or ternary) codes of every ADC over the whole scene, in the order of the ADCs'
    /// rows, for operators built from them ([`BlockOperator`](super::BlockOperator)); `None`
    /// (the default) for codes not held in memory (streamed) or pixels split across processes.
    fn whole_code_sets(&self) -> Option<Vec<&Arc<Codes>>> {
        None
    }

    /// The code sets of the whole scene, for an operator whose pixels are split across the
    /// parts of its [`space`](LinearOperator::space) ([`Part`]): every part's own codes
    /// gathered into every part, in the order of the pixels (a collective: every part calls it
    /// at once). `None` (the default) for an operator whose pixels are not split, or whose codes
    /// are not held in memory.
    ///
    /// # Errors
    /// [`Error::TooLarge`] when a process has no memory for the whole scene's codes and
    /// operator (checked before anything is gathered, the same answer in every process);
    /// [`Error::InvalidParameter`] for parts whose codes do not join into one grid.
    fn gathered_code_sets(&self) -> Option<Result<Vec<Arc<Codes>>>> {
        None
    }

    /// The weights w of an operator whose rows are weighted, W·A with W = diag(w)
    /// ([`RowWeighted`](super::RowWeighted)), one per row; `None` (the default) for unweighted
    /// rows. Operators built from [`whole_code_sets`](Self::whole_code_sets) apply them too.
    fn row_weights(&self) -> Option<&[T]> {
        None
    }

    /// The regime of the measurements against the unknowns (eq. 8–9, with every ADC's rows),
    /// those of every part when the unknowns are split ([`space`](LinearOperator::space)).
    fn regime(&self) -> Regime {
        let voxels = crate::space::count(self.space(), self.geometry().voxels());
        Regime::of(self.nrows(), voxels)
    }
}

impl<T: Real> LidarOperator<T> for RdOperator<T> {
    fn geometry(&self) -> Geometry {
        RdOperator::geometry(self)
    }
    fn pulse(&self) -> &[T] {
        RdOperator::pulse(self)
    }
    fn apply_sparse(&self, x: &[T], y: &mut [T]) {
        RdOperator::apply_sparse(self, x, y)
    }
    fn zero_mean_operator(&self) -> Box<dyn LinearOperator<T> + '_> {
        Box::new(self.zero_mean())
    }
    fn observed_pixels(&self) -> Option<Vec<bool>> {
        let observed = self.codes().observed_pixels();
        observed.iter().any(|&o| !o).then_some(observed)
    }
    fn whole_code_sets(&self) -> Option<Vec<&Arc<Codes>>> {
        Some(vec![self.codes()])
    }
}

/// A reference to a lidar operator, or a box of one, is one.
macro_rules! forward_lidar {
    ($($ty:ty),*) => {$(
        impl<T: Real, A: LidarOperator<T> + ?Sized> LidarOperator<T> for $ty {
            fn geometry(&self) -> Geometry {
                (**self).geometry()
            }
            fn pulse(&self) -> &[T] {
                (**self).pulse()
            }
            fn code_sets(&self) -> usize {
                (**self).code_sets()
            }
            fn apply_sparse(&self, x: &[T], y: &mut [T]) {
                (**self).apply_sparse(x, y)
            }
            fn zero_mean_operator(&self) -> Box<dyn LinearOperator<T> + '_> {
                (**self).zero_mean_operator()
            }
            fn observed_pixels(&self) -> Option<Vec<bool>> {
                (**self).observed_pixels()
            }
            fn whole_code_sets(&self) -> Option<Vec<&Arc<Codes>>> {
                (**self).whole_code_sets()
            }
            fn gathered_code_sets(&self) -> Option<Result<Vec<Arc<Codes>>>> {
                (**self).gathered_code_sets()
            }
            fn row_weights(&self) -> Option<&[T]> {
                (**self).row_weights()
            }
            fn regime(&self) -> Regime {
                (**self).regime()
            }
        }
    )*};
}
forward_lidar!(&A, Box<A>);

/// One process's rows of a lidar operator whose pixels are split across processes: the
/// geometry, pulse and column queries of its own rows' operator, the sparse forward and the
/// zero-mean operator summed over the parts, the regime of the whole.
impl<T: Real, A: LidarOperator<T>> LidarOperator<T> for Part<A> {
    fn geometry(&self) -> Geometry {
        self.inner().geometry()
    }
    fn pulse(&self) -> &[T] {
        self.inner().pulse()
    }
    fn code_sets(&self) -> usize {
        self.inner().code_sets()
    }
    fn apply_sparse(&self, x: &[T], y: &mut [T]) {
        self.inner().apply_sparse(x, y);
        crate::operator::sum_over(self.space(), y);
    }
    fn zero_mean_operator(&self) -> Box<dyn LinearOperator<T> + '_> {
        Box::new(Part::new(
            self.inner().zero_mean_operator(),
            Arc::clone(self.shared_space()),
        ))
    }
    fn observed_pixels(&self) -> Option<Vec<bool>> {
        self.inner().observed_pixels()
    }
    fn gathered_code_sets(&self) -> Option<Result<Vec<Arc<Codes>>>> {
        let sets = self.inner().whole_code_sets()?;
        let gathered = || -> Result<Vec<Arc<Codes>>> {
            // Every process will hold the whole scene's codes and operator: checked first.
            let band = self.geometry();
            let pixels = crate::space::count(self.space(), band.pixels());
            let whole = Geometry::new(pixels / band.n.max(1), band.n, band.ks)?;
            let alphabet = sets.first().map_or(CodeAlphabet::Binary, |c| c.alphabet());
            let bytes = RdOperator::<T>::estimated_memory_bytes(
                whole,
                self.pulse().len(),
                alphabet,
                rayon::current_num_threads(),
            )?;
            let fits = crate::limits::MemoryPlan::new()
                .add(
                    "the whole scene's codes and operator",
                    bytes as u128,
                    sets.len(),
                )
                .check(
                    &format!("gathering the codes of {whole} into every process"),
                    "more memory per process",
                );
            // Every process gathers, or none does.
            if !crate::space::all(self.space(), fits.is_ok()) {
                return Err(fits.err().unwrap_or_else(|| {
                    Error::param(
                        "operator",
                        "another process has no memory for the whole scene's codes",
                    )
                }));
            }
            sets.iter()
                .map(|c| gather_codes(self.space(), c).map(Arc::new))
                .collect()
        };
        Some(gathered())
    }
}

/// The codes of every part's pixels, in part order (a collective).
fn gather_codes(space: &dyn Space, codes: &Codes) -> Result<Codes> {
    let len = codes.len();
    match codes.alphabet() {
        CodeAlphabet::Binary => {
            let bytes = space.gather_bytes(&codes.to_packbits()?);
            Codes::from_packbits(&bytes, bytes.len() / packed_len(len), len)
        }
        CodeAlphabet::Ternary => {
            // Each entry −1, 0 or 1 as the byte of its value plus one.
            let local: Vec<u8> = codes.to_dense().iter().map(|&v| (v + 1) as u8).collect();
            let all: Vec<i8> = space
                .gather_bytes(&local)
                .into_iter()
                .map(|b| b as i8 - 1)
                .collect();
            let pixels = all.len() / len;
            let dense = ndarray::Array2::from_shape_vec((pixels, len), all)
                .map_err(|e| Error::param("codes", e.to_string()))?;
            Codes::from_dense(dense.view())
        }
    }
}

/// The lidar operator, every application counted: its sparse forward as a support
/// application, the zero-mean operator's applications as forward and adjoint ones.
impl<T: Real, A: LidarOperator<T>> LidarOperator<T> for Counted<A> {
    fn geometry(&self) -> Geometry {
        self.inner().geometry()
    }
    fn pulse(&self) -> &[T] {
        self.inner().pulse()
    }
    fn code_sets(&self) -> usize {
        self.inner().code_sets()
    }
    fn apply_sparse(&self, x: &[T], y: &mut [T]) {
        self.count_support();
        self.inner().apply_sparse(x, y)
    }
    fn zero_mean_operator(&self) -> Box<dyn LinearOperator<T> + '_> {
        self.counting_full(self.inner().zero_mean_operator())
    }
    fn observed_pixels(&self) -> Option<Vec<bool>> {
        self.inner().observed_pixels()
    }
    fn whole_code_sets(&self) -> Option<Vec<&Arc<Codes>>> {
        self.inner().whole_code_sets()
    }
    fn gathered_code_sets(&self) -> Option<Result<Vec<Arc<Codes>>>> {
        self.inner().gathered_code_sets()
    }
    fn row_weights(&self) -> Option<&[T]> {
        self.inner().row_weights()
    }
    fn regime(&self) -> Regime {
        self.inner().regime()
    }
}

/// G ADCs: every pixel is modulated by G independent code sets and set g has its own ADC; the
/// G fused operators share the pulse and their measurements are stacked, y = [A₁x; …; A_Gx]
/// (G·K rows, ADC by ADC). Every lidar solver runs on it: it is a [`LidarOperator`] whose
/// correlations, pixel Gram blocks and column norms are the sums over the code sets, and whose
/// restriction to a support stacks the G support operators.
#[derive(Debug)]
pub struct MultiAdcOperator<T: Real> {
    parts: Vec<RdOperator<T>>,
    geom: Geometry,
    k: usize,
    /// The single-precision twin ([`LinearOperator::single`]), built on first use.
    single: OnceLock<Option<Box<MultiAdcOperator<f32>>>>,
}

impl<T: Real> MultiAdcOperator<T> {
    /// G fused operators over `geom` with the common pulse `pulse` and the code sets `codes`.
    ///
    /// # Errors
    /// [`Error::InvalidParameter`] for an empty list of code sets; the errors of
    /// [`RdOperator::new`] for code sets that do not fit the geometry and pulse.
    pub fn new(geom: Geometry, pulse: &[T], codes: Vec<Arc<Codes>>) -> Result<Self> {
        if codes.is_empty() {
            return Err(Error::param("adcs", "need at least one code set"));
        }
        let parts = codes
            .into_iter()
            .map(|c| RdOperator::new(geom, pulse.to_vec(), c))
            .collect::<Result<Vec<_>>>()?;
        let k = parts[0].nrows();
        Ok(MultiAdcOperator {
            parts,
            geom,
            k,
            single: OnceLock::new(),
        })
    }

    /// The G one-ADC operators, in the order of their measurement rows.
    pub fn parts(&self) -> &[RdOperator<T>] {
        &self.parts
    }

    /// Each part with its block of `k` rows of `rows`.
    fn each_rows<'a>(
        &'a self,
        rows: &'a [T],
    ) -> impl Iterator<Item = (&'a RdOperator<T>, &'a [T])> {
        self.parts.iter().zip(rows.chunks_exact(self.k))
    }

    /// Sums `f(part, rows of part, out)` over the parts into `x`.
    fn sum_over(&self, y: &[T], x: &mut [T], f: impl Fn(&RdOperator<T>, &[T], &mut [T])) {
        let mut acc = vec![0.0f64; x.len()];
        let mut part = vec![T::zero(); x.len()];
        for (op, rows) in self.each_rows(y) {
            f(op, rows, &mut part);
            acc.iter_mut()
                .zip(&part)
                .for_each(|(a, v)| *a += v.as_f64());
        }
        x.iter_mut().zip(&acc).for_each(|(o, a)| *o = T::of_f64(*a));
    }
}

impl<T: Real> LinearOperator<T> for MultiAdcOperator<T> {
    fn nrows(&self) -> usize {
        self.k * self.parts.len()
    }

    fn ncols(&self) -> usize {
        self.geom.voxels()
    }

    fn forward_kernel(&self, x: &[T], y: &mut [T], _: &mut [T]) {
        for (op, rows) in self.parts.iter().zip(y.chunks_exact_mut(self.k)) {
            op.apply(x, rows);
        }
    }

    fn adjoint_kernel(&self, y: &[T], x: &mut [T], _: &mut [T]) {
        self.sum_over(y, x, |op, rows, out| op.apply_adjoint(rows, out));
    }

    /// The same code sets with the pulse rounded to `f32`, built on the first call and kept;
    /// `None` when `T` is `f32` or a pulse value overflows `f32` (as [`RdOperator`]'s).
    fn single(&self) -> Option<Box<dyn LinearOperator<f32> + '_>> {
        let twin = self.single.get_or_init(|| {
            let pulse = single_pulse(self.parts[0].pulse())?;
            let codes = self.parts.iter().map(|op| op.codes().clone()).collect();
            MultiAdcOperator::new(self.geom, &pulse, codes)
                .ok()
                .map(Box::new)
        });
        twin.as_deref()
            .map(|op| Box::new(op) as Box<dyn LinearOperator<f32> + '_>)
    }

    /// The G support operators stacked: both directions cost O(G·|columns|·K_p).
    fn restrict_columns(&self, columns: Vec<usize>) -> Result<Box<dyn LinearOperator<T> + '_>> {
        let parts = self
            .parts
            .iter()
            .map(|op| op.restrict_columns(columns.clone()))
            .collect::<Result<Vec<_>>>()?;
        Ok(Box::new(VStack::new(parts)?))
    }

    fn describe(&self) -> String {
        format!(
            "MultiAdcOperator({} ADCs, {}, K_p {})",
            self.parts.len(),
            self.geom,
            self.parts[0].pulse().len()
        )
    }
}

impl<T: Real> VoxelOperator<T> for MultiAdcOperator<T> {
    fn column_len(&self) -> usize {
        self.geom.ks
    }

    /// The sum over the code sets of the debiased correlations.
    fn correlate(&self, r: &[T], u: &mut [T]) {
        self.sum_over(r, u, |op, rows, out| op.correlate(rows, out));
    }

    fn self_correlations(&self, voxels: &[usize]) -> Vec<f64> {
        sum_rows(self.parts.iter().map(|op| op.self_correlations(voxels)))
    }

    fn pixel_gram(&self, pixel: usize) -> Vec<f64> {
        sum_rows(self.parts.iter().map(|op| op.pixel_gram(pixel)))
    }

    fn uniform_pixel_gram(&self) -> bool {
        self.parts.iter().all(|op| op.uniform_pixel_gram())
    }

    fn structured_columns(&self) -> bool {
        self.parts.iter().all(|op| op.structured_columns())
    }

    fn column_norms(&self, columns: &[usize]) -> Vec<f64> {
        sum_rows(self.parts.iter().map(|op| {
            let mut n = op.column_norms(columns);
            n.iter_mut().for_each(|v| *v *= *v);
            n
        }))
        .into_iter()
        .map(f64::sqrt)
        .collect()
    }

    /// The code sets' columns in their blocks of rows, from the first set's first row.
    fn column(&self, c: usize) -> (usize, Vec<f64>) {
        let k = self.parts[0].nrows();
        let mut first = usize::MAX;
        let mut pieces = Vec::with_capacity(self.parts.len());
        for (g, op) in self.parts.iter().enumerate() {
            let (at, values) = op.column(c);
            first = first.min(g * k + at);
            pieces.push((g * k + at, values));
        }
        let end = pieces
            .iter()
            .map(|(at, v)| at + v.len())
            .max()
            .unwrap_or(first);
        let mut out = vec![0.0; end - first];
        for (at, values) in pieces {
            out[at - first..at - first + values.len()].copy_from_slice(&values);
        }
        (first, out)
    }
}

impl<T: Real> LidarOperator<T> for MultiAdcOperator<T> {
    fn geometry(&self) -> Geometry {
        self.geom
    }
    fn whole_code_sets(&self) -> Option<Vec<&Arc<Codes>>> {
        Some(self.parts.iter().map(|op| op.codes()).collect())
    }

    fn pulse(&self) -> &[T] {
        self.parts[0].pulse()
    }

    fn code_sets(&self) -> usize {
        self.parts.len()
    }

    fn apply_sparse(&self, x: &[T], y: &mut [T]) {
        crate::operator::check_len("apply_sparse: output y", self.nrows(), y.len());
        for (op, rows) in self.parts.iter().zip(y.chunks_exact_mut(self.k)) {
            op.apply_sparse(x, rows);
        }
    }

    fn zero_mean_operator(&self) -> Box<dyn LinearOperator<T> + '_> {
        let parts: Vec<&RdOperator<T>> = self.parts.iter().map(|op| op.zero_mean()).collect();
        Box::new(VStack::new(parts).expect("the parts share their shape"))
    }

    /// A pixel is observed when any code set reaches it.
    fn observed_pixels(&self) -> Option<Vec<bool>> {
        let mut all = vec![false; self.geom.pixels()];
        for op in &self.parts {
            match op.observed_pixels() {
                None => return None,
                Some(o) => all.iter_mut().zip(o).for_each(|(a, b)| *a |= b),
            }
        }
        all.iter().any(|&o| !o).then_some(all)
    }
}

/// The elementwise sum of equally long rows.
fn sum_rows(rows: impl Iterator<Item = Vec<f64>>) -> Vec<f64> {
    rows.reduce(|mut a, b| {
        a.iter_mut().zip(&b).for_each(|(x, y)| *x += y);
        a
    })
    .unwrap_or_default()
}
