//! The measurement operator restricted to a set of voxels: A·Rᵀ with forward and adjoint in
//! O(|S|·K_p), for solvers that work on a support (least squares on candidate depths).

use std::ops::Range;

use rayon::prelude::*;

use crate::error::{Error, Result};
use crate::operator::LinearOperator;
use crate::operator::VoxelOperator;
use crate::real::Real;

use super::kernels::{depth_dots_isa, Coded};
use super::rdop::RdOperator;

/// Voxels of one depth that the adjoint takes together.
const PIECE: usize = 64;

/// `A·Rᵀ` for a set S of voxels: the input holds one amplitude per voxel of S (in the order
/// given), the output is the K measurements. Equivalent to
/// `op.compose(Restriction::new(n, S)?.adjoint())`, but both directions cost O(|S|·K_p) instead of
/// a full adjoint: the forward adds each voxel's modulated, shifted pulse, the adjoint correlates
/// the measurements with it (sums over K_p samples accumulated in `f64`).
#[derive(Debug)]
pub struct SupportOperator<'a, T: Real> {
    op: &'a RdOperator<T>,
    voxels: Vec<usize>,
    /// Positions in `voxels` sorted by depth, then pixel.
    by_depth: Vec<usize>,
    /// Ranges of `by_depth` of one depth (at most `PIECE` voxels each) and their depth.
    pieces: Vec<(Range<usize>, usize)>,
}

impl<'a, T: Real> SupportOperator<'a, T> {
    /// The restriction of `op` to `voxels` (flat scene indices, repeats allowed).
    ///
    /// # Errors
    /// [`Error::IndexOutOfBounds`] for a voxel not below M·N·K_s.
    pub fn new(op: &'a RdOperator<T>, voxels: Vec<usize>) -> Result<Self> {
        let n = op.ncols();
        if let Some(&bad) = voxels.iter().find(|&&v| v >= n) {
            return Err(Error::IndexOutOfBounds {
                context: "support voxels",
                index: bad,
                len: n,
            });
        }
        let ks = op.geometry().ks;
        let mut by_depth: Vec<usize> = (0..voxels.len()).collect();
        by_depth.sort_unstable_by_key(|&i| (voxels[i] % ks, voxels[i] / ks, i));
        let mut pieces = Vec::new();
        let mut at = 0;
        for run in by_depth.chunk_by(|&a, &b| voxels[a] % ks == voxels[b] % ks) {
            for piece in run.chunks(PIECE) {
                pieces.push((at..at + piece.len(), voxels[piece[0]] % ks));
                at += piece.len();
            }
        }
        Ok(SupportOperator {
            op,
            voxels,
            by_depth,
            pieces,
        })
    }

    /// The voxels of the support.
    pub fn voxels(&self) -> &[usize] {
        &self.voxels
    }
}

impl<T: Real> LinearOperator<T> for SupportOperator<'_, T> {
    fn nrows(&self) -> usize {
        self.op.nrows()
    }

    fn ncols(&self) -> usize {
        self.voxels.len()
    }

    fn forward_kernel(&self, x: &[T], y: &mut [T], _: &mut [T]) {
        let ks = self.op.geometry().ks;
        let entries: Vec<(usize, usize, T)> = self
            .voxels
            .iter()
            .zip(x)
            .filter(|(_, a)| **a != T::zero())
            .map(|(&v, &a)| (v / ks, v % ks, a))
            .collect();
        self.op.forward_entries(&entries, y);
    }

    fn adjoint_kernel(&self, y: &[T], x: &mut [T], _: &mut [T]) {
        let ks = self.op.geometry().ks;
        let pulse = self.op.pulse();
        let kp = pulse.len();
        let codes = self.op.codes();
        let isa = self.op.isa_kind();
        // Piece by piece (voxels of one depth, which share the window of y and of the pulse), in
        // spans of `SPAN` samples, every piece of a thread's share in turn, so that the span of
        // the pulse and of y stays in the nearest caches while the codes stream (16 kB for `f32`,
        // within L1; 32 kB for `f64`).
        const SPAN: usize = 2048;
        let share = self
            .pieces
            .len()
            .div_ceil(4 * rayon::current_num_threads())
            .max(1);
        let out: Vec<(usize, T)> = self
            .pieces
            .par_chunks(share)
            .flat_map_iter(|pieces| {
                let first = pieces.first().map_or(0, |p| p.0.start);
                let last = pieces.last().map_or(0, |p| p.0.end);
                let mut sums = vec![0.0f64; last - first];
                let mut part = [0.0f64; PIECE];
                let mut coded = Vec::with_capacity(PIECE);
                for t0 in (0..kp).step_by(SPAN) {
                    let t1 = (t0 + SPAN).min(kp);
                    for (range, d) in pieces {
                        let (lo, hi) = (d + t0, d + t1);
                        coded.clear();
                        coded.extend(self.by_depth[range.clone()].iter().map(|&i| {
                            let p = self.voxels[i] / ks;
                            let g = p / 8;
                            Coded {
                                bit: (p % 8) as u32,
                                plus: &codes.plus_group(g)[lo..hi],
                                minus: codes.minus_group(g).map(|m| &m[lo..hi]),
                            }
                        }));
                        let part = &mut part[..range.len()];
                        depth_dots_isa(isa, &coded, &y[lo..hi], &pulse[t0..t1], part);
                        let sums = &mut sums[range.start - first..range.end - first];
                        for (s, v) in sums.iter_mut().zip(part.iter()) {
                            *s += v;
                        }
                    }
                }
                self.by_depth[first..last]
                    .iter()
                    .zip(sums)
                    .map(|(&i, v)| (i, T::of_f64(v)))
                    .collect::<Vec<_>>()
            })
            .collect();
        for (i, v) in out {
            x[i] = v;
        }
    }

    /// The support operator of the selected voxels.
    fn restrict_columns(&self, columns: Vec<usize>) -> Result<Box<dyn LinearOperator<T> + '_>> {
        let n = self.voxels.len();
        if let Some(&bad) = columns.iter().find(|&&c| c >= n) {
            return Err(Error::IndexOutOfBounds {
                context: "support columns",
                index: bad,
                len: n,
            });
        }
        let voxels = columns.iter().map(|&c| self.voxels[c]).collect();
        Ok(Box::new(SupportOperator::new(self.op, voxels)?))
    }

    fn describe(&self) -> String {
        format!(
            "SupportOperator({} voxels of {})",
            self.voxels.len(),
            self.op.describe()
        )
    }
}

impl<T: Real> VoxelOperator<T> for RdOperator<T> {
    fn column_len(&self) -> usize {
        self.geometry().ks
    }

    /// The debiased correlation: the adjoint with the zero-mean pulse (docs/math.md §4).
    fn correlate(&self, r: &[T], u: &mut [T]) {
        self.apply_adjoint_debiased(r, u)
    }

    /// From the pulse autocorrelation for ±1 codes (s² = 1, the same for every pixel); with
    /// ternary codes from the pixel's nonzero codes.
    fn self_correlations(&self, voxels: &[usize]) -> Vec<f64> {
        let ks = self.geometry().ks;
        let pulse = self.pulse();
        let kp = pulse.len();
        let mean = pulse.iter().map(|v| v.as_f64()).sum::<f64>() / kp as f64;
        let p64: Vec<f64> = pulse.iter().map(|v| v.as_f64()).collect();
        // c(lag) = Σ_t (p[t + lag] − mean)·p[t] over the overlap, lag = d − j.
        let lag_corr = |lag: isize, weight: &dyn Fn(usize) -> f64| -> f64 {
            let lo = 0.max(-lag) as usize;
            let hi = (kp as isize).min(kp as isize - lag).max(0) as usize;
            (lo..hi)
                .map(|t| (p64[(t as isize + lag) as usize] - mean) * p64[t] * weight(t))
                .sum()
        };
        let codes = self.codes();
        match codes.minus_plane() {
            None => {
                let table: Vec<f64> = (0..2 * ks - 1)
                    .map(|i| lag_corr(i as isize - (ks as isize - 1), &|_| 1.0))
                    .collect();
                voxels
                    .iter()
                    .flat_map(|&v| {
                        let d = v % ks;
                        let table = &table;
                        (0..ks).map(move |j| table[d + ks - 1 - j])
                    })
                    .collect()
            }
            Some(_) => voxels
                .par_iter()
                .flat_map_iter(|&v| {
                    let (p, d) = (v / ks, v % ks);
                    let nonzero = |t: usize| f64::from(u8::from(codes.get(p, d + t) != 0));
                    (0..ks)
                        .map(|j| lag_corr(d as isize - j as isize, &nonzero))
                        .collect::<Vec<_>>()
                })
                .collect(),
        }
    }

    /// With ±1 codes (s² = 1) the pulse's plain autocorrelation, Toeplitz and the same for
    /// every pixel. With ternary codes an approximation: that block scaled by the fraction of
    /// the pixel's codes that are nonzero, exact for pixels whose codes are all zero or all
    /// nonzero (a coded aperture) and the expected block for randomly placed zeros.
    fn pixel_gram(&self, pixel: usize) -> Vec<f64> {
        let ks = self.geometry().ks;
        let lags = self.pulse_lags();
        let codes = self.codes();
        let scale = match codes.minus_plane() {
            None => 1.0,
            Some(_) => {
                let k = self.nrows();
                let nonzero = (0..k).filter(|&t| codes.get(pixel, t) != 0).count();
                nonzero as f64 / k.max(1) as f64
            }
        };
        (0..ks * ks)
            .map(|i| scale * lags[(i / ks).abs_diff(i % ks)])
            .collect()
    }

    fn uniform_pixel_gram(&self) -> bool {
        self.codes().minus_plane().is_none()
    }

    /// Column queries from the pulse and the codes, no application.
    fn structured_columns(&self) -> bool {
        true
    }

    /// `s_p[d + t]·p[t]` from row d, for column (p, d).
    fn column(&self, c: usize) -> (usize, Vec<f64>) {
        let ks = self.geometry().ks;
        let (p, d) = (c / ks, c % ks);
        let codes = self.codes();
        let values = self
            .pulse()
            .iter()
            .enumerate()
            .map(|(t, v)| f64::from(codes.get(p, d + t)) * v.as_f64())
            .collect();
        (d, values)
    }

    /// ‖p‖ for ±1 codes; with ternary codes the pulse energy over the nonzero codes of the window.
    fn column_norms(&self, columns: &[usize]) -> Vec<f64> {
        let ks = self.geometry().ks;
        let pulse = self.pulse();
        let codes = self.codes();
        match codes.minus_plane() {
            None => {
                let e = pulse.iter().map(|v| v.as_f64().powi(2)).sum::<f64>().sqrt();
                vec![e; columns.len()]
            }
            Some(_) => columns
                .par_iter()
                .map(|&c| {
                    let (p, j) = (c / ks, c % ks);
                    (0..pulse.len())
                        .filter(|&t| codes.get(p, j + t) != 0)
                        .map(|t| pulse[t].as_f64().powi(2))
                        .sum::<f64>()
                        .sqrt()
                })
                .collect(),
        }
    }
}
