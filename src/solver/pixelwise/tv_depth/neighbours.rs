//! The neighbourhood prior of [`tv_depth`](super::tv_depth): each pixel's prior built from its
//! neighbours' posteriors, and how much an estimate changed between two rounds.

use crate::real::Real;
use crate::space::{self, Space};

use rayon::prelude::*;

use super::super::amp::{PixelPriors, Posteriors};

/// How [`neighbour_priors`] builds each pixel's prior.
pub(super) struct Neighbourhood {
    /// Pixels within this many rows and columns.
    pub(super) radius: usize,
    /// The share of the uniform depth distribution.
    pub(super) floor: f64,
    /// The amplitude (mean, variance) of the first run: the prior where no neighbour has a return.
    pub(super) reference: (f64, f64),
    /// Neighbours whose expected amplitude is below `gate · reference.0` count as empty.
    pub(super) gate: f64,
    /// Columns per depth bin: the depth distribution spreads over ± this many columns.
    pub(super) per_bin: usize,
}

/// The neighbourhood prior of every pixel from the posteriors of the others:
///
/// - its probability of a return halfway between the global rate and its neighbours' mean;
/// - its depth distribution: the neighbours' depth posteriors summed, spread over ±1 bin (slanted
///   surfaces), normalized and mixed with `floor` of the uniform distribution;
/// - its amplitude: the mean and variance of the neighbours' amplitudes, each neighbour weighted
///   by its probability of a return, with a relative spread of at least 10% (or the reference
///   where no neighbour has a return).
///
/// The pixel's own posterior is left out, and neighbours below the amplitude gate count as empty.
///
/// The pixels are this part's rows (`grid` = (its rows, N)) of an image split by rows
/// (`space`); the neighbours in the rows of the parts above and below are fetched.
pub(super) fn neighbour_priors(
    space: &dyn Space,
    post: &Posteriors,
    (m, n): (usize, usize),
    ks: usize,
    hood: &Neighbourhood,
) -> PixelPriors {
    let [sum, pixels] = space::sums(space, [post.lit.iter().sum::<f64>(), post.lit.len() as f64]);
    let global = sum / pixels.max(1.0);
    let radius = hood.radius;
    // This part's posteriors with the rows of its neighbours above and below.
    let near = Nearby::new(space, post, n, ks, radius);
    let cut = hood.gate * hood.reference.0;
    let weight = |q: usize| {
        if near.amplitude[q].0 >= cut {
            near.lit[q]
        } else {
            0.0
        }
    };
    let rows_all = near.rows;
    type Row = (Vec<f64>, Vec<f64>, Vec<(f64, f64)>);
    let rows: Vec<Row> = (0..m)
        .into_par_iter()
        .map(|i_local| {
            // The row in the rows held, the neighbours' included.
            let i = i_local + near.above;
            let mut lit = Vec::with_capacity(n);
            let mut depth = Vec::with_capacity(n * ks);
            let mut amplitude = Vec::with_capacity(n);
            let mut h = vec![0.0; ks];
            let mut spread = vec![0.0; ks];
            for j in 0..n {
                h.fill(0.0);
                let (mut sum_lit, mut count) = (0.0, 0usize);
                let (mut a1, mut a2) = (0.0, 0.0);
                for a in i.saturating_sub(radius)..(i + radius + 1).min(rows_all) {
                    for b in j.saturating_sub(radius)..(j + radius + 1).min(n) {
                        if (a, b) == (i, j) {
                            continue;
                        }
                        let q = a * n + b;
                        let w = weight(q);
                        sum_lit += w;
                        count += 1;
                        a1 += w * near.amplitude[q].0;
                        a2 += w * near.amplitude[q].1;
                        for (hd, &w) in h.iter_mut().zip(&near.depth[q * ks..(q + 1) * ks]) {
                            *hd += w;
                        }
                    }
                }
                let near = if count > 0 {
                    sum_lit / count as f64
                } else {
                    global
                };
                lit.push((0.5 * global + 0.5 * near).clamp(0.02, 0.98));
                amplitude.push(if sum_lit > 1e-3 {
                    let mean = a1 / sum_lit;
                    let var = (a2 / sum_lit - mean * mean).max(0.0) + 0.01 * mean * mean;
                    (mean, var.max(f64::MIN_POSITIVE))
                } else {
                    hood.reference
                });
                // Each depth's neighbours summed, then spread over ±1 bin (slanted surfaces).
                let reach = hood.per_bin;
                for (d, s) in spread.iter_mut().enumerate() {
                    *s = h[d.saturating_sub(reach)..(d + reach + 1).min(ks)]
                        .iter()
                        .sum();
                }
                let total: f64 = spread.iter().sum();
                depth.extend(spread.iter().map(|&v| {
                    let shaped = if total > 0.0 {
                        v / total
                    } else {
                        1.0 / ks as f64
                    };
                    (1.0 - hood.floor) * shaped + hood.floor / ks as f64
                }));
            }
            (lit, depth, amplitude)
        })
        .collect();
    let mut lit = Vec::with_capacity(m * n);
    let mut depth = Vec::with_capacity(m * n * ks);
    let mut amplitude = Vec::with_capacity(m * n);
    for (l, d, a) in rows {
        lit.extend(l);
        depth.extend(d);
        amplitude.extend(a);
    }
    PixelPriors {
        lit,
        depth,
        amplitude: Some(amplitude),
    }
}

/// Posteriors of a part's pixels and of the pixels in the `radius` rows above and below it.
struct Nearby {
    lit: Vec<f64>,
    amplitude: Vec<(f64, f64)>,
    depth: Vec<f64>,
    /// Rows held, and how many of them are the rows above the part's own.
    rows: usize,
    above: usize,
}

impl Nearby {
    fn new(space: &dyn Space, post: &Posteriors, n: usize, ks: usize, radius: usize) -> Self {
        let own_rows = post.lit.len() / n.max(1);
        if space.parts() == 1 {
            return Self {
                lit: post.lit.clone(),
                amplitude: post.amplitude.clone(),
                depth: post.depth.clone(),
                rows: own_rows,
                above: 0,
            };
        }
        // Each pixel as one record: its probability of a return, amplitude and depths.
        let record = 3 + ks;
        let records = |lit: &[f64], amplitude: &[(f64, f64)], depth: &[f64]| -> Vec<f64> {
            let mut out = Vec::with_capacity(lit.len() * record);
            for (q, (&l, a)) in lit.iter().zip(amplitude).enumerate() {
                out.extend([l, a.0, a.1]);
                out.extend_from_slice(&depth[q * ks..(q + 1) * ks]);
            }
            out
        };
        let own = records(&post.lit, &post.amplitude, &post.depth);
        let (above, below) = space::neighbour_rows(space, &own, n * record, radius);
        let (mut lit, mut amplitude, mut depth) = (Vec::new(), Vec::new(), Vec::new());
        for r in [&above, &own, &below]
            .iter()
            .flat_map(|v| v.chunks_exact(record))
        {
            lit.push(r[0]);
            amplitude.push((r[1], r[2]));
            depth.extend_from_slice(&r[3..]);
        }
        Self {
            rows: lit.len() / n.max(1),
            above: above.len() / (n * record).max(1),
            lit,
            amplitude,
            depth,
        }
    }
}

/// The fraction of pixels whose estimate (empty, or the depth of its return) differs between two
/// scenes with at most one nonzero per pixel, over every part.
pub(super) fn changed_fraction<T: Real>(space: &dyn Space, a: &[T], b: &[T], ks: usize) -> f64 {
    let state = |c: &[T]| c.iter().position(|v| *v != T::zero());
    let changed = a
        .chunks(ks)
        .zip(b.chunks(ks))
        .filter(|(p, q)| state(p) != state(q))
        .count();
    let [changed, pixels] = space::sums(space, [changed as f64, (a.len() / ks) as f64]);
    changed / pixels.max(1.0)
}
