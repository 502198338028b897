//! What one application of [`RdOperator`] holds and does: the bytes of its codes and working
//! buffers, the additions and table bytes of its dense kernels, and what this machine's caches
//! deliver to a kernel of that access pattern (the limit the kernels are measured against).

use std::time::Instant;

use rand::{RngExt, SeedableRng};
use rayon::prelude::*;
use serde::Serialize;

use crate::error::{Error, Result};
use crate::real::Real;

use super::codes::CodeAlphabet;
use super::geometry::Geometry;
use super::kernels::adjoint_wide::{vector_row_nch, wide_adjoint_nch};
use super::kernels::quads::{gather_rows_wide, lines_as_mut, quad_row_read, CacheLine, QUAD_ROWS};
use super::kernels::{gather_rows, octet_stride, Isa, Lane, ADJ_OCTETS};
use super::rdop::{
    adjoint_groups_per_block, depth_slabs, groups_per_block, RdOperator, ADJ_BLOCK_BYTES,
    BLOCK_BYTES,
};

/// The work of one application of a dense kernel.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct KernelWork {
    /// Additions of table values: one per depth bin of every row looked up, and one per value
    /// of every table built.
    pub additions: f64,
    /// Bytes of table rows read by the lookups (rows padded to whole chunks of eight values; on
    /// AVX-512 to whole 512-bit vectors, but see [`RdOperator::adjoint_row_bytes`]).
    pub table_bytes: f64,
}

impl KernelWork {
    /// Additions per second for an application taking `seconds`.
    pub fn additions_per_s(&self, seconds: f64) -> f64 {
        self.additions / seconds
    }

    /// Table bytes read per second for an application taking `seconds`.
    pub fn table_bytes_per_s(&self, seconds: f64) -> f64 {
        self.table_bytes / seconds
    }
}

/// The work of [`RdOperator`]'s dense forward and adjoint.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct OperatorWork {
    /// The dense forward: one row of a group's table per group and sample (two for ternary
    /// codes), 256 rows tabulated per group; with the quad tables (AVX-512), two rows per group
    /// and sample (four for ternary codes), 2 × 16 rows tabulated per group, each row padded to
    /// whole cache lines.
    pub forward: KernelWork,
    /// The adjoint: one row of an octet's table per pixel and octet of samples (two for ternary
    /// codes), 256 rows tabulated per octet and block of pixels.
    pub adjoint: KernelWork,
}

impl<T: Real> RdOperator<T> {
    /// Bytes held by the operator: codes, pulse and the working buffers of one application per
    /// thread (of the current rayon pool).
    pub fn memory_bytes(&self) -> usize {
        let threads = rayon::current_num_threads();
        // The operator exists, so its own sizes fit; only an absurd thread count could overflow.
        Self::estimated_memory_bytes(
            self.geometry(),
            self.pulse().len(),
            self.codes().alphabet(),
            threads,
        )
        .unwrap_or(usize::MAX)
    }

    /// The bytes [`memory_bytes`](Self::memory_bytes) would report for an operator on `geom`
    /// with a pulse of `pulse_len` samples, codes of `alphabet` and `threads` worker threads,
    /// computed without building it: the packed codes (⌈M·N/8⌉·K bytes per bit plane), the
    /// pulse twice (as given and reversed, padded), and per thread the forward's `f64`
    /// accumulator and lane partial sums of K samples, one block of its lookup tables, and the
    /// adjoint's tables of one chunk of samples and partial sums of one block of pixels.
    ///
    /// # Errors
    /// [`Error::InvalidParameter`] if `pulse_len` or `threads` is zero, or if the count does not
    /// fit in `usize`.
    pub fn estimated_memory_bytes(
        geom: Geometry,
        pulse_len: usize,
        alphabet: CodeAlphabet,
        threads: usize,
    ) -> Result<usize> {
        if pulse_len == 0 {
            return Err(Error::param("pulse_len", "must be at least 1"));
        }
        if threads == 0 {
            return Err(Error::param("threads", "must be at least 1"));
        }
        let overflow = || {
            Error::param(
                "pulse_len",
                format!("the operator's memory for {geom} and K_p = {pulse_len} overflows usize"),
            )
        };
        let size = std::mem::size_of::<T>();
        let slabs = depth_slabs(geom.ks);
        let ks_pad = slabs.last().map_or(0, |&(j0, nch)| j0 + 8 * nch + 8);
        let max_nch = slabs.iter().map(|s| s.1).max().unwrap_or(1);
        let block_groups = groups_per_block::<T>(BLOCK_BYTES, max_nch);
        let planes = match alphabet {
            CodeAlphabet::Binary => 1,
            CodeAlphabet::Ternary => 2,
        };
        let k = pulse_len.checked_add(geom.ks - 1).ok_or_else(overflow)?;
        let codes = geom
            .pixels()
            .div_ceil(8)
            .checked_mul(k)
            .and_then(|v| v.checked_mul(planes))
            .ok_or_else(overflow)?;
        let pulses = pulse_len
            .checked_mul(2)
            .and_then(|v| v.checked_add(geom.ks + ks_pad))
            .and_then(|v| v.checked_mul(size))
            .ok_or_else(overflow)?;
        // The forward's block of 256-row tables (larger than a block of quad tables); the
        // adjoint's rows as wide as on AVX-512 (whole vectors): an upper bound for every path.
        let tables = block_groups * 256 * max_nch * 8 * size;
        // The adjoint's block: a chunk's tables (rows of whole vectors), and the block's partial
        // sums in `T` and `f64` (the slab's bins).
        let adjoint = ADJ_OCTETS * octet_stride::<T>(wide_adjoint_nch::<T>(max_nch)) * 8 * size
            + adjoint_groups_per_block::<T>(ADJ_BLOCK_BYTES, max_nch)
                * 8
                * max_nch
                * 8
                * (size + 8);
        let per_task = k
            .checked_mul(8 + 8 * size)
            .and_then(|v| v.checked_add(tables + adjoint))
            .ok_or_else(overflow)?;
        threads
            .checked_mul(per_task)
            .and_then(|v| v.checked_add(codes))
            .and_then(|v| v.checked_add(pulses))
            .ok_or_else(overflow)
    }

    /// Bytes of one row of the adjoint's tables for a depth slab of `8·nch` bins (1 ≤ `nch` ≤ 8)
    /// as the kernels read it: the slab's values in chunks of eight, on AVX-512 widened to whole
    /// 512-bit vectors, except `f32` rows on processors that execute 512-bit operations in two
    /// halves (AMD's family 19h, Zen 4), which the 256-bit kernel reads at the slab's width.
    pub fn adjoint_row_bytes(&self, nch: usize) -> usize {
        8 * self.adjoint_nch(nch) * std::mem::size_of::<T>()
    }

    /// The additions and table bytes of one dense forward and one adjoint (with the threads of
    /// the current rayon pool, which set the adjoint's blocks).
    pub fn work(&self) -> OperatorWork {
        let g = self.geometry();
        let (ks, size) = (g.ks as f64, std::mem::size_of::<T>() as f64);
        let ks_pad = self.slabs().iter().map(|s| 8 * s.1).sum::<usize>() as f64;
        let planes = match self.codes().alphabet() {
            CodeAlphabet::Binary => 1.0,
            CodeAlphabet::Ternary => 2.0,
        };
        let groups = self.codes().groups() as f64;
        let k = self.codes().len() as f64;
        let octets = self.codes().len().div_ceil(8) as f64;
        let blocks = self.codes().groups().div_ceil(self.adjoint_block_groups()) as f64;
        let adjoint_lookups = 8.0 * groups * octets * planes;
        let adjoint_row = self
            .slabs()
            .iter()
            .map(|s| 8 * self.adjoint_nch(s.1))
            .sum::<usize>() as f64;
        let forward = if self.forward_uses_quads() {
            let row = self
                .slabs()
                .iter()
                .map(|s| quad_row_read::<T>(s.1, (8 * s.1).min(g.ks - s.0)))
                .sum::<usize>();
            let lookups = 2.0 * groups * k * planes;
            KernelWork {
                additions: lookups * ks + groups * 2.0 * QUAD_ROWS as f64 * ks,
                table_bytes: lookups * row as f64 * size,
            }
        } else {
            let lookups = groups * k * planes;
            KernelWork {
                additions: lookups * ks + groups * 256.0 * ks,
                table_bytes: lookups * ks_pad * size,
            }
        };
        OperatorWork {
            forward,
            adjoint: KernelWork {
                additions: adjoint_lookups * ks + blocks * octets * 256.0 * ks,
                table_bytes: adjoint_lookups * adjoint_row * size,
            },
        }
    }
}

/// What a cache level delivers to the table kernels' access pattern: rows of `8·nch` values of
/// `T` (on AVX-512 padded to whole 512-bit vectors and summed in them, as the wide kernels do; on
/// AVX2 summed in 256-bit vectors)
/// read at random from a table of `table_bytes` (one per thread of the current rayon pool) and
/// summed, with the kernels' instruction set. The additions count the `8·nch` values of a row.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct GatherLimit {
    /// Bytes of each thread's table.
    pub table_bytes: usize,
    /// Bytes of one row.
    pub row_bytes: usize,
    /// Rows read per second, all threads together (the median of the timed runs).
    pub rows_per_s: f64,
    /// Bytes read per second, all threads together.
    pub bytes_per_s: f64,
    /// Values added per second, all threads together.
    pub additions_per_s: f64,
}

impl GatherLimit {
    /// The limit for `rows` rows of `row_bytes` each (of which `8·nch` values are added) read at
    /// `rows_per_s`.
    fn of(rows: usize, row_bytes: usize, nch: usize, rows_per_s: f64) -> GatherLimit {
        GatherLimit {
            table_bytes: rows * row_bytes,
            row_bytes,
            rows_per_s,
            bytes_per_s: rows_per_s * row_bytes as f64,
            additions_per_s: rows_per_s * (8 * nch) as f64,
        }
    }
}

/// Measures [`GatherLimit`] for rows of `nch` chunks of eight values (1 … 8) in tables of about
/// `table_bytes` per thread (with the wide kernels a power of two of rows, between half of it and
/// all of it), `repeats` timed runs of 2²⁰ rows per thread after a warm-up.
///
/// # Errors
/// [`Error::InvalidParameter`] (`nch`, `repeats`) for a chunk count outside 1 … 8 or no runs,
/// and for `RDLIDAR_ISA` as [`RdOperator::new`].
pub fn gather_limit<T: Real>(
    nch: usize,
    table_bytes: usize,
    repeats: usize,
) -> Result<GatherLimit> {
    if !(1..=8).contains(&nch) {
        return Err(Error::param("nch", format!("{nch} is not between 1 and 8")));
    }
    if repeats == 0 {
        return Err(Error::param("repeats", "must be at least 1"));
    }
    let isa = Isa::chosen()?;
    if isa.has_wide() {
        return gather_limit_wide::<T>(isa, nch, table_bytes, repeats);
    }
    let row_bytes = nch * std::mem::size_of::<Lane<T>>();
    let rows = (table_bytes / row_bytes).clamp(2, 1 << 16);
    let threads = rayon::current_num_threads().max(1);
    let setup: Vec<(Vec<Lane<T>>, Vec<u16>)> = (0..threads)
        .map(|t| {
            let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(t as u64);
            let table = (0..rows * nch)
                .map(|_| std::array::from_fn(|_| T::of_f64(rng.random_range(-1.0..1.0))))
                .collect();
            let index = (0..GATHER_READS)
                .map(|_| rng.random_range(0..rows) as u16)
                .collect();
            (table, index)
        })
        .collect();
    let run = || {
        let sums: Vec<f64> = setup
            .par_iter()
            .map(|(table, index)| {
                let mut out = vec![[T::zero(); 8]; nch];
                gather_rows(isa, nch, table, index, &mut out);
                out.iter().flatten().map(|v| v.as_f64()).sum()
            })
            .collect();
        std::hint::black_box(sums);
    };
    let rows_per_s = (threads * GATHER_READS) as f64 / median_seconds(run, repeats);
    Ok(GatherLimit::of(rows, row_bytes, nch, rows_per_s))
}

/// Rows each thread of the gather probe reads per run.
const GATHER_READS: usize = 1 << 20;

/// The median time of `repeats` runs of `run`, after one to warm up.
fn median_seconds(run: impl Fn(), repeats: usize) -> f64 {
    run();
    let mut times: Vec<f64> = (0..repeats)
        .map(|_| {
            let t0 = Instant::now();
            run();
            t0.elapsed().as_secs_f64()
        })
        .collect();
    times.sort_by(f64::total_cmp);
    times[times.len() / 2].max(f64::MIN_POSITIVE)
}

/// [`gather_limit`] with the wide kernels: rows of their width (on AVX-512 `8·nch` values rounded
/// up to whole 512-bit vectors, on cache lines; on AVX2 `8·nch` values, a chunk a 256-bit vector
/// of `f32`), a power of two of them within `table_bytes`, summed in vectors
/// ([`gather_rows_wide`]).
fn gather_limit_wide<T: Real>(
    isa: Isa,
    nch: usize,
    table_bytes: usize,
    repeats: usize,
) -> Result<GatherLimit> {
    // The wide kernels' rows: whole 512-bit vectors on AVX-512 (the quad rows' width too).
    let rl = 8 * vector_row_nch::<T>(isa, nch);
    let row_bytes = rl * std::mem::size_of::<T>();
    let rows = prev_power_of_two((table_bytes / row_bytes).clamp(2, 1 << 16));
    let threads = rayon::current_num_threads().max(1);
    let mut setup: Vec<(Vec<CacheLine>, Vec<u16>)> = (0..threads)
        .map(|t| {
            let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(t as u64);
            let mut lines = vec![CacheLine::default(); rows * row_bytes / 64];
            for v in lines_as_mut::<T>(&mut lines) {
                *v = T::of_f64(rng.random_range(-1.0..1.0));
            }
            let index = (0..GATHER_READS)
                .map(|_| rng.random_range(0..rows) as u16)
                .collect();
            (lines, index)
        })
        .collect();
    let tables: Vec<(&[T], &[u16])> = setup
        .iter_mut()
        .map(|(lines, index)| (&*lines_as_mut::<T>(lines), index.as_slice()))
        .collect();
    let run = || {
        let sums: Vec<f64> = tables
            .par_iter()
            .map(|&(table, index)| {
                let mut out = vec![T::zero(); rl];
                gather_rows_wide(isa, rl, table, index, &mut out);
                out.iter().map(|v| v.as_f64()).sum()
            })
            .collect();
        std::hint::black_box(sums);
    };
    let rows_per_s = (threads * GATHER_READS) as f64 / median_seconds(run, repeats);
    Ok(GatherLimit::of(rows, row_bytes, nch, rows_per_s))
}

/// The largest power of two not above `n` (n ≥ 1).
fn prev_power_of_two(n: usize) -> usize {
    1 << (usize::BITS - 1 - n.leading_zeros())
}
