//! The 256-row tables: the forward's (generic and AVX2 paths), the signed subset sums of a
//! group's eight depth columns, one row per code byte; and the adjoint's, the signed subset sums
//! of an octet's eight samples, one row per code byte.

use std::ops::Range;

use super::{add8, lane_at, octet_stride, scale8, sub8, AdjChunk, Isa, Lane, ADJ_OCTETS};
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

/// The tables of a chunk: for octet o and byte b, Σ_t ±w_t (binary codes: + where bit t of b is
/// set, − elsewhere) or Σ_{t ∈ b} w_t (ternary codes), where w_t = y[k]·p[k − j], k = 8·o + t,
/// is the row every pixel's backprojection adds with its code's sign at sample k. Each table is
/// built by doubling: row additions from its first row; for binary codes only the rows below
/// 128, each row b from 128 on being the negated row ¬b (the complement of b: every sign
/// flipped), so that row ¬b = −row b exactly and a kernel may read either. With `upper` false
/// those negated rows are not written (for kernels that read the rows below 128 only).
#[inline(always)]
fn adj_tables<T: Real, const NCH: usize>(a: &AdjChunk<'_, T>, tables: &mut [Lane<T>], upper: bool) {
    let zero = [T::zero(); 8];
    let binary = a.minus.is_none();
    let k = a.y.len();
    for (oi, o) in (a.first_octet..a.first_octet + ADJ_OCTETS).enumerate() {
        let mut w = [[zero; NCH]; 8];
        let mut first = [zero; NCH];
        for (t, wt) in w.iter_mut().enumerate() {
            let kk = 8 * o + t;
            if kk >= k || a.y[kk] == T::zero() {
                continue;
            }
            let w0 = a.base0 - kk;
            for c in 0..NCH {
                wt[c] = scale8(a.y[kk], lane_at(a.prev, w0 + 8 * c));
                if binary {
                    first[c] = sub8(first[c], wt[c]);
                    wt[c] = add8(wt[c], wt[c]);
                }
            }
        }
        let t = &mut tables[oi * octet_stride::<T>(NCH)..][..256 * NCH];
        t[..NCH].copy_from_slice(&first);
        // Row b is row b − 2^z plus w_z, z the lowest set bit of b: the same additions of the
        // same rows in any order that has each row's earlier one ready. By blocks of 64 rows
        // (in L1), and in each block by z from the highest, so that w_z is read once for all
        // the rows that add it.
        let built: usize = if binary { 128 } else { 256 };
        for block in (0..built).step_by(64) {
            if block > 0 {
                let z = block.trailing_zeros() as usize;
                let wz = w[z];
                for c in 0..NCH {
                    t[block * NCH + c] = add8(t[(block - (1 << z)) * NCH + c], wz[c]);
                }
            }
            for z in (0..6).rev() {
                let wz = w[z];
                for b in ((block + (1 << z))..block + 64).step_by(2 << z) {
                    let from = (b - (1 << z)) * NCH;
                    for c in 0..NCH {
                        t[b * NCH + c] = add8(t[from + c], wz[c]);
                    }
                }
            }
        }
        if binary && upper {
            let (lower, high) = t.split_at_mut(128 * NCH);
            for (i, row) in high.chunks_exact_mut(NCH).enumerate() {
                let from = &lower[(127 - i) * NCH..][..NCH];
                for (r, f) in row.iter_mut().zip(from) {
                    *r = f.map(|v| -v);
                }
            }
        }
    }
}

multiversion!(fn adj_tables_isa<T, const NCH: usize>(a: &AdjChunk<'_, T>, tables: &mut [Lane<T>], upper: bool) => adj_tables);

/// Builds a chunk's tables ([`adj_tables`]) for rows of `nch` chunks, in a function of its own
/// for each instruction set: compiled apart from the loops that read the tables, so that a change
/// to either leaves the other's machine code as it was. With `upper` false the negated rows of
/// binary codes (128 on) are left unwritten.
pub(crate) fn adjoint_tables<T: Real>(
    isa: Isa,
    nch: usize,
    a: &AdjChunk<'_, T>,
    tables: &mut [Lane<T>],
    upper: bool,
) {
    match nch {
        1 => adj_tables_isa::<T, 1>(isa, a, tables, upper),
        2 => adj_tables_isa::<T, 2>(isa, a, tables, upper),
        3 => adj_tables_isa::<T, 3>(isa, a, tables, upper),
        4 => adj_tables_isa::<T, 4>(isa, a, tables, upper),
        5 => adj_tables_isa::<T, 5>(isa, a, tables, upper),
        6 => adj_tables_isa::<T, 6>(isa, a, tables, upper),
        7 => adj_tables_isa::<T, 7>(isa, a, tables, upper),
        8 => adj_tables_isa::<T, 8>(isa, a, tables, upper),
        _ => unreachable!("rows have 1 to 8 chunks"),
    }
}
