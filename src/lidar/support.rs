//! The measurement operator restricted to a set of voxels: A·Rᵀ with forward and adjoint in
//! O(|S|·K_p), for solvers that work on a support (least squares on candidate depths).

use rayon::prelude::*;

use crate::error::{Error, Result};
use crate::operator::LinearOperator;
use crate::real::Real;

use super::rdop::RdOperator;

/// `A·Rᵀ` for a set S of voxels: the input holds one amplitude per voxel of S (in the order
/// given), the output is the K measurements. Equivalent to
/// `op.compose(Restriction::new(n, S)?.adjoint())`, but both directions cost O(|S|·K_p) instead of
/// a full adjoint: the forward adds each voxel's modulated, shifted pulse, the adjoint correlates
/// the measurements with it (sums over K_p samples accumulated in `f64`).
#[derive(Debug)]
pub struct SupportOperator<'a, T: Real> {
    op: &'a RdOperator<T>,
    voxels: Vec<usize>,
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
        Ok(SupportOperator { op, voxels })
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
        x.par_iter_mut()
            .zip(self.voxels.par_iter())
            .for_each(|(xv, &v)| {
                let (p, j) = (v / ks, v % ks);
                let bit = (p % 8) as u32;
                let plus = &codes.plus_group(p / 8)[j..j + kp];
                let minus = codes.minus_group(p / 8).map(|m| &m[j..j + kp]);
                let ys = &y[j..j + kp];
                let mut acc = 0.0f64;
                // Blocks of 256 samples summed in the working precision, then in f64.
                for start in (0..kp).step_by(256) {
                    let end = (start + 256).min(kp);
                    let mut s = T::zero();
                    for t in start..end {
                        let c = ((plus[t] >> bit) & 1) as i32
                            - minus.map_or(1 - ((plus[t] >> bit) & 1) as i32, |m| {
                                ((m[t] >> bit) & 1) as i32
                            });
                        let w = ys[t] * pulse[t];
                        s = s + if c > 0 {
                            w
                        } else if c < 0 {
                            -w
                        } else {
                            T::zero()
                        };
                    }
                    acc += s.as_f64();
                }
                *xv = T::of_f64(acc);
            });
    }

    fn describe(&self) -> String {
        format!(
            "SupportOperator({} voxels of {})",
            self.voxels.len(),
            self.op.describe()
        )
    }
}
