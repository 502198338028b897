//! A reconstruction of any architecture.

use super::*;
use crate::operator::Applies;

/// A reconstruction of any architecture: one operator's, or a tiled array's.
// One value per reconstruction, moved a few times: its size does not matter.
#[allow(clippy::large_enum_variant)]
#[derive(Debug, Clone)]
pub enum Reconstructed<T> {
    /// One ADC or G ADCs: one reconstruction.
    Single(Reconstruction<T>),
    /// Tiles: every tile's reconstruction, stitched.
    Tiled(TiledReconstruction<T>),
}

impl<T: Real> Reconstructed<T> {
    /// Every return found.
    pub fn scene(&self) -> &Scene<T> {
        match self {
            Reconstructed::Single(r) => &r.scene,
            Reconstructed::Tiled(r) => &r.scene,
        }
    }

    /// The depth map (each pixel's strongest return; unobserved pixels marked).
    pub fn depth(&self) -> &DepthMap<T> {
        match self {
            Reconstructed::Single(r) => &r.depth,
            Reconstructed::Tiled(r) => &r.depth,
        }
    }

    /// The depth map, mutable (e.g. to fill unobserved pixels).
    pub fn depth_mut(&mut self) -> &mut DepthMap<T> {
        match self {
            Reconstructed::Single(r) => &mut r.depth,
            Reconstructed::Tiled(r) => &mut r.depth,
        }
    }

    /// Wall-clock time.
    pub fn elapsed(&self) -> std::time::Duration {
        match self {
            Reconstructed::Single(r) => r.elapsed,
            Reconstructed::Tiled(r) => r.elapsed,
        }
    }

    /// Forward, adjoint and support applications (summed over the tiles).
    pub fn applies(&self) -> Applies {
        match self {
            // A backprojection: one adjoint application.
            Reconstructed::Single(r) => super::outcome::single_applies(r),
            Reconstructed::Tiled(r) => r.applies(),
        }
    }
}

/// An observer of every iteration that never stops a solver.
pub fn observe_nothing<T>(_: usize, _: &IterationInfo<'_, T>) -> Control {
    Control::Continue
}
