//! One pixel's exact posterior under the one-reflector prior: the denoiser that AMP applies to
//! every pixel's correlations.

use super::Prior;

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
pub(super) fn denoise(
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
    for d in (lo..=hi).filter(|&d| admissible(d)) {
        let prec = gram[d * ks + d] / tau2 + 1.0 / prior.var;
        let b = g[d] / tau2 + prior.mean / prior.var;
        logw[d] = log_depth + log_q(d) - 0.5 * (prior.var * prec).ln() + b * b / (2.0 * prec);
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
    let mut quad = 0.0;
    for (d, &md) in mean.iter().enumerate() {
        if md != 0.0 {
            quad += md * dot_f64(&gram[d * ks..(d + 1) * ks], mean);
        }
    }
    PixelPosterior {
        lit,
        amp1,
        amp2,
        divergence: (energy - quad).max(0.0) / tau2,
        best: best.map(|(d, _, a)| (d, a)),
    }
}

pub(super) fn dot_f64(a: &[f64], b: &[f64]) -> f64 {
    a.iter().zip(b).map(|(x, y)| x * y).sum()
}
