//! The generic probe of what the caches deliver to the table kernels: rows of chunks of eight
//! values summed at random from a table, as [`gather_limit`](crate::lidar::gather_limit)
//! measures them where the wide kernels do not run ([`gather_rows_wide`] where they do).
//!
//! [`gather_rows_wide`]: super::quads::gather_rows_wide

use super::{add8, Isa, Lane};
use crate::real::Real;

/// out += Σ of the rows of `table` (NCH lanes each) that `index` lists, in four interleaved
/// partial sums: the table kernels' memory access and additions without their bookkeeping.
#[inline(always)]
fn gather_rows_n<T: Real, const NCH: usize>(table: &[Lane<T>], index: &[u16], out: &mut [Lane<T>]) {
    let zero = [T::zero(); 8];
    let mut acc = [[zero; NCH]; 4];
    for quad in index.chunks(4) {
        for (a, &r) in acc.iter_mut().zip(quad) {
            let r = r as usize * NCH;
            let row: &[Lane<T>; NCH] = table[r..r + NCH].try_into().expect("NCH lanes");
            for c in 0..NCH {
                a[c] = add8(a[c], row[c]);
            }
        }
    }
    for (c, o) in out.iter_mut().enumerate().take(NCH) {
        *o = add8(
            *o,
            add8(add8(acc[0][c], acc[1][c]), add8(acc[2][c], acc[3][c])),
        );
    }
}

multiversion!(fn gather_rows_isa<T, const NCH: usize>(table: &[Lane<T>], index: &[u16], out: &mut [Lane<T>]) => gather_rows_n);

/// Runs the row-gathering probe ([`gather_rows_n`]) for rows of `nch` chunks.
pub(crate) fn gather_rows<T: Real>(
    isa: Isa,
    nch: usize,
    table: &[Lane<T>],
    index: &[u16],
    out: &mut [Lane<T>],
) {
    match nch {
        1 => gather_rows_isa::<T, 1>(isa, table, index, out),
        2 => gather_rows_isa::<T, 2>(isa, table, index, out),
        3 => gather_rows_isa::<T, 3>(isa, table, index, out),
        4 => gather_rows_isa::<T, 4>(isa, table, index, out),
        5 => gather_rows_isa::<T, 5>(isa, table, index, out),
        6 => gather_rows_isa::<T, 6>(isa, table, index, out),
        7 => gather_rows_isa::<T, 7>(isa, table, index, out),
        8 => gather_rows_isa::<T, 8>(isa, table, index, out),
        _ => unreachable!("rows have 1 to 8 chunks"),
    }
}
