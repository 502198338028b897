//! The one-ADC operator over codes described by a seed, regenerating its codes block by block
//! on every application, so that no code file is read and memory stays bounded however large
//! the array.

use std::sync::{Arc, OnceLock};

use crate::error::{Error, Result};
use crate::operator::{check_len, LinearOperator, VoxelOperator};
use crate::real::Real;

use super::codes::packed_len;
use super::geometry::Geometry;
use super::measurement::LidarOperator;
use super::rdop::RdOperator;
use super::seeded::SeededCodes;
use super::support::SupportOperator;

/// Bytes of packed codes generated at once by default: one block of pixels.
pub const STREAM_BLOCK_BYTES: usize = 16 << 20;

/// A support's codes up to this many bytes are generated once and kept by its
/// [restriction](LinearOperator::restrict_columns); larger supports regenerate theirs block by
/// block on every application.
const HOLD_SUPPORT_BYTES: usize = 256 << 20;

/// The measurement operator of one ADC whose ±1 codes are [`SeededCodes`], equal to
/// [`RdOperator`] on the materialized codes but holding none of them: every application
/// generates the codes of one block of pixels at a time (about [`STREAM_BLOCK_BYTES`] of
/// packed codes, a multiple of eight pixels), applies the fused operator of that block and
/// drops them.
///
/// - The forward product is `y = Σ_b A_b·x_b` over the blocks of pixels whose depth columns
///   are not all zero, accumulated in `f64`: a sparse scene costs the codes of its nonzero
///   pixels only.
/// - The adjoint is `x_b = A_bᵀ·y` block by block, identical to [`RdOperator`]'s to the bit
///   (a pixel's backprojection depends only on its own codes).
/// - A restriction to a support generates the codes of the support's pixels only, once if they
///   fit in 256 MB, otherwise block by block on every application.
///
/// The price is the regeneration: about one ChaCha8 keystream byte per eight codes and
/// application, a small fraction of the fused kernels' work on eight codes; the memory is one
/// block per application in flight, whatever M·N.
pub struct StreamedOperator<T: Real> {
    geom: Geometry,
    pulse: Vec<T>,
    codes: SeededCodes,
    set: usize,
    block: usize,
    /// One pixel's operator, for what ±1 codes make the same for every pixel (Gram blocks,
    /// self-correlations, column norms).
    probe: RdOperator<T>,
    twin: OnceLock<Box<StreamedOperator<T>>>,
}

impl<T: Real> std::fmt::Debug for StreamedOperator<T> {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("StreamedOperator")
            .field("geometry", &self.geom)
            .field("pulse_len", &self.pulse.len())
            .field("codes", &self.codes)
            .field("set", &self.set)
            .field("block_pixels", &self.block)
            .finish()
    }
}

impl<T: Real> StreamedOperator<T> {
    /// The operator of code set `set` of `codes` over `geom` with the pulse `pulse`, in blocks
    /// of about [`STREAM_BLOCK_BYTES`] of codes.
    ///
    /// # Errors
    /// [`Error::ShapeMismatch`] if the codes do not have `M·N` pixels and `K_p + K_s − 1`
    /// samples; [`Error::IndexOutOfBounds`] for a set the codes do not have; the pulse errors
    /// of [`RdOperator::new`].
    pub fn new(geom: Geometry, pulse: Vec<T>, codes: SeededCodes, set: usize) -> Result<Self> {
        if codes.pixels() != geom.pixels() {
            return Err(Error::shape(
                format!("seeded codes: pixels vs the {geom} scene's M·N"),
                geom.pixels(),
                codes.pixels(),
            ));
        }
        let k = geom.samples(pulse.len());
        if codes.len() != k {
            return Err(Error::shape(
                format!(
                    "seeded codes: samples vs K = K_p + K_s − 1 = {} + {} − 1",
                    pulse.len(),
                    geom.ks
                ),
                k,
                codes.len(),
            ));
        }
        if set >= codes.sets() {
            return Err(Error::IndexOutOfBounds {
                context: "code set",
                index: set,
                len: codes.sets(),
            });
        }
        let probe = RdOperator::new(
            Geometry::new(1, 1, geom.ks)?,
            pulse.clone(),
            Arc::new(codes.select(set, &[0])?),
        )?;
        let per_pixel = packed_len(k);
        let block = (STREAM_BLOCK_BYTES / per_pixel / 8 * 8).max(8);
        Ok(StreamedOperator {
            geom,
            pulse,
            codes,
            set,
            block,
            probe,
            twin: OnceLock::new(),
        })
    }

    /// The same operator generating `pixels` pixels' codes at a time (rounded up to a multiple
    /// of eight).
    ///
    /// # Errors
    /// [`Error::InvalidParameter`] for zero pixels.
    pub fn with_block_pixels(mut self, pixels: usize) -> Result<Self> {
        if pixels == 0 {
            return Err(Error::param("block pixels", "must be at least 1"));
        }
        self.block = pixels.div_ceil(8) * 8;
        self.twin = OnceLock::new();
        Ok(self)
    }

    /// Pixels whose codes are generated at once.
    pub fn block_pixels(&self) -> usize {
        self.block
    }

    /// The codes' description.
    pub fn seeded_codes(&self) -> SeededCodes {
        self.codes
    }

    /// The code set used.
    pub fn set(&self) -> usize {
        self.set
    }

    /// Bytes of codes held during one application: one block's packed codes in the kernels'
    /// layout, and its packed keystream while it is converted.
    pub fn block_memory_bytes(&self) -> usize {
        let per_pixel = packed_len(self.codes.len());
        2 * self.block.min(self.geom.pixels()) * per_pixel
    }

    /// The fused operator of the pixels `pixels` (in that order) as a 1 × |pixels| array.
    fn block_operator(&self, pixels: &[usize]) -> RdOperator<T> {
        // The pixels come from this operator's grid and the geometry and pulse were checked
        // when it was built, so neither the generation nor the operator can fail.
        let codes = self
            .codes
            .select(self.set, pixels)
            .expect("pixels of the operator's own grid");
        let geom = Geometry::new(1, pixels.len(), self.geom.ks).expect("a nonempty block");
        RdOperator::new(geom, self.pulse.clone(), Arc::new(codes))
            .expect("the block has the operator's pulse and samples")
    }

    /// The forward product over the pixels `pixels` (sorted, each with a nonzero column) in
    /// blocks, summed into `y` in f64; `sparse` takes every block's sparse path.
    fn forward_pixels(&self, pixels: &[usize], x: &[T], y: &mut [T], sparse: bool) {
        let ks = self.geom.ks;
        let mut acc = vec![0.0f64; y.len()];
        let mut part = vec![T::zero(); y.len()];
        let mut xs = Vec::new();
        for chunk in pixels.chunks(self.block) {
            xs.clear();
            for &p in chunk {
                xs.extend_from_slice(&x[p * ks..(p + 1) * ks]);
            }
            let op = self.block_operator(chunk);
            if sparse {
                op.apply_sparse(&xs, &mut part);
            } else {
                op.apply(&xs, &mut part);
            }
            acc.iter_mut()
                .zip(&part)
                .for_each(|(a, v)| *a += v.as_f64());
        }
        y.iter_mut().zip(&acc).for_each(|(o, a)| *o = T::of_f64(*a));
    }

    /// The pixels whose depth columns hold a nonzero, in order.
    fn lit_pixels(&self, x: &[T]) -> Vec<usize> {
        x.chunks_exact(self.geom.ks)
            .enumerate()
            .filter(|(_, col)| col.iter().any(|v| *v != T::zero()))
            .map(|(p, _)| p)
            .collect()
    }

    /// The same operator with the zero-mean pulse: its adjoint is the debiased backprojection.
    pub fn zero_mean(&self) -> &StreamedOperator<T> {
        self.twin.get_or_init(|| {
            let mut op = StreamedOperator::new(
                self.geom,
                super::zero_mean(&self.pulse),
                self.codes,
                self.set,
            )
            .expect("the zero-mean pulse of a valid pulse is valid");
            op.block = self.block;
            Box::new(op)
        })
    }
}

impl<T: Real> LinearOperator<T> for StreamedOperator<T> {
    fn nrows(&self) -> usize {
        self.codes.len()
    }

    fn ncols(&self) -> usize {
        self.geom.voxels()
    }

    fn forward_kernel(&self, x: &[T], y: &mut [T], _: &mut [T]) {
        let pixels = self.lit_pixels(x);
        self.forward_pixels(&pixels, x, y, false);
    }

    fn adjoint_kernel(&self, y: &[T], x: &mut [T], _: &mut [T]) {
        let ks = self.geom.ks;
        let npix = self.geom.pixels();
        for (b, xb) in x.chunks_mut(self.block * ks).enumerate() {
            let pixels: Vec<usize> = (b * self.block..((b + 1) * self.block).min(npix)).collect();
            self.block_operator(&pixels).apply_adjoint(y, xb);
        }
    }

    /// The support's pixels' codes only: generated once and kept if they fit in 256 MB,
    /// otherwise regenerated block by block on every application.
    fn restrict_columns(&self, columns: Vec<usize>) -> Result<Box<dyn LinearOperator<T> + '_>> {
        Ok(Box::new(StreamedSupport::new(self, columns)?))
    }

    fn describe(&self) -> String {
        format!(
            "StreamedOperator({}, K_p {}, seeded codes {} set {}, {} pixels per block)",
            self.geom,
            self.pulse.len(),
            self.codes.seed(),
            self.set,
            self.block
        )
    }
}

impl<T: Real> VoxelOperator<T> for StreamedOperator<T> {
    fn column_len(&self) -> usize {
        self.geom.ks
    }

    /// The debiased correlation: the adjoint with the zero-mean pulse.
    fn correlate(&self, r: &[T], u: &mut [T]) {
        self.zero_mean().apply_adjoint(r, u)
    }

    /// With ±1 codes the same for every pixel: one pixel's, from the pulse.
    fn self_correlations(&self, voxels: &[usize]) -> Vec<f64> {
        let ks = self.geom.ks;
        let local: Vec<usize> = voxels.iter().map(|&v| v % ks).collect();
        self.probe.self_correlations(&local)
    }

    fn pixel_gram(&self, _pixel: usize) -> Vec<f64> {
        self.probe.pixel_gram(0)
    }

    fn uniform_pixel_gram(&self) -> bool {
        true
    }

    /// Column queries from the pulse (the probe's), no application.
    fn structured_columns(&self) -> bool {
        true
    }

    fn column_norms(&self, columns: &[usize]) -> Vec<f64> {
        let ks = self.geom.ks;
        let local: Vec<usize> = columns.iter().map(|&c| c % ks).collect();
        self.probe.column_norms(&local)
    }
}

impl<T: Real> LidarOperator<T> for StreamedOperator<T> {
    fn geometry(&self) -> Geometry {
        self.geom
    }

    fn pulse(&self) -> &[T] {
        &self.pulse
    }

    fn apply_sparse(&self, x: &[T], y: &mut [T]) {
        check_len("apply_sparse: input x", self.ncols(), x.len());
        check_len("apply_sparse: output y", self.nrows(), y.len());
        let pixels = self.lit_pixels(x);
        self.forward_pixels(&pixels, x, y, true);
    }

    fn zero_mean_operator(&self) -> Box<dyn LinearOperator<T> + '_> {
        Box::new(self.zero_mean())
    }
}

/// One block of a [`StreamedSupport`]: its pixels, and for each of its voxels the position in
/// the support and the voxel in the block's own 1 × |pixels| grid.
struct SupportBlock<T: Real> {
    pixels: Vec<usize>,
    positions: Vec<usize>,
    local: Vec<usize>,
    held: Option<RdOperator<T>>,
}

/// A [`StreamedOperator`] restricted to a set of voxels ([`SupportOperator`] block by block).
struct StreamedSupport<'a, T: Real> {
    parent: &'a StreamedOperator<T>,
    columns: usize,
    blocks: Vec<SupportBlock<T>>,
}

impl<'a, T: Real> StreamedSupport<'a, T> {
    fn new(parent: &'a StreamedOperator<T>, voxels: Vec<usize>) -> Result<Self> {
        let n = parent.ncols();
        if let Some(&bad) = voxels.iter().find(|&&v| v >= n) {
            return Err(Error::IndexOutOfBounds {
                context: "support voxels",
                index: bad,
                len: n,
            });
        }
        let ks = parent.geom.ks;
        let mut order: Vec<usize> = (0..voxels.len()).collect();
        order.sort_by_key(|&i| voxels[i]);
        let mut pixels: Vec<usize> = order.iter().map(|&i| voxels[i] / ks).collect();
        pixels.dedup();
        let hold =
            pixels.len().saturating_mul(packed_len(parent.codes.len())) <= HOLD_SUPPORT_BYTES;
        let mut blocks = Vec::new();
        let mut next = order.iter().peekable();
        for chunk in pixels.chunks(parent.block) {
            let (mut positions, mut local) = (Vec::new(), Vec::new());
            let last = *chunk.last().expect("chunks are nonempty");
            let mut slot = 0;
            while let Some(&&i) = next.peek() {
                let p = voxels[i] / ks;
                if p > last {
                    break;
                }
                while chunk[slot] != p {
                    slot += 1;
                }
                positions.push(i);
                local.push(slot * ks + voxels[i] % ks);
                next.next();
            }
            let held = hold.then(|| parent.block_operator(chunk));
            blocks.push(SupportBlock {
                pixels: chunk.to_vec(),
                positions,
                local,
                held,
            });
        }
        Ok(StreamedSupport {
            parent,
            columns: voxels.len(),
            blocks,
        })
    }

    /// Runs `f` on each block with its operator restricted to the block's voxels.
    fn each_block(&self, mut f: impl FnMut(&SupportBlock<T>, &dyn LinearOperator<T>)) {
        for block in &self.blocks {
            let generated;
            let op = match &block.held {
                Some(op) => op,
                None => {
                    generated = self.parent.block_operator(&block.pixels);
                    &generated
                }
            };
            let support = SupportOperator::new(op, block.local.clone())
                .expect("the block's voxels lie in its grid");
            f(block, &support);
        }
    }
}

impl<T: Real> LinearOperator<T> for StreamedSupport<'_, T> {
    fn nrows(&self) -> usize {
        self.parent.nrows()
    }

    fn ncols(&self) -> usize {
        self.columns
    }

    fn forward_kernel(&self, x: &[T], y: &mut [T], _: &mut [T]) {
        let mut acc = vec![0.0f64; y.len()];
        let mut part = vec![T::zero(); y.len()];
        self.each_block(|block, op| {
            let xs: Vec<T> = block.positions.iter().map(|&i| x[i]).collect();
            if xs.iter().all(|v| *v == T::zero()) {
                return;
            }
            op.apply(&xs, &mut part);
            acc.iter_mut()
                .zip(&part)
                .for_each(|(a, v)| *a += v.as_f64());
        });
        y.iter_mut().zip(&acc).for_each(|(o, a)| *o = T::of_f64(*a));
    }

    fn adjoint_kernel(&self, y: &[T], x: &mut [T], _: &mut [T]) {
        self.each_block(|block, op| {
            let mut xs = vec![T::zero(); block.positions.len()];
            op.apply_adjoint(y, &mut xs);
            for (&i, v) in block.positions.iter().zip(xs) {
                x[i] = v;
            }
        });
    }

    fn describe(&self) -> String {
        format!(
            "StreamedSupport({} voxels of {})",
            self.columns,
            self.parent.describe()
        )
    }
}
