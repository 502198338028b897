//! The fused random-demodulation operator A = Σ·S·P (the same operator composed from the generic
//! algebra, the reference, is in `composed.rs`).

use std::sync::{Arc, Mutex, OnceLock};

use rayon::prelude::*;

use crate::error::{Error, Result};
use crate::operator::LinearOperator;
use crate::real::Real;

use super::codes::Codes;
use super::geometry::Geometry;
use super::kernels::adjoint_wide::{adjoint_chunk_wide, adjoint_row_nch};
use super::kernels::quads::{
    build_quad_tables, lines_as_mut, quad_forward, quad_groups_per_block, quad_lines, CacheLine,
    QuadBlock,
};
use super::kernels::tables::build_group_tables;
use super::kernels::{
    adjoint_chunk, depth_entries_isa, depth_schedule, flush_into, forward_block, octet_stride,
    AdjChunk, Coded, FwdBlock, Isa, Lane, ADJ_OCTETS,
};
use super::pulse::single_pulse;

/// Largest slab of depth bins a kernel handles at once (8 lanes × 8 chunks).
const SLAB: usize = 64;
/// Cache budget (bytes) for the forward's tables of one block of groups.
pub(super) const BLOCK_BYTES: usize = 512 * 1024;
/// Cache budget (bytes) for the adjoint's per-pixel partial sums of one block of groups: they
/// are updated once per chunk of samples, so they should stay in the L2 cache beside the chunk's
/// tables.
pub(super) const ADJ_BLOCK_BYTES: usize = 1024 * 1024;
/// Chunks of [`ADJ_OCTETS`] octets whose adjoint partial sums are accumulated in `T` before they
/// are added to `f64` sums: 128 table rows (1024 samples) per sum.
const ADJ_FLUSH_CHUNKS: usize = 16;
/// Blocks whose lane partial sums are accumulated in `T` before a flush to `f64`.
const FLUSH_BLOCKS: usize = 8;
/// The dense forward's tasks at most (each holds K sums in `f64`).
const MAX_FORWARD_TASKS: usize = 64;
/// The dense forward's tasks over `blocks` blocks: one per [`FLUSH_BLOCKS`] blocks, at most
/// [`MAX_FORWARD_TASKS`], whatever the number of threads.
fn forward_tasks(blocks: usize) -> usize {
    blocks.div_ceil(FLUSH_BLOCKS).clamp(1, MAX_FORWARD_TASKS)
}

/// The depth slabs of K_s bins: (first bin, chunks of eight bins), at most [`SLAB`] bins each.
pub(super) fn depth_slabs(ks: usize) -> Vec<(usize, usize)> {
    let mut slabs = Vec::new();
    let mut j0 = 0;
    while j0 < ks {
        let width = (ks - j0).min(SLAB);
        slabs.push((j0, width.div_ceil(8)));
        j0 += width;
    }
    slabs
}

/// Groups of eight pixels per adjoint block: as many as have their partial sums (eight pixels
/// of `max_nch` chunks each) within `budget` bytes, at least one.
pub(super) fn adjoint_groups_per_block<T: Real>(budget: usize, max_nch: usize) -> usize {
    (budget / (8 * max_nch * std::mem::size_of::<Lane<T>>())).max(1)
}

/// Groups of eight pixels whose 256-row tables of `max_nch` chunks fit in `budget` bytes
/// (between 1 and 64).
pub(super) fn groups_per_block<T: Real>(budget: usize, max_nch: usize) -> usize {
    let table_bytes = 256 * 8 * max_nch * std::mem::size_of::<T>();
    (budget / table_bytes).clamp(1, 64)
}

/// How [`RdOperator`]'s forward product is evaluated.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum ForwardPath {
    /// Sparse when the scene has few nonzeros, dense otherwise (the default).
    Auto,
    /// Table lookups over all pixels: O(M·N·K·K_s / 8).
    Dense,
    /// One pass per nonzero voxel: O(nnz(x)·K_p).
    Sparse,
}

/// Reusable per-task buffers, so that repeated applications do not allocate.
#[derive(Default)]
struct Work<T> {
    y64: Vec<f64>,
    part: Vec<Lane<T>>,
    lanes: Vec<Lane<T>>,
    lines: Vec<CacheLine>,
}

struct Pool<T>(Mutex<Vec<Work<T>>>);

impl<T> Pool<T> {
    fn take(&self) -> Work<T>
    where
        T: Default,
    {
        self.0
            .lock()
            .map(|mut v| v.pop())
            .ok()
            .flatten()
            .unwrap_or_default()
    }
    fn give(&self, w: Work<T>) {
        if let Ok(mut v) = self.0.lock() {
            v.push(w);
        }
    }
}

fn resize<U: Copy>(v: &mut Vec<U>, len: usize, zero: U) {
    v.clear();
    v.resize(len, zero);
}

/// The measurement operator of the random-demodulation lidar, computed directly from bit-packed
/// codes (the fast formulation of docs/math.md §5, implemented as docs/lidar.md describes):
///
/// `y[k] = Σ_p s[p, k] · Σ_j x[p, j] · p[k − j]`,  k < K = K_p + K_s − 1,
///
/// with the scene x as the operator's input (C order, index `p·K_s + j` for pixel p = m·N + n).
///
/// **Forward.** Pixels are taken in groups of eight. For a block of groups and a slab of up to 64
/// depth bins, the 256 signed subset sums of each group's depth columns are tabulated; then for
/// every sample one table row per group (selected by the group's code byte) is added, and the
/// sum is weighted by the pulse window p[k − j] and accumulated in `f64`. One lookup replaces
/// eight additions of the equivalent matrix product, and the intermediate K × K_s matrix is never
/// stored. On AVX-512 each group is split into two quads of four pixels with 16-row tables
/// instead, so that a block's tables stay in the L1 cache: two rows per group and sample, each
/// read several times faster than a row of a 256-row table from L2
/// (docs/performance.md). Scenes with few nonzeros take a sparse path costing
/// O(nnz·K_p) (see [`ForwardPath`]).
///
/// **Adjoint.** The same tables, built along the samples instead of across the pixels: for a
/// chunk of eight octets (64 samples), the 256 signed subset sums of each octet's eight rows
/// `y[k]·p[k − j]` are tabulated once, and every pixel adds one row per octet, the one its own
/// code byte along those eight samples selects (the packed codes are transposed 8 × 8 bits at a
/// time; a +1 row minus a −1 row for ternary codes). The kernel only reads the shared tables and
/// keeps the pixel's sum in registers; the tables start on a cache line (a row of `f64` values then
/// never straddles one more line than it needs); the partial sums of a block of pixels (1 MB) stay
/// in the L2 cache and are added to `f64` sums every 1024 samples, group by group by the kernel
/// itself while a group's sums are in L1.
///
/// Blocks are processed in parallel with rayon; the kernels are compiled for AVX-512, AVX2+FMA and
/// generic x86-64 and chosen at run time.
pub struct RdOperator<T: Real> {
    geom: Geometry,
    codes: Arc<Codes>,
    pulse: Vec<T>,
    /// Reversed pulse with `pad` zeros before and `ks_pad` after.
    prev: Vec<T>,
    pad: usize,
    slabs: Vec<(usize, usize)>,
    /// Groups per block of the forward: of 256-row tables, or of quad tables.
    block_groups: usize,
    adj_block_groups: usize,
    /// Whether the forward uses the quad tables ([`quad_forward`], AVX-512).
    quads: bool,
    path: ForwardPath,
    isa: Isa,
    pool: Pool<T>,
    /// The pulse's plain autocorrelation at lags 0..K_s, computed on first use.
    lags: OnceLock<Vec<f64>>,
    /// The zero-mean twin ([`RdOperator::zero_mean`]), built on first use.
    twin: OnceLock<Box<RdOperator<T>>>,
    /// The single-precision twin ([`LinearOperator::single`]), built on first use.
    single: OnceLock<Option<Box<RdOperator<f32>>>>,
}

impl<T: Real> std::fmt::Debug for RdOperator<T> {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("RdOperator")
            .field("geometry", &self.geom)
            .field("pulse_len", &self.pulse.len())
            .field("alphabet", &self.codes.alphabet())
            .field("isa", &self.isa.name())
            .finish()
    }
}

impl<T: Real> RdOperator<T> {
    /// The operator for a scene grid, a pulse and codes. The pulse may be any finite real vector
    /// (physical pulses are nonnegative, see [`Pulse`](super::Pulse); the zero-mean pulse of the
    /// debiased adjoint is not).
    ///
    /// # Errors
    /// [`Error::ShapeMismatch`] if the codes do not have `M·N` pixels and `K_p + K_s − 1`
    /// samples; [`Error::InvalidParameter`] for an empty pulse, or naming `RDLIDAR_ISA` when that
    /// environment variable names no instruction set ([`ISA_VAR`](crate::lidar::ISA_VAR));
    /// [`Error::NonFinite`] for a NaN or infinite pulse value.
    pub fn new(geom: Geometry, pulse: Vec<T>, codes: Arc<Codes>) -> Result<Self> {
        if pulse.is_empty() {
            return Err(Error::param("pulse", "must have at least one sample"));
        }
        if let Some(i) = pulse.iter().position(|v| !v.is_finite()) {
            return Err(Error::NonFinite {
                what: format!("pulse sample {i} ({})", pulse[i]),
            });
        }
        if codes.pixels() != geom.pixels() {
            return Err(Error::shape(
                format!("codes: pixels vs the {geom} scene's M·N"),
                geom.pixels(),
                codes.pixels(),
            ));
        }
        let k = geom.samples(pulse.len());
        if codes.len() != k {
            return Err(Error::shape(
                format!(
                    "codes: samples vs K = K_p + K_s − 1 = {} + {} − 1",
                    pulse.len(),
                    geom.ks
                ),
                k,
                codes.len(),
            ));
        }
        let ks = geom.ks;
        let slabs = depth_slabs(ks);
        // One chunk more than the last slab: the wide adjoint's rows may be a chunk longer.
        let ks_pad = slabs.last().map_or(0, |&(j0, nch)| j0 + 8 * nch + 8);
        let pad = ks;
        let kp = pulse.len();
        let mut prev = vec![T::zero(); pad + kp + ks_pad];
        for (t, &v) in pulse.iter().rev().enumerate() {
            prev[pad + t] = v;
        }
        let max_nch = slabs.iter().map(|s| s.1).max().unwrap_or(1);
        let isa = Isa::chosen()?;
        let quads = isa.has_quads();
        let block_groups = if quads {
            quad_groups_per_block::<T>(max_nch)
        } else {
            groups_per_block::<T>(BLOCK_BYTES, max_nch)
        };
        // The adjoint's partial sums hold the slab's bins (its rows may be wider).
        let adj_block_groups = adjoint_groups_per_block::<T>(ADJ_BLOCK_BYTES, max_nch);
        Ok(RdOperator {
            geom,
            codes,
            pulse,
            prev,
            pad,
            slabs,
            block_groups,
            adj_block_groups,
            quads,
            path: ForwardPath::Auto,
            isa,
            pool: Pool(Mutex::new(Vec::new())),
            lags: OnceLock::new(),
            twin: OnceLock::new(),
            single: OnceLock::new(),
        })
    }

    /// The same operator with another pulse (sharing the codes), e.g. the zero-mean pulse.
    ///
    /// # Errors
    /// As [`RdOperator::new`]; the pulse must have the same length.
    pub fn with_pulse(&self, pulse: Vec<T>) -> Result<Self> {
        if pulse.len() != self.pulse.len() {
            return Err(Error::shape(
                "with_pulse: pulse length",
                self.pulse.len(),
                pulse.len(),
            ));
        }
        let mut op = RdOperator::new(self.geom, pulse, self.codes.clone())?;
        op.path = self.path;
        Ok(op)
    }

    /// The operator with the zero-mean pulse p − mean(p) ([`zero_mean`](super::zero_mean)),
    /// sharing the codes: its adjoint is the debiased backprojection, whose per-pixel Gram
    /// block tends to (K_p/4)·I instead of the plain adjoint's (K_p/4)·(I + 11ᵀ) (docs/math.md
    /// §4). Built on the first call and kept.
    pub fn zero_mean(&self) -> &RdOperator<T> {
        self.twin.get_or_init(|| {
            let p = super::zero_mean(&self.pulse);
            // Same length, and finite: |p_k − mean| ≤ max |p| for a finite pulse.
            Box::new(
                self.with_pulse(p)
                    .expect("the zero-mean pulse of a valid pulse is valid"),
            )
        })
    }

    /// x̃ = Ã*y with the zero-mean pulse: the debiased backprojection.
    ///
    /// # Panics
    /// On wrong buffer lengths, as [`LinearOperator::apply_adjoint`].
    pub fn apply_adjoint_debiased(&self, y: &[T], x: &mut [T]) {
        self.zero_mean().apply_adjoint(y, x)
    }

    /// Sets how the forward product is evaluated.
    pub fn with_forward_path(mut self, path: ForwardPath) -> Self {
        self.path = path;
        // Twins built before take the new path when next asked for.
        self.twin = OnceLock::new();
        self.single = OnceLock::new();
        self
    }

    /// The scene grid.
    pub fn geometry(&self) -> Geometry {
        self.geom
    }

    /// The pulse.
    pub fn pulse(&self) -> &[T] {
        &self.pulse
    }

    /// Σ_t p[t]·p[t + l] for the lags l = 0 … K_s − 1, in f64, computed once per operator.
    pub(crate) fn pulse_lags(&self) -> &[f64] {
        self.lags.get_or_init(|| {
            let p: Vec<f64> = self.pulse.iter().map(|v| v.as_f64()).collect();
            (0..self.geom.ks)
                .map(|l| {
                    (0..p.len().saturating_sub(l))
                        .map(|t| p[t] * p[t + l])
                        .sum()
                })
                .collect()
        })
    }

    /// The codes.
    pub fn codes(&self) -> &Arc<Codes> {
        &self.codes
    }

    /// The operator of the image rows `rows` alone: their pixels' codes and the same pulse, an
    /// M_band × N × K_s operator whose measurements are this band's share of the whole's. The
    /// bands of a split of the rows, each in an [`operator::Part`](crate::operator::Part), make
    /// the whole operator split across processes.
    ///
    /// # Errors
    /// [`Error::InvalidParameter`] for an empty band or one beyond the image.
    pub fn row_band(&self, rows: std::ops::Range<usize>) -> Result<Self> {
        let g = self.geom;
        if rows.is_empty() || rows.end > g.m {
            return Err(Error::param(
                "rows",
                format!("need a non-empty band of the {} rows, got {rows:?}", g.m),
            ));
        }
        let pixels: Vec<usize> = (rows.start * g.n..rows.end * g.n).collect();
        let codes = self.codes.select_pixels(&pixels)?;
        Self::new(
            Geometry::new(rows.len(), g.n, g.ks)?,
            self.pulse.clone(),
            Arc::new(codes),
        )
    }

    /// The kernels' instruction set, for kernels run outside the operator.
    pub(crate) fn isa_kind(&self) -> Isa {
        self.isa
    }

    /// The instruction set the kernels run with (`"avx512"`, `"avx2+fma"` or `"generic"`).
    pub fn isa(&self) -> &'static str {
        self.isa.name()
    }

    /// Groups of eight pixels per block of the adjoint (the same count for every block, the
    /// blocks a multiple of the threads of the current rayon pool).
    pub(crate) fn adjoint_block_groups(&self) -> usize {
        let groups = self.codes.groups();
        let threads = rayon::current_num_threads().max(1);
        let blocks = groups
            .div_ceil(self.adj_block_groups)
            .next_multiple_of(threads)
            .min(groups)
            .max(1);
        groups.div_ceil(blocks)
    }

    /// Chunks of eight values per row of the adjoint's tables for a slab of `nch` chunks: whole
    /// 512-bit vectors on AVX-512 but for `f32` rows on Zen 4 ([`adjoint_row_nch`]).
    pub(crate) fn adjoint_nch(&self, nch: usize) -> usize {
        adjoint_row_nch::<T>(self.isa, nch)
    }

    /// Whether the dense forward uses the quad tables (AVX-512).
    pub(crate) fn forward_uses_quads(&self) -> bool {
        self.quads
    }

    /// The depth slabs: (first bin, chunks of eight bins).
    pub(crate) fn slabs(&self) -> &[(usize, usize)] {
        &self.slabs
    }

    fn block_range(&self, b: usize) -> std::ops::Range<usize> {
        let g0 = b * self.block_groups;
        g0..(g0 + self.block_groups).min(self.codes.groups())
    }

    fn nblocks(&self) -> usize {
        self.codes.groups().div_ceil(self.block_groups)
    }

    /// The dense forward: every pixel through the tables, in [`forward_tasks`] tasks of
    /// consecutive blocks whose `f64` sums are added in task order (the same for any threads).
    fn forward_dense(&self, x: &[T], y: &mut [T]) {
        let k = self.codes.len();
        let nb = self.nblocks();
        let tasks = forward_tasks(nb);
        let max_nch = self.slabs.iter().map(|s| s.1).max().unwrap_or(1);
        let partial: Vec<Vec<f64>> = (0..tasks)
            .into_par_iter()
            .map(|t| {
                let mut w = self.pool.take();
                w.y64 = vec![0.0; k];
                // A task leaves its lane sums at zero (its last flush), so a pooled buffer of
                // the right length is ready.
                if w.part.len() != k {
                    resize(&mut w.part, k, [T::zero(); 8]);
                }
                // Every block builds its tables whole before reading them: a pooled buffer of
                // the right length is ready as it is.
                if self.quads {
                    let lines = quad_lines::<T>(self.block_groups, max_nch);
                    if w.lines.len() != lines {
                        resize(&mut w.lines, lines, CacheLine::default());
                    }
                } else {
                    let lanes = self.block_groups * 256 * max_nch;
                    if w.lanes.len() != lanes {
                        resize(&mut w.lanes, lanes, [T::zero(); 8]);
                    }
                }
                let (b0, b1) = (t * nb / tasks, (t + 1) * nb / tasks);
                for b in b0..b1 {
                    self.forward_block(x, b, &mut w);
                    // Flush the lane partial sums to f64 every few blocks to bound their length.
                    if (b - b0) % FLUSH_BLOCKS == FLUSH_BLOCKS - 1 || b + 1 == b1 {
                        for (acc, p) in w.y64.iter_mut().zip(w.part.iter_mut()) {
                            *acc += p.iter().map(|v| v.as_f64()).sum::<f64>();
                            *p = [T::zero(); 8];
                        }
                    }
                }
                let sums = std::mem::take(&mut w.y64);
                self.pool.give(w);
                sums
            })
            .collect();
        for (i, yi) in y.iter_mut().enumerate() {
            *yi = T::of_f64(partial.iter().map(|s| s[i]).sum());
        }
    }

    /// Adds block `b`'s groups, every slab, to the lane partial sums `w.part`.
    fn forward_block(&self, x: &[T], b: usize, w: &mut Work<T>) {
        let groups = self.block_range(b);
        let (plus, minus) = self.codes.group_bytes(groups.clone());
        let (shape, binary) = ((self.geom.pixels(), self.geom.ks), minus.is_none());
        for &(j0, nch) in &self.slabs {
            let base0 = self.pad + self.pulse.len() - 1 + j0;
            if self.quads {
                let tables = lines_as_mut::<T>(&mut w.lines);
                build_quad_tables(x, shape, binary, groups.clone(), j0, nch, tables);
                let blk = QuadBlock {
                    tables,
                    nch,
                    width: (8 * nch).min(shape.1 - j0),
                    plus,
                    minus,
                    prev: &self.prev,
                    base0,
                };
                quad_forward(self.isa, &blk, &mut w.part);
            } else {
                build_group_tables(x, shape, binary, groups.clone(), j0, nch, &mut w.lanes);
                let blk = FwdBlock {
                    tables: &w.lanes,
                    plus,
                    minus,
                    prev: &self.prev,
                    base0,
                };
                forward_block(self.isa, nch, &blk, &mut w.part);
            }
        }
    }

    /// Nonzero voxels as (pixel, depth, value).
    fn support(&self, x: &[T]) -> Vec<(usize, usize, T)> {
        let ks = self.geom.ks;
        x.iter()
            .enumerate()
            .filter(|(_, v)| **v != T::zero())
            .map(|(i, &v)| (i / ks, i % ks, v))
            .collect()
    }

    /// The sparse forward over nonzero voxels, in parallel over segments of samples.
    ///
    /// The entries go depth by depth (pixel by pixel within a depth): those of one depth share
    /// the pulse's window and go to [`depth_entries_isa`] together. Their sums are
    /// kept in `T` for at most `BATCH` entries, then added to the segment's sums in `f64`. The
    /// pieces and the points where the sums go to `f64` follow from the entries alone, so every
    /// segment, whatever the number of threads, adds the same values in the same order.
    fn forward_sparse(&self, entries: &[(usize, usize, T)], y: &mut [T]) {
        const BATCH: usize = 32;
        let k = self.codes.len();
        let kp = self.pulse.len();
        let (order, pieces) = depth_schedule(entries, BATCH);
        let segs = (rayon::current_num_threads() * 4).clamp(1, k);
        let seg = k.div_ceil(segs);
        y.par_chunks_mut(seg).enumerate().for_each(|(si, yseg)| {
            let k0 = si * seg;
            let k1 = k0 + yseg.len();
            let mut acc = vec![0.0f64; yseg.len()];
            let mut buf = vec![T::zero(); yseg.len()];
            let (mut amps, mut codes) = (Vec::with_capacity(BATCH), Vec::with_capacity(BATCH));
            for (range, j, flush) in &pieces {
                if *flush {
                    flush_into(&mut acc, &mut buf);
                }
                let (lo, hi) = (k0.max(*j), k1.min(j + kp));
                if lo >= hi {
                    continue;
                }
                amps.clear();
                codes.clear();
                for &i in &order[range.clone()] {
                    let (p, _, amp) = entries[i];
                    let g = p / 8;
                    amps.push(amp);
                    codes.push(Coded {
                        bit: (p % 8) as u32,
                        plus: &self.codes.plus_group(g)[lo..hi],
                        minus: self.codes.minus_group(g).map(|m| &m[lo..hi]),
                    });
                }
                let (pw, out) = (&self.pulse[lo - j..hi - j], &mut buf[lo - k0..hi - k0]);
                depth_entries_isa(self.isa, &amps, &codes, pw, out);
            }
            flush_into(&mut acc, &mut buf);
            for (o, a) in yseg.iter_mut().zip(&acc) {
                *o = T::of_f64(*a);
            }
        });
    }

    /// y = Σ over `entries` (pixel, depth, value) of the voxel's contribution: the sparse forward
    /// on an explicit list of nonzeros.
    pub(crate) fn forward_entries(&self, entries: &[(usize, usize, T)], y: &mut [T]) {
        self.forward_sparse(entries, y);
    }

    /// Whether the sparse path is cheaper for `nnz` nonzero voxels.
    fn prefers_sparse(&self, nnz: usize) -> bool {
        // Dense: one table-row addition of `nch` lane chunks per group and sample. Sparse: about a
        // quarter of a lane chunk's work per (voxel, pulse sample) pair.
        let nch: usize = self.slabs.iter().map(|s| s.1).sum();
        let dense = (self.codes.groups() * self.codes.len() * nch) as f64;
        let sparse = 0.25 * (nnz * self.pulse.len()) as f64;
        sparse < dense
    }

    /// y = A·x using only the nonzero entries of x (O(nnz·K_p)).
    ///
    /// # Panics
    /// On wrong buffer lengths.
    pub fn apply_sparse(&self, x: &[T], y: &mut [T]) {
        crate::operator::check_len("apply_sparse: input x", self.ncols(), x.len());
        crate::operator::check_len("apply_sparse: output y", self.nrows(), y.len());
        self.forward_sparse(&self.support(x), y);
    }

    /// y = A·x through the tables over all pixels, whatever the sparsity of x.
    ///
    /// # Panics
    /// On wrong buffer lengths.
    pub fn apply_dense(&self, x: &[T], y: &mut [T]) {
        crate::operator::check_len("apply_dense: input x", self.ncols(), x.len());
        crate::operator::check_len("apply_dense: output y", self.nrows(), y.len());
        self.forward_dense(x, y);
    }
}

impl<T: Real> LinearOperator<T> for RdOperator<T> {
    fn nrows(&self) -> usize {
        self.codes.len()
    }

    fn ncols(&self) -> usize {
        self.geom.voxels()
    }

    fn forward_kernel(&self, x: &[T], y: &mut [T], _: &mut [T]) {
        match self.path {
            ForwardPath::Dense => self.forward_dense(x, y),
            ForwardPath::Sparse => self.forward_sparse(&self.support(x), y),
            ForwardPath::Auto => {
                let nnz = x.iter().filter(|v| **v != T::zero()).count();
                if self.prefers_sparse(nnz) {
                    self.forward_sparse(&self.support(x), y)
                } else {
                    self.forward_dense(x, y)
                }
            }
        }
    }

    fn adjoint_kernel(&self, y: &[T], x: &mut [T], _: &mut [T]) {
        let (ks, npix) = (self.geom.ks, self.geom.pixels());
        let groups = self.codes.groups();
        let per = self.adjoint_block_groups();
        let octets = self.codes.len().div_ceil(8);
        x.par_chunks_mut(per * 8 * ks)
            .enumerate()
            .for_each(|(b, xb)| {
                let groups = b * per..((b + 1) * per).min(groups);
                let (plus, minus) = self.codes.group_bytes(groups.clone());
                // Allocated per application rather than pooled, so that an operator that is
                // kept does not hold them (megabytes per thread at large K_s).
                let (mut lines, mut part, mut out) = (Vec::new(), Vec::new(), Vec::new());
                for &(j0, slab_nch) in &self.slabs {
                    // Rows of whole vectors for the wide kernel (the extra bins are discarded).
                    let nch = self.adjoint_nch(slab_nch);
                    // On whole cache lines, so that rows start on a line where they can.
                    let bytes =
                        ADJ_OCTETS * octet_stride::<T>(nch) * std::mem::size_of::<Lane<T>>();
                    resize(&mut lines, bytes.div_ceil(64), CacheLine::default());
                    let tables = lines_as_mut::<T>(&mut lines).as_chunks_mut::<8>().0;
                    // The sums hold the slab's bins only.
                    resize(&mut part, groups.len() * 8 * slab_nch, [T::zero(); 8]);
                    resize(&mut out, groups.len() * 8 * slab_nch, [0.0; 8]);
                    for (c, o0) in (0..octets).step_by(ADJ_OCTETS).enumerate() {
                        let chunk = AdjChunk {
                            plus,
                            minus,
                            y,
                            prev: &self.prev,
                            base0: self.pad + self.pulse.len() - 1 + j0,
                            first_octet: o0,
                        };
                        // The partial sums go to `out` after the last chunk of each run.
                        let last = c % ADJ_FLUSH_CHUNKS == ADJ_FLUSH_CHUNKS - 1
                            || o0 + ADJ_OCTETS >= octets;
                        let flush = last.then_some(out.as_mut_slice());
                        if self.isa.has_wide() {
                            let (isa, part) = (self.isa, &mut part);
                            adjoint_chunk_wide(isa, nch, slab_nch, &chunk, tables, part, flush);
                        } else {
                            // The generic kernel's rows are the slab's width (`nch == slab_nch`).
                            adjoint_chunk(self.isa, nch, &chunk, tables, &mut part, flush);
                        }
                    }
                    let pixels = (8 * groups.len()).min(npix - 8 * groups.start);
                    let width = (8 * slab_nch).min(ks - j0);
                    let sums = out.chunks_exact(slab_nch).take(pixels);
                    for (o, xp) in sums.zip(xb.chunks_exact_mut(ks)) {
                        let (o, xp) = (&o.as_flattened()[..width], &mut xp[j0..j0 + width]);
                        for (v, &s) in xp.iter_mut().zip(o) {
                            *v = T::of_f64(s);
                        }
                    }
                }
            });
    }

    /// The same codes and forward path with the pulse rounded to `f32` (exactly the pulse for
    /// the 0/1 pulses of the simulations), built on the first call and kept; `None` when `T` is
    /// `f32`, or when a pulse value overflows `f32`.
    fn single(&self) -> Option<Box<dyn LinearOperator<f32> + '_>> {
        let twin = self.single.get_or_init(|| {
            let op = RdOperator::new(self.geom, single_pulse(&self.pulse)?, self.codes.clone());
            op.ok().map(|op| Box::new(op.with_forward_path(self.path)))
        });
        twin.as_deref()
            .map(|op| Box::new(op) as Box<dyn LinearOperator<f32> + '_>)
    }

    /// A [`SupportOperator`](super::SupportOperator): both directions cost O(|columns|·K_p),
    /// the adjoint only for the listed voxels.
    fn restrict_columns(&self, columns: Vec<usize>) -> Result<Box<dyn LinearOperator<T> + '_>> {
        Ok(Box::new(super::SupportOperator::new(self, columns)?))
    }

    fn describe(&self) -> String {
        format!(
            "RdOperator({}, K_p {}, {:?} codes)",
            self.geom,
            self.pulse.len(),
            self.codes.alphabet()
        )
    }
}
