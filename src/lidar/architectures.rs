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
use super::measurement::MultiAdcOperator;
use super::rdop::RdOperator;

/// G fused operators with a common pulse and independent codes, stacked: y = [A₁x; …; A_Gx]
/// (see [`MultiAdcOperator`]).
///
/// # Errors
/// [`Error::InvalidParameter`] for an empty list of code sets; the errors of
/// [`RdOperator::new`] for code sets that do not fit the geometry and pulse.
pub fn multi_adc<T: Real>(
    geom: Geometry,
    pulse: &[T],
    codes: Vec<Arc<Codes>>,
) -> Result<MultiAdcOperator<T>> {
    MultiAdcOperator::new(geom, pulse, codes)
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

/// A tile of A×B pixels (`"AxB"`): A rows and B columns, both at least 1.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct TileSize {
    /// Pixel rows of a tile.
    pub m: usize,
    /// Pixel columns of a tile.
    pub n: usize,
}

impl TileSize {
    /// Parses `"AxB"` (e.g. `"10x20"`).
    ///
    /// # Errors
    /// [`Error::InvalidParameter`] (`tile`) unless the text is two positive integers separated
    /// by `x`.
    pub fn parse(text: &str) -> Result<Self> {
        let bad = || {
            Error::param(
                "tile",
                format!("expected AxB (tile rows x tile columns), got {text:?}"),
            )
        };
        let dims: Vec<usize> = text
            .trim()
            .split(['x', 'X'])
            .map(|p| p.trim().parse::<usize>().map_err(|_| bad()))
            .collect::<Result<_>>()?;
        match dims[..] {
            [m, n] if m > 0 && n > 0 => Ok(TileSize { m, n }),
            [m, n] => Err(Error::param(
                "tile",
                format!("tile dimensions must be positive, got {m}x{n}"),
            )),
            _ => Err(bad()),
        }
    }

    /// A tile of `m` rows and `n` columns.
    ///
    /// # Errors
    /// [`Error::InvalidParameter`] (`tiles`) when either is zero.
    pub fn new(m: usize, n: usize) -> Result<Self> {
        if m == 0 || n == 0 {
            return Err(Error::param(
                "tiles",
                format!("tile rows and columns must be at least 1, got ({m}, {n})"),
            ));
        }
        Ok(TileSize { m, n })
    }

    /// The number of tiles (edge tiles clipped) of an `m`×`n` array.
    pub fn count(&self, m: usize, n: usize) -> usize {
        m.div_ceil(self.m) * n.div_ceil(self.n)
    }
}

impl std::fmt::Display for TileSize {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(f, "{}x{}", self.m, self.n)
    }
}

/// How the pixels reach the ADCs (the paper's §3).
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Architecture {
    /// One ADC summing every pixel (one code set).
    Single,
    /// G ADCs, each with its own code set for every pixel.
    MultiAdc(usize),
    /// One code set, one ADC per tile of pixels.
    Tiles(TileSize),
    /// One ADC summing a random fraction (in (0, 1]) of the pixels; the others are blocked.
    Aperture(f64),
}

impl Architecture {
    /// The name of `meta.json`'s `architecture.kind`: "single", "multi_adc", "tiles" or
    /// "aperture".
    pub fn kind(&self) -> &'static str {
        match self {
            Architecture::Single => "single",
            Architecture::MultiAdc(_) => "multi_adc",
            Architecture::Tiles(_) => "tiles",
            Architecture::Aperture(_) => "aperture",
        }
    }

    /// Number of code sets: G for [`Architecture::MultiAdc`], 1 otherwise.
    pub fn code_sets(&self) -> usize {
        match self {
            Architecture::MultiAdc(g) => *g,
            _ => 1,
        }
    }

    /// The architecture in a few words for messages: `""` for one ADC, `", 4 ADCs"`,
    /// `", tiles 8x8"`, `", aperture 0.5"`.
    pub fn describe_suffix(&self) -> String {
        match self {
            Architecture::Single => String::new(),
            Architecture::MultiAdc(g) => format!(", {g} ADCs"),
            Architecture::Tiles(t) => format!(", tiles {t}"),
            Architecture::Aperture(f) => format!(", aperture {f}"),
        }
    }

    /// Rows of the measurements of an `m`×`n` array: `None` for the (K,) vector of one ADC,
    /// `Some(R)` for the (R, K) array of R ADCs.
    pub fn rows(&self, m: usize, n: usize) -> Option<usize> {
        match self {
            Architecture::MultiAdc(g) => Some(*g),
            Architecture::Tiles(t) => Some(t.count(m, n)),
            Architecture::Single | Architecture::Aperture(_) => None,
        }
    }
}

/// An integer in [0, n), n ≥ 1, uniformly (rejection of the incomplete last block).
fn below(rng: &mut rand_chacha::ChaCha8Rng, n: u64) -> u64 {
    use rand::Rng;
    // 2^64 mod n: the values at or above 2^64 − r would favour the first r results.
    let r = (u64::MAX % n + 1) % n;
    loop {
        let v = rng.next_u64();
        if r == 0 || v <= u64::MAX - r {
            return v % n;
        }
    }
}

/// The active pixels of a coded aperture: ⌈fraction·pixels⌉ distinct pixels (at least one; a
/// product within 1e-9 of an integer counts as that integer), drawn by a partial Fisher–Yates
/// shuffle of 0 … pixels−1 on a ChaCha8 stream seeded with `seed`, in increasing order.
///
/// # Errors
/// [`Error::InvalidParameter`] (`aperture`) unless `fraction` is in (0, 1] and `pixels` ≥ 1.
pub fn aperture_pixels(pixels: usize, fraction: f64, seed: u64) -> Result<Vec<usize>> {
    use rand::SeedableRng;
    if !(fraction > 0.0 && fraction <= 1.0) || pixels == 0 {
        return Err(Error::param(
            "aperture",
            format!(
                "the fraction must be in (0, 1] of at least one pixel, got {}",
                crate::units::number(fraction)
            ),
        ));
    }
    let x = fraction * pixels as f64;
    let count = if (x - x.round()).abs() <= 1e-9 * x.max(1.0) {
        x.round()
    } else {
        x.ceil()
    };
    let count = (count as usize).clamp(1, pixels);
    let mut order: Vec<usize> = (0..pixels).collect();
    let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(seed);
    for i in 0..count {
        let j = i + below(&mut rng, (pixels - i) as u64) as usize;
        order.swap(i, j);
    }
    order.truncate(count);
    order.sort_unstable();
    Ok(order)
}
