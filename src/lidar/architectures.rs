//! The architecture variants of the paper's §3, built from the operator algebra and the fused
//! operator.
//!
//! * **G ADCs** ([`multi_adc`]): every pixel is modulated by G independent code sets and each set
//!   has its own ADC; one pulse gives G·K measurements. A is the vertical stack of G fused
//!   operators sharing the pulse.
//! * **Pixel groups** ([`pixel_groups`], [`tiles`]): the array is split into groups of pixels and
//!   each group has its own ADC, which sums only its pixels. A is the vertical stack of
//!   `A_g · R_g`, where `R_g` restricts the scene to group g's voxels.
//! * **Coded aperture / subsampled array** ([`coded_aperture`]): only a selection of pixels reaches
//!   the ADC: `A = A_active · R`.

use std::sync::Arc;

use crate::error::{Error, Result};
use crate::operator::{Compose, Restriction, VStack};
use crate::real::Real;

use super::codes::Codes;
use super::geometry::Geometry;
use super::rdop::RdOperator;

/// G fused operators with a common pulse and independent codes, stacked: y = [A₁x; …; A_Gx].
///
/// # Errors
/// [`Error::InvalidParameter`] for an empty list of code sets; the errors of
/// [`RdOperator::new`] for code sets that do not fit the geometry and pulse.
pub fn multi_adc<T: Real>(
    geom: Geometry,
    pulse: &[T],
    codes: Vec<Arc<Codes>>,
) -> Result<VStack<RdOperator<T>>> {
    if codes.is_empty() {
        return Err(Error::param("adcs", "need at least one code set"));
    }
    let ops = codes
        .into_iter()
        .map(|c| RdOperator::new(geom, pulse.to_vec(), c))
        .collect::<Result<Vec<_>>>()?;
    VStack::new(ops)
}

/// The voxel indices (pixel-major, depth fastest) of the pixels `pixels`.
fn voxels_of(pixels: &[usize], ks: usize) -> Vec<usize> {
    pixels
        .iter()
        .flat_map(|&p| (p * ks)..(p * ks + ks))
        .collect()
}

fn check_pixels(geom: Geometry, pixels: &[usize], what: &'static str) -> Result<()> {
    if pixels.is_empty() {
        return Err(Error::param(what, "a pixel group must not be empty"));
    }
    if let Some(&bad) = pixels.iter().find(|&&p| p >= geom.pixels()) {
        return Err(Error::IndexOutOfBounds {
            context: what,
            index: bad,
            len: geom.pixels(),
        });
    }
    Ok(())
}

/// One ADC summing only the pixels `active` (a coded aperture or a subsampled array):
/// `A_active · R`, with R the restriction of the scene to the active pixels' voxels and `A_active`
/// the fused operator of those pixels (as a 1 × |active| array) with their codes taken from
/// `codes` (the codes of the full array).
///
/// # Errors
/// [`Error::InvalidParameter`] for an empty selection, [`Error::IndexOutOfBounds`] for a pixel
/// outside the array, and the errors of [`RdOperator::new`].
pub fn coded_aperture<T: Real>(
    geom: Geometry,
    pulse: &[T],
    codes: &Codes,
    active: &[usize],
) -> Result<Compose<RdOperator<T>, Restriction<T>>> {
    check_pixels(geom, active, "aperture")?;
    if codes.pixels() != geom.pixels() {
        return Err(Error::shape(
            "aperture: code pixels vs M·N",
            geom.pixels(),
            codes.pixels(),
        ));
    }
    let sub = Geometry::new(1, active.len(), geom.ks)?;
    let op = RdOperator::new(sub, pulse.to_vec(), Arc::new(codes.select_pixels(active)?))?;
    let r = Restriction::new(geom.voxels(), voxels_of(active, geom.ks))?;
    Compose::new(op, r)
}

/// One ADC per group of pixels: the vertical stack of [`coded_aperture`] operators, one per group,
/// each with the codes of its pixels taken from `codes`.
///
/// # Errors
/// As [`coded_aperture`] for each group; [`Error::InvalidParameter`] for an empty list of groups.
pub fn pixel_groups<T: Real>(
    geom: Geometry,
    pulse: &[T],
    codes: &Codes,
    groups: &[Vec<usize>],
) -> Result<VStack<Compose<RdOperator<T>, Restriction<T>>>> {
    if groups.is_empty() {
        return Err(Error::param("groups", "need at least one pixel group"));
    }
    let ops = groups
        .iter()
        .map(|g| coded_aperture(geom, pulse, codes, g))
        .collect::<Result<Vec<_>>>()?;
    VStack::new(ops)
}

/// Splits the M × N array into rectangular tiles of at most `tile_m × tile_n` pixels (row-major
/// pixel indices, tiles in row-major order): the pixel groups of a block-structured array with
/// one ADC per tile.
///
/// # Errors
/// [`Error::InvalidParameter`] if a tile dimension is zero.
pub fn tiles(geom: Geometry, tile_m: usize, tile_n: usize) -> Result<Vec<Vec<usize>>> {
    if tile_m == 0 || tile_n == 0 {
        return Err(Error::param(
            "tile",
            format!("tile dimensions must be positive, got {tile_m}x{tile_n}"),
        ));
    }
    let mut out = Vec::new();
    for i0 in (0..geom.m).step_by(tile_m) {
        for j0 in (0..geom.n).step_by(tile_n) {
            let mut t = Vec::new();
            for i in i0..(i0 + tile_m).min(geom.m) {
                for j in j0..(j0 + tile_n).min(geom.n) {
                    t.push(i * geom.n + j);
                }
            }
            out.push(t);
        }
    }
    Ok(out)
}
