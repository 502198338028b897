//! One pixel's exact posterior under the one-reflector prior: the denoiser that AMP applies to
//! every pixel's correlations.

use super::Prior;
use crate::real::Real;

/// One pixel's posterior.
pub(super) struct PixelPosterior {
    /// Probability of a return.
    pub(super) lit: f64,
    /// Σ_d w_d E[a | d] and Σ_d w_d E[a² | d] (for the prior's update).
    pub(super) amp1: f64,
    pub(super) amp2: f64,
    /// trace(Cov(x | g) Gₚ) / τ²: the pixel's share of the Onsager term.
    pub(super) divergence: f64,
    /// The most probable depth and its amplitude E[a | d].
    pub(super) best: Option<(usize, f64)>,
}

/// One pixel's prior as [`denoise`] takes it: P(return), the depth weights and the amplitude's
/// mean and variance when they replace the global ones.
pub(super) type PixelPrior<'a> = (f64, &'a [f64], Option<(f64, f64)>);

/// The posterior of one pixel given its correlations `g` (Gram block `gram`, noise τ²),
/// writing the posterior mean into `mean` and the depth probabilities into `post`. Depths
/// outside `lo..=hi` or with a zero column are not admissible. `pixel_prior` replaces the
/// uniform depth prior and λ (and μ, σ² when it has them) when given.
#[allow(clippy::too_many_arguments)]
#[inline(always)]
fn denoise(
    g: &[f64],
    gram: &[f64],
    (lo, hi): (usize, usize),
    tau2: f64,
    prior: Prior,
    pixel_prior: Option<PixelPrior<'_>>,
    mean: &mut [f64],
    post: &mut [f64],
) -> PixelPosterior {
    let ks = g.len();
    mean.fill(0.0);
    post.fill(0.0);
    let admissible = |d: usize| d >= lo && d <= hi && gram[d * ks + d] > 0.0;
    let count = (lo..=hi).filter(|&d| admissible(d)).count();
    if count == 0 {
        return PixelPosterior {
            lit: 0.0,
            amp1: 0.0,
            amp2: 0.0,
            divergence: 0.0,
            best: None,
        };
    }
    let lit_prior = pixel_prior.map_or(prior.lit, |p| p.0);
    let prior = match pixel_prior.and_then(|p| p.2) {
        Some((mean, var)) => Prior { mean, var, ..prior },
        None => prior,
    };
    let depth_mass: f64 = pixel_prior.map_or(count as f64, |p| {
        (lo..=hi).filter(|&d| admissible(d)).map(|d| p.1[d]).sum()
    });
    // log p(g | d) / p(g | empty) integrated over a ~ N(μ, σ²), plus the log prior.
    let log_empty = (1.0 - lit_prior).ln();
    let log_depth = lit_prior.ln() - prior.mean * prior.mean / (2.0 * prior.var);
    let log_q = |d: usize| match pixel_prior {
        Some((_, q, _)) if depth_mass > 0.0 => (q[d] / depth_mass).ln(),
        _ => -(count as f64).ln(),
    };
    let mut logw = [f64::NEG_INFINITY; 256];
    let mut big;
    let logw: &mut [f64] = if ks <= logw.len() {
        &mut logw[..ks]
    } else {
        big = vec![f64::NEG_INFINITY; ks];
        &mut big
    };
    let mut top = log_empty;
    // The logarithm of the amplitude's posterior spread, once per distinct diagonal entry (one
    // for the Toeplitz blocks of ±1 codes).
    let mut spread: Option<(u64, f64)> = None;
    for d in (lo..=hi).filter(|&d| admissible(d)) {
        let prec = gram[d * ks + d] / tau2 + 1.0 / prior.var;
        let log_spread = match spread {
            Some((bits, v)) if bits == prec.to_bits() => v,
            _ => {
                let v = 0.5 * (prior.var * prec).ln();
                spread = Some((prec.to_bits(), v));
                v
            }
        };
        let b = g[d] / tau2 + prior.mean / prior.var;
        logw[d] = log_depth + log_q(d) - log_spread + b * b / (2.0 * prec);
        top = top.max(logw[d]);
    }
    let mut total = (log_empty - top).exp();
    for w in logw.iter_mut() {
        *w = (*w - top).exp();
        total += *w;
    }
    let (mut lit, mut amp1, mut amp2, mut energy) = (0.0, 0.0, 0.0, 0.0);
    let mut best: Option<(usize, f64, f64)> = None;
    for d in (lo..=hi).filter(|&d| admissible(d)) {
        let w = logw[d] / total;
        post[d] = w;
        let prec = gram[d * ks + d] / tau2 + 1.0 / prior.var;
        let a = (g[d] / tau2 + prior.mean / prior.var) / prec;
        let a2 = a * a + 1.0 / prec;
        mean[d] = w * a;
        lit += w;
        amp1 += w * a;
        amp2 += w * a2;
        energy += w * a2 * gram[d * ks + d];
        if best.is_none_or(|b| w > b.1) {
            best = Some((d, w, a));
        }
    }
    // The weights are spent: their buffer takes G·mean.
    let times = logw;
    gram_times(gram, mean, times);
    let quad = dot_f64(mean, times);
    PixelPosterior {
        lit,
        amp1,
        amp2,
        divergence: (energy - quad).max(0.0) / tau2,
        best: best.map(|(d, _, a)| (d, a)),
    }
}

/// Σ aᵢbᵢ in eight interleaved sums (which the compiler keeps in vector registers).
#[inline(always)]
fn dot_f64(a: &[f64], b: &[f64]) -> f64 {
    let mut lanes = [0.0f64; 8];
    let (a8, b8) = (a.chunks_exact(8), b.chunks_exact(8));
    let tail: f64 = a8
        .remainder()
        .iter()
        .zip(b8.remainder())
        .map(|(x, y)| x * y)
        .sum();
    for (x, y) in a8.zip(b8) {
        for l in 0..8 {
            lanes[l] += x[l] * y[l];
        }
    }
    lanes.iter().sum::<f64>() + tail
}

/// `out` = G·m for a symmetric K_s × K_s block G (row-major): Σ_d m_d G[d, ·], the rows of the
/// zero entries of m skipped. Each value is summed over the rows in their order, a product and
/// an addition at a time, as a row-by-row accumulation into `out` would; but the columns go in
/// blocks of up to 64 whose sums stay in registers through all the rows, instead of going
/// through memory row after row, where each addition waits for the store of the one before.
#[inline(always)]
fn gram_times(gram: &[f64], m: &[f64], out: &mut [f64]) {
    let ks = m.len();
    debug_assert!(gram.len() == ks * ks && out.len() == ks, "Gram block");
    let mut c0 = 0;
    while ks - c0 >= 8 {
        let chunks = ((ks - c0) / 8).min(8);
        match chunks {
            1 => gram_columns::<1>(gram, m, c0, out),
            2 => gram_columns::<2>(gram, m, c0, out),
            3 => gram_columns::<3>(gram, m, c0, out),
            4 => gram_columns::<4>(gram, m, c0, out),
            5 => gram_columns::<5>(gram, m, c0, out),
            6 => gram_columns::<6>(gram, m, c0, out),
            7 => gram_columns::<7>(gram, m, c0, out),
            _ => gram_columns::<8>(gram, m, c0, out),
        }
        c0 += 8 * chunks;
    }
    if c0 < ks {
        let mut acc = [0.0f64; 8];
        for (row, &md) in gram.chunks_exact(ks).zip(m) {
            if md != 0.0 {
                for (a, &g) in acc.iter_mut().zip(&row[c0..]) {
                    *a += md * g;
                }
            }
        }
        out[c0..].copy_from_slice(&acc[..ks - c0]);
    }
}

/// Columns `c0 .. c0 + 8·N` of [`gram_times`].
#[inline(always)]
fn gram_columns<const N: usize>(gram: &[f64], m: &[f64], c0: usize, out: &mut [f64]) {
    let ks = m.len();
    let mut acc = [[0.0f64; 8]; N];
    for (row, &md) in gram.chunks_exact(ks).zip(m) {
        if md != 0.0 {
            let cols = &row[c0..c0 + 8 * N];
            for (a, g) in acc.iter_mut().zip(cols.chunks_exact(8)) {
                for l in 0..8 {
                    a[l] += md * g[l];
                }
            }
        }
    }
    for (a, o) in acc.iter().zip(out[c0..c0 + 8 * N].chunks_exact_mut(8)) {
        o.copy_from_slice(a);
    }
}

/// One pixel's posterior from its correlations `u` with the residual: its reflector added back
/// (g = u + Gₚ·x̂ₚ, x̂ₚ the previous posterior mean in `mean`), then [`denoise`], which writes the
/// new mean into `mean`.
#[allow(clippy::too_many_arguments)]
#[inline(always)]
fn pixel<T: Real>(
    u: &[T],
    gram: &[f64],
    window: (usize, usize),
    tau2: f64,
    prior: Prior,
    pixel_prior: Option<PixelPrior<'_>>,
    mean: &mut [f64],
    post: &mut [f64],
) -> PixelPosterior {
    let ks = u.len();
    let mut g = [0.0f64; 256];
    let mut big;
    let g: &mut [f64] = if ks <= g.len() {
        &mut g[..ks]
    } else {
        big = vec![0.0; ks];
        &mut big
    };
    gram_times(gram, mean, g);
    for (gd, u) in g.iter_mut().zip(u) {
        *gd += u.as_f64();
    }
    denoise(g, gram, window, tau2, prior, pixel_prior, mean, post)
}

/// [`pixel`] compiled for the widest vectors of this CPU (AVX-512 or AVX2, checked at run time),
/// else for the baseline instruction set. All give the same results: the Gram products keep
/// one sum per lane and add in the same order whatever the width.
#[allow(clippy::too_many_arguments)]
pub(super) fn pixel_posterior<T: Real>(
    u: &[T],
    gram: &[f64],
    window: (usize, usize),
    tau2: f64,
    prior: Prior,
    pixel_prior: Option<PixelPrior<'_>>,
    mean: &mut [f64],
    post: &mut [f64],
) -> PixelPosterior {
    #[cfg(target_arch = "x86_64")]
    {
        /// [`pixel`] compiled with `$features`.
        macro_rules! compiled_with {
            ($name:ident, $features:literal) => {
                #[target_feature(enable = $features)]
                #[allow(clippy::too_many_arguments)]
                unsafe fn $name<T: Real>(
                    u: &[T],
                    gram: &[f64],
                    window: (usize, usize),
                    tau2: f64,
                    prior: Prior,
                    pixel_prior: Option<PixelPrior<'_>>,
                    mean: &mut [f64],
                    post: &mut [f64],
                ) -> PixelPosterior {
                    pixel(u, gram, window, tau2, prior, pixel_prior, mean, post)
                }
            };
        }
        compiled_with!(avx512, "avx512f");
        compiled_with!(avx2, "avx2");
        if std::arch::is_x86_feature_detected!("avx512f") {
            // SAFETY: the CPU supports AVX-512F, checked on the line above.
            return unsafe { avx512(u, gram, window, tau2, prior, pixel_prior, mean, post) };
        }
        if std::arch::is_x86_feature_detected!("avx2") {
            // SAFETY: the CPU supports AVX2, checked on the line above.
            return unsafe { avx2(u, gram, window, tau2, prior, pixel_prior, mean, post) };
        }
    }
    pixel(u, gram, window, tau2, prior, pixel_prior, mean, post)
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::{RngExt, SeedableRng};
    use rand_chacha::ChaCha8Rng;

    /// [`gram_times`] sums as a row-by-row accumulation into its output does, to the last bit,
    /// for blocks of 1 to 140 columns (with and without a tail of fewer than eight, one to
    /// three blocks of columns) and zero entries skipped.
    #[test]
    fn gram_times_adds_as_row_by_row() {
        let mut rng = ChaCha8Rng::seed_from_u64(84);
        for ks in (1..=20).chain([37, 40, 63, 64, 65, 100, 128, 140]) {
            let gram: Vec<f64> = (0..ks * ks).map(|_| rng.random_range(-2.0..2.0)).collect();
            let m: Vec<f64> = (0..ks)
                .map(|d| {
                    if d % 4 == 1 {
                        0.0
                    } else {
                        rng.random_range(-1.0..1.0)
                    }
                })
                .collect();
            let mut want = vec![0.0f64; ks];
            for (row, &md) in gram.chunks_exact(ks).zip(&m) {
                if md != 0.0 {
                    for (o, &g) in want.iter_mut().zip(row) {
                        *o += md * g;
                    }
                }
            }
            let mut got = vec![f64::NAN; ks];
            gram_times(&gram, &m, &mut got);
            let bits = |v: &[f64]| v.iter().map(|x| x.to_bits()).collect::<Vec<_>>();
            assert_eq!(bits(&got), bits(&want), "K_s {ks}");
        }
    }

    /// The dispatched posterior equals the baseline build's to the last bit, and its Gram
    /// products equal the plain row-by-row sums to rounding, for a Toeplitz block (one shared
    /// diagonal entry) and a general symmetric one, with and without a pixel prior.
    #[test]
    fn the_wide_posterior_is_the_baseline_one() {
        let mut rng = ChaCha8Rng::seed_from_u64(83);
        let ks: usize = 37;
        let lags: Vec<f64> = (0..ks).map(|t| 50.0 / (1.0 + t as f64)).collect();
        let toeplitz: Vec<f64> = (0..ks * ks)
            .map(|i| lags[(i / ks).abs_diff(i % ks)])
            .collect();
        let mut general = vec![0.0; ks * ks];
        for d in 0..ks {
            for e in 0..=d {
                let v = if d == e {
                    rng.random_range(40.0..60.0)
                } else {
                    rng.random_range(-3.0..3.0)
                };
                general[d * ks + e] = v;
                general[e * ks + d] = v;
            }
        }
        let depth: Vec<f64> = (0..ks).map(|_| rng.random_range(0.0..1.0)).collect();
        let prior = Prior {
            lit: 0.4,
            mean: 1.0,
            var: 0.25,
        };
        for gram in [&toeplitz, &general] {
            for pixel_prior in [None, Some((0.6, depth.as_slice(), Some((0.9, 0.3))))] {
                let u: Vec<f32> = (0..ks).map(|_| rng.random_range(-40.0..60.0)).collect();
                let start: Vec<f64> = (0..ks)
                    .map(|d| {
                        if d % 3 == 0 {
                            0.0
                        } else {
                            rng.random_range(0.0..0.1)
                        }
                    })
                    .collect();
                let (mut m1, mut m2) = (start.clone(), start.clone());
                let (mut w1, mut w2) = (vec![0.0; ks], vec![0.0; ks]);
                let a = pixel(
                    &u,
                    gram,
                    (2, ks - 3),
                    30.0,
                    prior,
                    pixel_prior,
                    &mut m1,
                    &mut w1,
                );
                let b = pixel_posterior(
                    &u,
                    gram,
                    (2, ks - 3),
                    30.0,
                    prior,
                    pixel_prior,
                    &mut m2,
                    &mut w2,
                );
                assert!(m1 == m2 && w1 == w2);
                assert_eq!(a.lit.to_bits(), b.lit.to_bits());
                assert_eq!(a.divergence.to_bits(), b.divergence.to_bits());
                assert_eq!(a.best, b.best);
                assert!(a.lit > 0.0 && a.lit < 1.0 && a.divergence > 0.0);
                let mut times = vec![0.0; ks];
                gram_times(gram, &start, &mut times);
                for (d, t) in times.iter().enumerate() {
                    let want: f64 = (0..ks).map(|e| gram[d * ks + e] * start[e]).sum();
                    assert!((t - want).abs() <= 1e-12 * want.abs().max(1.0), "row {d}");
                }
            }
        }
    }
}
