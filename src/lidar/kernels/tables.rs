//! The forward's 256-row tables (generic and AVX2 paths): the signed subset sums of a group's
//! eight depth columns, one row per code byte.

use std::ops::Range;

use super::Lane;
use crate::real::Real;

/// Tabulates the groups `groups` for the slab of bins `j0 ..` (`nch` chunks of eight) of the
/// scene `x` (`npix` pixels of `ks` bins) into `tables`, 256·nch lanes per group: row b holds
/// Σ_i ±x[8g + i, j] (+ where bit i of b is set, − elsewhere) for binary codes, or the sum over
/// the set bits only for ternary codes. Each row is one vector addition from the row without its
/// lowest set bit. Pixels past `npix` and bins past the slab's end count as zero.
pub(crate) fn build_group_tables<T: Real>(
    x: &[T],
    (npix, ks): (usize, usize),
    binary: bool,
    groups: Range<usize>,
    j0: usize,
    nch: usize,
    tables: &mut [Lane<T>],
) {
    let two = T::one() + T::one();
    for (gi, g) in groups.enumerate() {
        // The group's eight depth columns restricted to the slab, as lanes.
        let mut cols = [[[T::zero(); 8]; 8]; 8];
        for (i, col) in cols.iter_mut().enumerate() {
            let p = 8 * g + i;
            if p >= npix {
                continue;
            }
            for jj in 0..(8 * nch).min(ks - j0) {
                col[jj / 8][jj % 8] = x[p * ks + j0 + jj];
            }
        }
        let t = &mut tables[gi * 256 * nch..(gi + 1) * 256 * nch];
        for c in 0..nch {
            let mut first = [T::zero(); 8];
            if binary {
                for col in &cols {
                    for l in 0..8 {
                        first[l] = first[l] - col[c][l];
                    }
                }
            }
            t[c] = first;
        }
        for b in 1..256usize {
            let prev = (b & (b - 1)) * nch;
            let i = b.trailing_zeros() as usize;
            for c in 0..nch {
                let mut row = t[prev + c];
                for l in 0..8 {
                    row[l] = if binary {
                        row[l] + two * cols[i][c][l]
                    } else {
                        row[l] + cols[i][c][l]
                    };
                }
                t[b * nch + c] = row;
            }
        }
    }
}
