//! The measurement operator on a coarser grid: the scene constant over blocks of bm × bn pixels.
//!
//! If every pixel of a block B has the same depth column x_B, the pixels' terms add up to one
//! pixel whose code is the sum of theirs: `Σ_{p∈B} s[p,k]·(x_B ⊛ p)[k] = c_B[k]·(x_B ⊛ p)[k]`
//! with `c_B = Σ_{p∈B} s_p`. The coarse problem has bm·bn times fewer unknowns for the same
//! measurements, so a scene with fewer measurements than lit pixels can be solved there first
//! (where its surfaces are wider than the blocks) and the result refined on the pixels.

use rayon::prelude::*;

use crate::error::{Error, Result};
use crate::operator::{LinearOperator, VoxelOperator};
use crate::real::Real;

use super::measurement::LidarOperator;
use super::pulse::zero_mean;

/// Chunks of the voxels of a support application on the coarse grid, summed apart then added in
/// order.
const SUPPORT_CHUNKS: usize = 16;

/// `A·U` for a lidar operator A over the whole scene (one ADC or several) and the upsampling U
/// that copies each block's depth column to its pixels: the operator of the scene on the grid of
/// blocks (⌈M/bm⌉ × ⌈N/bn⌉ pixels, K_s bins, C order). Its dense applications and correlations
/// go through A (one application of A each, so that A's wrappers count or cancel them); its
/// support-restricted applications and column queries use the blocks' summed codes directly.
pub struct BlockOperator<'a, T: Real> {
    op: &'a dyn LidarOperator<T>,
    block: (usize, usize),
    grid: (usize, usize),
    /// The summed codes c_B of each code set, set-major then block-major (K per block).
    codes: Vec<i8>,
    /// Code sets (ADCs), each with K rows.
    sets: usize,
    /// Rows per code set (K).
    k: usize,
    pulse: Vec<f64>,
    /// The zero-mean pulse, for the debiased correlation.
    pulse0: Vec<f64>,
    /// The pulse's autocorrelation at lags 0..K_s.
    lags: Vec<f64>,
    /// Each block's mean squared code, summed over the code sets (weighted by the squared row
    /// weights when A's rows are weighted).
    power: Vec<f64>,
    /// A's row weights ([`LidarOperator::row_weights`]), in f64: the support applications and
    /// column queries weight the rows as A's applications do.
    weights: Option<Vec<f64>>,
}

impl<'a, T: Real> BlockOperator<'a, T> {
    /// The coarse operator of `op` for blocks of `block = (bm, bn)` pixels (the last row and
    /// column of blocks may be smaller).
    ///
    /// # Errors
    /// [`Error::InvalidParameter`] for a block side of 0 or a block of more than 127 pixels
    /// (the summed codes are stored as bytes), or for an operator without whole codes in
    /// memory ([`LidarOperator::whole_code_sets`]).
    pub fn new(op: &'a dyn LidarOperator<T>, block: (usize, usize)) -> Result<Self> {
        let (bm, bn) = block;
        if bm == 0 || bn == 0 || bm.checked_mul(bn).is_none_or(|pixels| pixels > 127) {
            return Err(Error::param(
                "block",
                format!("must have 1 to 127 pixels, got {bm}×{bn}"),
            ));
        }
        let Some(sources) = op.whole_code_sets() else {
            return Err(Error::param(
                "operator",
                "the coarse grid needs the codes in memory and the whole scene in one process",
            ));
        };
        let g = op.geometry();
        let grid = (g.m.div_ceil(bm), g.n.div_ceil(bn));
        let blocks = grid.0 * grid.1;
        let sets = sources.len().max(1);
        let k = op.nrows() / sets;
        let mut codes = vec![0i8; sets * blocks * k];
        codes.par_chunks_mut(k).enumerate().for_each(|(i, row)| {
            let (src, b) = (sources[i / blocks], i % blocks);
            let (bi, bj) = (b / grid.1, b % grid.1);
            for r in bi * bm..((bi + 1) * bm).min(g.m) {
                for c in bj * bn..((bj + 1) * bn).min(g.n) {
                    let p = r * g.n + c;
                    for (t, code) in row.iter_mut().enumerate() {
                        *code += src.get(p, t);
                    }
                }
            }
        });
        let weights: Option<Vec<f64>> = op
            .row_weights()
            .map(|w| w.iter().map(|v| v.as_f64()).collect());
        let pulse: Vec<f64> = op.pulse().iter().map(|v| v.as_f64()).collect();
        let pulse0 = zero_mean(&pulse);
        let kp = pulse.len();
        let lags = (0..g.ks)
            .map(|l| {
                (0..kp.saturating_sub(l))
                    .map(|t| pulse[t] * pulse[t + l])
                    .sum()
            })
            .collect();
        let power = (0..blocks)
            .map(|b| {
                (0..sets)
                    .map(|set| {
                        let c = &codes[(set * blocks + b) * k..][..k];
                        let u = |t: usize| weights.as_ref().map_or(1.0, |w| w[set * k + t].powi(2));
                        c.iter()
                            .enumerate()
                            .map(|(t, &v)| f64::from(v).powi(2) * u(t))
                            .sum::<f64>()
                            / k.max(1) as f64
                    })
                    .sum()
            })
            .collect();
        Ok(BlockOperator {
            weights,
            lags,
            power,
            sets,
            k,
            op,
            block,
            grid,
            codes,
            pulse,
            pulse0,
        })
    }

    /// The grid of blocks (rows, columns).
    pub fn grid(&self) -> (usize, usize) {
        self.grid
    }

    /// The block size (rows, columns of pixels).
    pub fn block(&self) -> (usize, usize) {
        self.block
    }

    fn ks(&self) -> usize {
        self.op.geometry().ks
    }

    /// The block that holds fine pixel `p`.
    pub fn block_of(&self, p: usize) -> usize {
        let n = self.op.geometry().n;
        let (i, j) = (p / n, p % n);
        (i / self.block.0) * self.grid.1 + j / self.block.1
    }

    /// The fine scene with each block's depth column copied to its pixels.
    pub fn upsample(&self, coarse: &[T], fine: &mut [T]) {
        let ks = self.ks();
        fine.par_chunks_mut(ks).enumerate().for_each(|(p, col)| {
            let b = self.block_of(p);
            col.copy_from_slice(&coarse[b * ks..(b + 1) * ks]);
        });
    }

    /// The sum of each block's pixels' depth columns (the adjoint of
    /// [`upsample`](Self::upsample)).
    pub fn sum_blocks(&self, fine: &[T], coarse: &mut [T]) {
        let ks = self.ks();
        let n = self.op.geometry().n;
        let m = self.op.geometry().m;
        let (bm, bn) = self.block;
        let gn = self.grid.1;
        coarse.par_chunks_mut(ks).enumerate().for_each(|(b, col)| {
            let mut acc = vec![0.0f64; ks];
            let (bi, bj) = (b / gn, b % gn);
            for i in bi * bm..((bi + 1) * bm).min(m) {
                for j in bj * bn..((bj + 1) * bn).min(n) {
                    let p = i * n + j;
                    for (a, v) in acc.iter_mut().zip(&fine[p * ks..(p + 1) * ks]) {
                        *a += v.as_f64();
                    }
                }
            }
            for (c, a) in col.iter_mut().zip(acc) {
                *c = T::of_f64(a);
            }
        });
    }

    /// Block b's summed codes of code set `set`.
    fn block_codes(&self, set: usize, b: usize) -> &[i8] {
        let blocks = self.grid.0 * self.grid.1;
        &self.codes[(set * blocks + b) * self.k..][..self.k]
    }

    /// The weight of row `row` (1 when A's rows are not weighted).
    fn row_weight(&self, row: usize) -> f64 {
        self.weights.as_ref().map_or(1.0, |w| w[row])
    }

    /// Σ_sets Σ_t c_B[d + t]²·w[d + t]²·p[t]·q[t + lag] over the overlap, for block b, depth d
    /// (w the row weights of the set's rows, 1 when unweighted).
    fn weighted(&self, b: usize, d: usize, lag: isize, q: &[f64]) -> f64 {
        let kp = self.pulse.len() as isize;
        let lo = 0.max(-lag);
        let hi = kp.min(kp - lag);
        (0..self.sets)
            .map(|set| {
                let c = &self.block_codes(set, b)[d..];
                (lo..hi)
                    .map(|t| {
                        let t = t as usize;
                        let w = f64::from(c[t]) * self.row_weight(set * self.k + d + t);
                        w * w * self.pulse[t] * q[(t as isize + lag) as usize]
                    })
                    .sum::<f64>()
            })
            .sum()
    }
}

impl<T: Real> std::fmt::Debug for BlockOperator<'_, T> {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("BlockOperator")
            .field("block", &self.block)
            .field("grid", &self.grid)
            .finish()
    }
}

impl<T: Real> LinearOperator<T> for BlockOperator<'_, T> {
    fn nrows(&self) -> usize {
        self.op.nrows()
    }

    fn ncols(&self) -> usize {
        self.grid.0 * self.grid.1 * self.ks()
    }

    fn forward_kernel(&self, x: &[T], y: &mut [T], _: &mut [T]) {
        let mut fine = vec![T::zero(); self.op.ncols()];
        self.upsample(x, &mut fine);
        self.op.apply(&fine, y);
    }

    fn adjoint_kernel(&self, y: &[T], x: &mut [T], _: &mut [T]) {
        let mut fine = vec![T::zero(); self.op.ncols()];
        self.op.apply_adjoint(y, &mut fine);
        self.sum_blocks(&fine, x);
    }

    fn restrict_columns(&self, columns: Vec<usize>) -> Result<Box<dyn LinearOperator<T> + '_>> {
        let n = self.ncols();
        if let Some(&bad) = columns.iter().find(|&&c| c >= n) {
            return Err(Error::IndexOutOfBounds {
                context: "support voxels",
                index: bad,
                len: n,
            });
        }
        Ok(Box::new(BlockSupport {
            op: self,
            voxels: columns,
        }))
    }

    fn describe(&self) -> String {
        format!(
            "BlockOperator({}×{} blocks of {})",
            self.block.0,
            self.block.1,
            self.op.describe()
        )
    }
}

impl<T: Real> VoxelOperator<T> for BlockOperator<'_, T> {
    fn column_len(&self) -> usize {
        self.ks()
    }

    /// The fine operator's correlation (the debiased one of the lidar operator), summed over
    /// each block's pixels.
    fn correlate(&self, r: &[T], u: &mut [T]) {
        let mut fine = vec![T::zero(); self.op.ncols()];
        self.op.correlate(r, &mut fine);
        self.sum_blocks(&fine, u);
    }

    fn self_correlations(&self, voxels: &[usize]) -> Vec<f64> {
        let ks = self.ks();
        voxels
            .par_iter()
            .flat_map_iter(|&v| {
                let (b, d) = (v / ks, v % ks);
                (0..ks)
                    .map(|j| self.weighted(b, d, d as isize - j as isize, &self.pulse0))
                    .collect::<Vec<_>>()
            })
            .collect()
    }

    /// The pulse's autocorrelation scaled by the block's mean squared code: the expected Gram
    /// block (exact on the diagonal up to the codes' fluctuation over the pulse).
    fn pixel_gram(&self, pixel: usize) -> Vec<f64> {
        let ks = self.ks();
        let scale = self.power[pixel];
        (0..ks * ks)
            .map(|i| scale * self.lags[(i / ks).abs_diff(i % ks)])
            .collect()
    }

    fn structured_columns(&self) -> bool {
        true
    }

    /// The code sets' columns in their blocks of rows, from the first set's row d.
    fn column(&self, c: usize) -> (usize, Vec<f64>) {
        let ks = self.ks();
        let (b, d) = (c / ks, c % ks);
        let kp = self.pulse.len();
        let mut values = vec![0.0; (self.sets - 1) * self.k + kp];
        for set in 0..self.sets {
            let codes = &self.block_codes(set, b)[d..];
            let out = &mut values[set * self.k..set * self.k + kp];
            for (t, ((o, v), &s)) in out.iter_mut().zip(&self.pulse).zip(codes).enumerate() {
                *o = f64::from(s) * v * self.row_weight(set * self.k + d + t);
            }
        }
        (d, values)
    }

    fn column_norms(&self, columns: &[usize]) -> Vec<f64> {
        let ks = self.ks();
        columns
            .par_iter()
            .map(|&v| self.weighted(v / ks, v % ks, 0, &self.pulse).sqrt())
            .collect()
    }
}

/// [`BlockOperator`] restricted to a set of its voxels.
struct BlockSupport<'b, 'a, T: Real> {
    op: &'b BlockOperator<'a, T>,
    voxels: Vec<usize>,
}

impl<T: Real> LinearOperator<T> for BlockSupport<'_, '_, T> {
    fn nrows(&self) -> usize {
        self.op.nrows()
    }

    fn ncols(&self) -> usize {
        self.voxels.len()
    }

    fn forward_kernel(&self, x: &[T], y: &mut [T], _: &mut [T]) {
        let ks = self.op.ks();
        let rows = y.len();
        let (sets, k) = (self.op.sets, self.op.k);
        let kp = self.op.pulse.len();
        // Chunks of voxels that depend on the support alone, their sums added in their order:
        // the same values for any number of threads.
        let chunk = self.voxels.len().div_ceil(SUPPORT_CHUNKS).max(1);
        let partial: Vec<Vec<f64>> = self
            .voxels
            .par_chunks(chunk)
            .zip(x.par_chunks(chunk))
            .map(|(vs, xs)| {
                let mut acc = vec![0.0f64; rows];
                for (&v, &a) in vs.iter().zip(xs) {
                    let a = a.as_f64();
                    if a == 0.0 {
                        continue;
                    }
                    let (b, d) = (v / ks, v % ks);
                    for set in 0..sets {
                        let c = &self.op.block_codes(set, b)[d..d + kp];
                        let out = &mut acc[set * k + d..set * k + d + kp];
                        for ((s, &ct), &pt) in out.iter_mut().zip(c).zip(&self.op.pulse) {
                            *s += a * f64::from(ct) * pt;
                        }
                    }
                }
                acc
            })
            .collect();
        let mut sums = vec![0.0f64; rows];
        for part in partial {
            for (u, v) in sums.iter_mut().zip(part) {
                *u += v;
            }
        }
        for (i, (yi, s)) in y.iter_mut().zip(sums).enumerate() {
            *yi = T::of_f64(s * self.op.row_weight(i));
        }
    }

    fn adjoint_kernel(&self, y: &[T], x: &mut [T], _: &mut [T]) {
        let ks = self.op.ks();
        let kp = self.op.pulse.len();
        let (sets, k) = (self.op.sets, self.op.k);
        // The measurements weighted once, as A's rows are (none when unweighted).
        let weighted: Option<Vec<f64>> = self
            .op
            .weights
            .as_ref()
            .map(|w| y.iter().zip(w).map(|(v, w)| v.as_f64() * w).collect());
        let yt = |row: usize| {
            weighted
                .as_ref()
                .map_or_else(|| y[row].as_f64(), |z| z[row])
        };
        x.par_iter_mut().zip(&self.voxels).for_each(|(xi, &v)| {
            let (b, d) = (v / ks, v % ks);
            let s: f64 = (0..sets)
                .map(|set| {
                    let c = &self.op.block_codes(set, b)[d..d + kp];
                    c.iter()
                        .zip(&self.op.pulse)
                        .enumerate()
                        .map(|(t, (&ct, &pt))| f64::from(ct) * pt * yt(set * k + d + t))
                        .sum::<f64>()
                })
                .sum();
            *xi = T::of_f64(s);
        });
    }

    fn describe(&self) -> String {
        format!(
            "BlockSupport({} voxels of {})",
            self.voxels.len(),
            self.op.describe()
        )
    }
}
