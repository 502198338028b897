//! The measurement operator with weighted rows: W·A for W = diag(w), the operator of a weighted
//! least-squares data term ‖W(y − Ax)‖². With w = 1/√v for measurement variances v, least squares
//! on W·A and W·y is matched to noise whose variance changes from sample to sample (photon noise,
//! whose variance follows the light each sample receives).
//!
//! [`RowWeighted`] is a [`LidarOperator`] like the one it weights: its applications, its
//! restrictions to a support and its correlations go through that operator (scaled before or
//! after), and its column queries (norms, pixel Gram blocks, self-correlations) come from the
//! codes and the pulse with the squared weights inside the sums, so every lidar solver runs on it
//! unchanged.

use std::sync::Arc;

use rayon::prelude::*;

use crate::error::{Error, Result};
use crate::operator::{LinearOperator, VoxelOperator};
use crate::real::Real;

use super::codes::Codes;
use super::geometry::{Geometry, Regime};
use super::measurement::LidarOperator;
use super::pulse::zero_mean;

/// W·A: the rows of the lidar operator A scaled by the weights w (one per measurement, in the
/// order of A's rows: ADC by ADC).
///
/// A must hold its codes in memory over the whole scene ([`LidarOperator::whole_code_sets`]: one
/// ADC or several, not streamed codes or pixels split across processes), since the column queries
/// need the codes sample by sample.
pub struct RowWeighted<'a, T: Real> {
    op: &'a dyn LidarOperator<T>,
    w: Vec<T>,
    /// w², in f64.
    u: Vec<f64>,
    sets: Vec<&'a Arc<Codes>>,
    /// Rows per code set (K).
    k: usize,
    pulse: Vec<f64>,
    pulse0: Vec<f64>,
    /// Every code set binary (±1, s² = 1): the column queries are the same for every pixel.
    binary: bool,
    /// The self-correlations (d, j) with the codes taken as ±1, K_s × K_s: exact for binary codes.
    corr: Vec<f64>,
    /// The Gram block (i, j) with the codes taken as ±1, K_s × K_s: exact for binary codes, the
    /// base of the ternary one.
    gram: Vec<f64>,
}

impl<T: Real> std::fmt::Debug for RowWeighted<'_, T> {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("RowWeighted")
            .field("rows", &self.w.len())
            .field("code_sets", &self.sets.len())
            .finish()
    }
}

impl<'a, T: Real> RowWeighted<'a, T> {
    /// diag(`w`)·`op`.
    ///
    /// # Errors
    /// [`Error::ShapeMismatch`] unless `w` has one weight per row of `op`;
    /// [`Error::InvalidParameter`] (`weights`) for a negative, NaN or infinite weight or all
    /// weights zero, and (`operator`) for an operator without its codes in memory over the whole
    /// scene or one that is already weighted.
    pub fn new(op: &'a dyn LidarOperator<T>, w: Vec<T>) -> Result<Self> {
        if w.len() != op.nrows() {
            return Err(Error::shape(
                "row weights vs operator rows",
                op.nrows(),
                w.len(),
            ));
        }
        if let Some(i) = w.iter().position(|v| !(v.is_finite() && *v >= T::zero())) {
            return Err(Error::param(
                "weights",
                format!(
                    "weight {i} is {}: weights must be finite and >= 0",
                    crate::units::number(w[i])
                ),
            ));
        }
        if w.iter().all(|v| *v == T::zero()) {
            return Err(Error::param("weights", "every weight is zero"));
        }
        if op.row_weights().is_some() {
            return Err(Error::param("operator", "the operator is already weighted"));
        }
        let Some(sets) = op.whole_code_sets() else {
            return Err(Error::param(
                "operator",
                "weighted rows need the codes in memory and the whole scene in one process",
            ));
        };
        let k = op.nrows() / sets.len().max(1);
        let pulse: Vec<f64> = op.pulse().iter().map(|v| v.as_f64()).collect();
        let pulse0 = zero_mean(&pulse);
        let binary = sets.iter().all(|c| c.minus_plane().is_none());
        let u = w.iter().map(|v| v.as_f64().powi(2)).collect();
        let mut weighted = RowWeighted {
            op,
            w,
            u,
            sets,
            k,
            pulse,
            pulse0,
            binary,
            corr: Vec::new(),
            gram: Vec::new(),
        };
        // Built here, not on first use: a lazy cell filled by a parallel loop could be entered
        // again by the same thread from the caller's parallel loop over pixels.
        (weighted.corr, weighted.gram) = weighted.build_tables();
        Ok(weighted)
    }

    /// The weights.
    pub fn weights(&self) -> &[T] {
        &self.w
    }

    /// `Σ_sets Σ_t u[set·K + d + t]·s²·p[t]·q[t + d − j]` over the overlap: the weighted inner
    /// product of column (pixel, d) with column j of the pixel built on the pulse `q`. With
    /// `pixel` `None` the codes count as ±1 (s² = 1).
    fn sum(&self, pixel: Option<usize>, d: usize, j: usize, q: &[f64]) -> f64 {
        let kp = self.pulse.len() as isize;
        let lag = d as isize - j as isize;
        let (lo, hi) = (0.max(-lag) as usize, kp.min(kp - lag).max(0) as usize);
        self.sets
            .iter()
            .enumerate()
            .map(|(set, codes)| {
                let u = &self.u[set * self.k + d..];
                (lo..hi)
                    .filter(|&t| pixel.is_none_or(|p| codes.get(p, d + t) != 0))
                    .map(|t| u[t] * self.pulse[t] * q[(t as isize + lag) as usize])
                    .sum::<f64>()
            })
            .sum()
    }

    /// The tables with the codes taken as ±1: self-correlations with the zero-mean pulse and the
    /// Gram block (O(K_s²·K_p) per code set).
    fn build_tables(&self) -> (Vec<f64>, Vec<f64>) {
        let ks = self.op.column_len();
        let cell = |i: usize, q: &[f64]| self.sum(None, i / ks, i % ks, q);
        let corr = (0..ks * ks)
            .into_par_iter()
            .map(|i| cell(i, &self.pulse0))
            .collect();
        let gram = (0..ks * ks)
            .into_par_iter()
            .map(|i| cell(i, &self.pulse))
            .collect();
        (corr, gram)
    }

    /// W·`v`: `v` scaled by the weights, row by row (the weighted measurements of `v`).
    pub fn weigh(&self, v: &[T]) -> Vec<T> {
        let mut out = v.to_vec();
        scale_rows(&mut out, &self.w);
        out
    }
}

/// v ← diag(w)·v.
fn scale_rows<T: Real>(v: &mut [T], w: &[T]) {
    for (a, b) in v.iter_mut().zip(w) {
        *a = *a * *b;
    }
}

/// An operator whose rows are scaled by weights: `inner` then diag(w).
struct RowScaled<'b, T: Real> {
    inner: Box<dyn LinearOperator<T> + 'b>,
    w: &'b [T],
}

impl<T: Real> LinearOperator<T> for RowScaled<'_, T> {
    fn nrows(&self) -> usize {
        self.inner.nrows()
    }
    fn ncols(&self) -> usize {
        self.inner.ncols()
    }
    fn forward_kernel(&self, x: &[T], y: &mut [T], _: &mut [T]) {
        self.inner.apply(x, y);
        scale_rows(y, self.w);
    }
    fn adjoint_kernel(&self, y: &[T], x: &mut [T], _: &mut [T]) {
        let mut z = y.to_vec();
        scale_rows(&mut z, self.w);
        self.inner.apply_adjoint(&z, x);
    }
    fn describe(&self) -> String {
        format!("RowScaled({})", self.inner.describe())
    }
}

impl<T: Real> LinearOperator<T> for RowWeighted<'_, T> {
    fn nrows(&self) -> usize {
        self.op.nrows()
    }

    fn ncols(&self) -> usize {
        self.op.ncols()
    }

    fn forward_kernel(&self, x: &[T], y: &mut [T], _: &mut [T]) {
        self.op.apply(x, y);
        scale_rows(y, &self.w);
    }

    fn adjoint_kernel(&self, y: &[T], x: &mut [T], _: &mut [T]) {
        self.op.apply_adjoint(&self.weigh(y), x);
    }

    fn restrict_columns(&self, columns: Vec<usize>) -> Result<Box<dyn LinearOperator<T> + '_>> {
        Ok(Box::new(RowScaled {
            inner: self.op.restrict_columns(columns)?,
            w: &self.w,
        }))
    }

    fn describe(&self) -> String {
        format!("RowWeighted({})", self.op.describe())
    }
}

impl<T: Real> VoxelOperator<T> for RowWeighted<'_, T> {
    fn column_len(&self) -> usize {
        self.op.column_len()
    }

    /// The operator's correlation (the debiased one) of the weighted residual: Aᵀ₀·W·r.
    fn correlate(&self, r: &[T], u: &mut [T]) {
        self.op.correlate(&self.weigh(r), u)
    }

    fn self_correlations(&self, voxels: &[usize]) -> Vec<f64> {
        let ks = self.column_len();
        if self.binary {
            return voxels
                .iter()
                .flat_map(|&v| self.corr[(v % ks) * ks..][..ks].iter().copied())
                .collect();
        }
        voxels
            .par_iter()
            .flat_map_iter(|&v| {
                let (p, d) = (v / ks, v % ks);
                (0..ks)
                    .map(|j| self.sum(Some(p), d, j, &self.pulse0))
                    .collect::<Vec<_>>()
            })
            .collect()
    }

    /// Exact for binary codes (the same block for every pixel); with ternary codes the binary
    /// block scaled by the weighted share of the pixel's nonzero codes, as the unweighted
    /// operator approximates it.
    fn pixel_gram(&self, pixel: usize) -> Vec<f64> {
        if self.binary {
            return self.gram.clone();
        }
        let (mut nonzero, mut all) = (0.0, 0.0);
        for (set, codes) in self.sets.iter().enumerate() {
            for t in 0..self.k {
                let u = self.u[set * self.k + t];
                all += u;
                if codes.get(pixel, t) != 0 {
                    nonzero += u;
                }
            }
        }
        let scale = if all > 0.0 { nonzero / all } else { 0.0 };
        self.gram.iter().map(|g| scale * g).collect()
    }

    fn uniform_pixel_gram(&self) -> bool {
        self.binary
    }

    fn structured_columns(&self) -> bool {
        true
    }

    fn column_norms(&self, columns: &[usize]) -> Vec<f64> {
        let ks = self.column_len();
        if self.binary {
            return columns
                .iter()
                .map(|&c| self.gram[(c % ks) * (ks + 1)].max(0.0).sqrt())
                .collect();
        }
        columns
            .par_iter()
            .map(|&c| {
                let d = c % ks;
                self.sum(Some(c / ks), d, d, &self.pulse).max(0.0).sqrt()
            })
            .collect()
    }

    fn column(&self, c: usize) -> (usize, Vec<f64>) {
        let (start, mut values) = self.op.column(c);
        for (v, w) in values.iter_mut().zip(&self.w[start.min(self.w.len())..]) {
            *v *= w.as_f64();
        }
        (start, values)
    }
}

impl<T: Real> LidarOperator<T> for RowWeighted<'_, T> {
    fn geometry(&self) -> Geometry {
        self.op.geometry()
    }

    fn pulse(&self) -> &[T] {
        self.op.pulse()
    }

    fn code_sets(&self) -> usize {
        self.op.code_sets()
    }

    fn apply_sparse(&self, x: &[T], y: &mut [T]) {
        self.op.apply_sparse(x, y);
        scale_rows(y, &self.w);
    }

    fn zero_mean_operator(&self) -> Box<dyn LinearOperator<T> + '_> {
        Box::new(RowScaled {
            inner: self.op.zero_mean_operator(),
            w: &self.w,
        })
    }

    fn observed_pixels(&self) -> Option<Vec<bool>> {
        self.op.observed_pixels()
    }

    fn whole_code_sets(&self) -> Option<Vec<&Arc<Codes>>> {
        Some(self.sets.clone())
    }

    fn row_weights(&self) -> Option<&[T]> {
        Some(&self.w)
    }

    fn regime(&self) -> Regime {
        self.op.regime()
    }
}
