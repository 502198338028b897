//! Forward differences on a 2-D grid: the discrete gradient used by total variation.

use std::marker::PhantomData;

use crate::error::{Error, Result};
use crate::real::Real;

use super::LinearOperator;

/// The discrete gradient ∇ of an `m × n` image stored in row-major order (`x[i·n + j]`).
///
/// The output has length `2·m·n`: first the vertical differences
/// `g₀[i, j] = x[i+1, j] − x[i, j]` (zero on the last row), then the horizontal differences
/// `g₁[i, j] = x[i, j+1] − x[i, j]` (zero on the last column). These are the Neumann-boundary forward
/// differences of Chambolle's TV algorithms; the adjoint is the negative divergence, ∇* = −div.
#[derive(Debug, Clone, Copy)]
pub struct Gradient2D<T> {
    m: usize,
    n: usize,
    _t: PhantomData<T>,
}

impl<T: Real> Gradient2D<T> {
    /// The gradient on an `m × n` grid.
    ///
    /// # Errors
    /// [`Error::InvalidParameter`] if `m` or `n` is zero.
    pub fn new(m: usize, n: usize) -> Result<Self> {
        if m == 0 || n == 0 {
            return Err(Error::param(
                "grid",
                format!("gradient grid must be non-empty, got {m}x{n}"),
            ));
        }
        Ok(Gradient2D {
            m,
            n,
            _t: PhantomData,
        })
    }

    /// The grid shape `(m, n)`.
    pub fn grid(&self) -> (usize, usize) {
        (self.m, self.n)
    }
}

impl<T: Real> LinearOperator<T> for Gradient2D<T> {
    fn nrows(&self) -> usize {
        2 * self.m * self.n
    }
    fn ncols(&self) -> usize {
        self.m * self.n
    }
    fn forward_kernel(&self, x: &[T], y: &mut [T], _: &mut [T]) {
        let (m, n) = (self.m, self.n);
        let (gv, gh) = y.split_at_mut(m * n);
        for i in 0..m {
            let row = &x[i * n..(i + 1) * n];
            let out_v = &mut gv[i * n..(i + 1) * n];
            if i + 1 < m {
                let next = &x[(i + 1) * n..(i + 2) * n];
                for ((o, &a), &b) in out_v.iter_mut().zip(row).zip(next) {
                    *o = b - a;
                }
            } else {
                out_v.fill(T::zero());
            }
            let out_h = &mut gh[i * n..(i + 1) * n];
            for j in 0..n - 1 {
                out_h[j] = row[j + 1] - row[j];
            }
            out_h[n - 1] = T::zero();
        }
    }
    fn adjoint_kernel(&self, y: &[T], x: &mut [T], _: &mut [T]) {
        // x = −div(g): each difference b − a sends +g to b and −g to a. Row by row, so that the
        // inner loops are branch-free and contiguous.
        let (m, n) = (self.m, self.n);
        let (gv, gh) = y.split_at(m * n);
        for i in 0..m {
            let xr = &mut x[i * n..(i + 1) * n];
            let hr = &gh[i * n..(i + 1) * n];
            // Horizontal part: x[j] = g[j − 1]·[j > 0] − g[j]·[j < n − 1].
            xr[0] = -hr[0];
            for j in 1..n {
                xr[j] = hr[j - 1] - hr[j];
            }
            xr[n - 1] = xr[n - 1] + hr[n - 1];
            // Vertical part: + g[i − 1] for i > 0, − g[i] for i < m − 1.
            if i + 1 < m {
                for (xv, &g) in xr.iter_mut().zip(&gv[i * n..(i + 1) * n]) {
                    *xv = *xv - g;
                }
            }
            if i > 0 {
                for (xv, &g) in xr.iter_mut().zip(&gv[(i - 1) * n..i * n]) {
                    *xv = *xv + g;
                }
            }
        }
    }
    fn describe(&self) -> String {
        format!("Gradient2D({}x{})", self.m, self.n)
    }
}
