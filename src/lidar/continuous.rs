//! Scenes at continuous depths: the generators of [`scenes`](super::scenes) without the
//! rounding to the grid, as [`Returns`] for a response to render.

use ndarray::{Array2, Array3};
use rand::{RngExt, SeedableRng};
use rand_chacha::ChaCha8Rng;

use crate::error::Result;

use super::geometry::Geometry;
use super::returns::Returns;
use super::scenes::{check_lit_fraction, checked, paper_layers};

/// The closest spacing of two returns of a pixel of [`transparent_returns`], in bins.
pub const TRANSPARENT_SPACING: f64 = 3.0;

/// The paper's scene ([`paper_scene`](super::paper_scene)) at continuous depths: a depth
/// fraction f is depth f·(K_s − 1) bins, unrounded (the slanted plane's depth varies
/// continuously along the columns; the square and disk lie between bins unless K_s − 1 makes
/// 0.3 and 0.6 of it whole); where reflectors overlap the nearest wins (the earlier of square,
/// disk, plane on equal depths).
///
/// # Errors
/// As [`paper_scene`](super::paper_scene).
pub fn paper_returns(g: Geometry) -> Result<Returns> {
    let layers = paper_layers(g)?;
    let mut depth = Array2::from_elem((g.m, g.n), f64::NAN);
    let mut amplitude = Array2::zeros((g.m, g.n));
    for (layer, reflectivity) in &layers {
        for ((i, j), &d) in layer.indexed_iter() {
            let current = depth[[i, j]];
            if !d.is_nan() && (current.is_nan() || d < current) {
                depth[[i, j]] = d;
                amplitude[[i, j]] = *reflectivity;
            }
        }
    }
    Returns::single(depth, amplitude)
}

/// A random opaque scene at continuous depths: each pixel lit with probability
/// `lit_fraction`, at a depth uniform in [0, K_s − 1] bins with an amplitude uniform in
/// [0.2, 1.0], drawn from `seed`.
///
/// # Errors
/// [`Error::InvalidParameter`](crate::Error::InvalidParameter) if `lit_fraction` is not in
/// [0, 1], or for the geometry.
pub fn random_returns(g: Geometry, lit_fraction: f64, seed: u64) -> Result<Returns> {
    let g = checked(g)?;
    check_lit_fraction(lit_fraction)?;
    let top = (g.ks - 1) as f64;
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    let mut depth = Array2::from_elem((g.m, g.n), f64::NAN);
    let mut amplitude = Array2::zeros((g.m, g.n));
    for (d, a) in depth.iter_mut().zip(amplitude.iter_mut()) {
        if rng.random_bool(lit_fraction) {
            *d = rng.random_range(0.0..=top);
            *a = rng.random_range(0.2..=1.0);
        }
    }
    Returns::single(depth, amplitude)
}

/// A random semi-transparent scene at continuous depths: every pixel has 1 to 3 returns (as
/// many as fit) at least [`TRANSPARENT_SPACING`] bins apart, at depths uniform in
/// [0, K_s − 1] otherwise, with amplitudes uniform in [0.1, 1.0] that do not increase with
/// depth, drawn from `seed`.
///
/// # Errors
/// For the geometry.
pub fn transparent_returns(g: Geometry, seed: u64) -> Result<Returns> {
    let g = checked(g)?;
    let top = (g.ks - 1) as f64;
    // r returns spaced by s need a range of (r − 1)·s.
    let most = (1..=3)
        .rev()
        .find(|&r| (r - 1) as f64 * TRANSPARENT_SPACING <= top)
        .unwrap_or(1);
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    let mut depth = Array3::from_elem((most, g.m, g.n), f64::NAN);
    let mut amplitude = Array3::zeros((most, g.m, g.n));
    for i in 0..g.m {
        for j in 0..g.n {
            let count = rng.random_range(1..=most);
            // Uniform in the room left once the spacings are taken out, then spread apart.
            let slack = top - (count - 1) as f64 * TRANSPARENT_SPACING;
            let mut at: Vec<f64> = (0..count).map(|_| rng.random_range(0.0..=slack)).collect();
            at.sort_unstable_by(f64::total_cmp);
            let mut amps: Vec<f64> = (0..count).map(|_| rng.random_range(0.1..=1.0)).collect();
            amps.sort_unstable_by(|a, b| b.total_cmp(a));
            for (q, (d, a)) in at.iter().zip(&amps).enumerate() {
                depth[[q, i, j]] = d + q as f64 * TRANSPARENT_SPACING;
                amplitude[[q, i, j]] = *a;
            }
        }
    }
    Returns::new(depth, amplitude)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::lidar::{paper_scene, Response, Scene};

    #[test]
    fn the_paper_scene_rounded_is_the_grid_paper_scene() {
        let g = Geometry::new(20, 24, 17).unwrap();
        let r = paper_returns(g).unwrap();
        assert!(r.depth.iter().any(|d| !d.is_nan() && d.fract() != 0.0));
        let rounded = Returns::single(
            r.depth.index_axis(ndarray::Axis(0), 0).mapv(f64::round),
            r.amplitude.index_axis(ndarray::Axis(0), 0).to_owned(),
        )
        .unwrap();
        let grid: Scene<f64> = paper_scene(g).unwrap();
        assert_eq!(rounded.render::<f64>(g.ks, &Response::Delta).unwrap(), grid);
    }

    #[test]
    fn random_scenes_are_seeded_and_in_range() {
        let g = Geometry::new(10, 10, 8).unwrap();
        let a = random_returns(g, 0.5, 3).unwrap();
        assert_eq!(a, random_returns(g, 0.5, 3).unwrap());
        assert_ne!(a, random_returns(g, 0.5, 4).unwrap());
        assert!(a.lit_pixels() > 20 && a.lit_pixels() < 80);
        assert!(random_returns(g, 1.5, 3).is_err());
        let t = transparent_returns(g, 5).unwrap();
        assert_eq!(t.layers(), 3);
        for i in 0..10 {
            for j in 0..10 {
                let d: Vec<f64> = (0..3)
                    .map(|q| t.depth[[q, i, j]])
                    .filter(|d| !d.is_nan())
                    .collect();
                assert!(!d.is_empty());
                assert!(d
                    .windows(2)
                    .all(|w| w[1] - w[0] >= TRANSPARENT_SPACING - 1e-12));
                assert!(d.iter().all(|&x| (0.0..=7.0).contains(&x)));
            }
        }
        t.render::<f32>(g.ks, &Response::gaussian(0.8).unwrap())
            .unwrap();
    }
}
