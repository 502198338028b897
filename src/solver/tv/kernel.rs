//! The Chambolle–Pock iteration of [`tv_denoise`](super::tv_denoise) on one depth map: the dual
//! update on the gradient, the primal update, and their sums, with an AVX2 path.

use super::*;

/// The normalized problem ½ Σ wᵢ(xᵢ − fᵢ)² + λ·TV(x) over the box [−1, 1]ⁿ (which holds every
/// minimizer), with max wᵢ = 1, λ > 0 and the data where wᵢ > 0 spanning [−1, 1]; the map
/// is u = shift + scale·x.
pub(super) struct Problem {
    /// Run the pointwise passes compiled for AVX2.
    pub(super) avx2: bool,
    pub(super) f: Vec<f64>,
    pub(super) w: Vec<f64>,
    pub(super) lambda: f64,
    pub(super) shift: f64,
    pub(super) scale: f64,
    pub(super) norm: TvNorm,
}

/// Sums gathered by the pointwise passes.
#[derive(Default)]
pub(super) struct Sums {
    /// ½ Σ wᵢ(uᵢ − fᵢ)² at the new u.
    pub(super) data: f64,
    /// ‖u_new − u_old‖².
    pub(super) change: f64,
    /// ‖u_new‖² in the units of the map, divided by scale².
    pub(super) norm: f64,
    /// TV of the new u.
    pub(super) tv: f64,
    /// Σ G*ᵢ((div p)ᵢ) at the new p.
    pub(super) conj: f64,
    /// Squared norm of the primal residual.
    pub(super) primal_res: f64,
    /// Squared norm of the dual residual.
    pub(super) dual_res: f64,
}

/// Block-local buffers of per-pixel terms and their running sums.
struct Terms<const N: usize> {
    buf: [[f64; BLOCK]; N],
    acc: [[f64; 4]; N],
}

impl<const N: usize> Terms<N> {
    pub(super) fn new() -> Self {
        Terms {
            buf: [[0.0; BLOCK]; N],
            acc: [[0.0; 4]; N],
        }
    }

    /// Adds the first `len` terms of each buffer to its sum (four lanes, so that it vectorizes).
    #[inline(always)]
    fn flush(&mut self, len: usize) {
        for (acc, buf) in self.acc.iter_mut().zip(&self.buf) {
            let mut chunks = buf[..len].chunks_exact(4);
            for c in &mut chunks {
                for l in 0..4 {
                    acc[l] += c[l];
                }
            }
            for (l, &t) in chunks.remainder().iter().enumerate() {
                acc[l] += t;
            }
        }
    }

    fn totals(&self) -> [f64; N] {
        self.acc.map(|a| (a[0] + a[1]) + (a[2] + a[3]))
    }
}

/// min(max(x, lo), hi), with NaN mapped to lo; written with comparisons so that it vectorizes.
#[inline(always)]
fn clip(x: f64, lo: f64, hi: f64) -> f64 {
    let x = if x >= lo { x } else { lo };
    if x <= hi {
        x
    } else {
        hi
    }
}

/// Whether the CPU supports AVX2 (checked at run time).
pub(super) fn has_avx2() -> bool {
    #[cfg(target_arch = "x86_64")]
    {
        std::arch::is_x86_feature_detected!("avx2")
    }
    #[cfg(not(target_arch = "x86_64"))]
    {
        false
    }
}

/// Runs a kernel compiled for AVX2 when `$avx2` holds (the kernels are `#[inline(always)]`, so
/// they are compiled into the AVX2 wrapper), else for the baseline instruction set. Both give
/// the same results: the kernels do not reassociate sums, only the vector width differs.
macro_rules! dispatch {
    ($avx2:expr, $problem:expr, $kernel:ident($($arg:ident: $ty:ty),*)) => {{
        #[cfg(target_arch = "x86_64")]
        if $avx2 {
            #[target_feature(enable = "avx2")]
            unsafe fn wide(problem: &Problem, $($arg: $ty),*) {
                problem.$kernel($($arg),*)
            }
            // SAFETY: `$avx2` is set from `has_avx2`, so the CPU supports AVX2.
            return unsafe { wide($problem, $($arg),*) };
        }
        $problem.$kernel($($arg),*)
    }};
}

impl Problem {
    #[allow(clippy::too_many_arguments)]
    pub(super) fn primal_step(
        &self,
        x: &mut [f64],
        out: &mut [f64],
        adj: &[f64],
        r: &mut [f64],
        tau: f64,
        sums: &mut Sums,
    ) {
        dispatch!(self.avx2, self, primal_kernel(x: &mut [f64], out: &mut [f64], adj: &[f64], r: &mut [f64], tau: f64, sums: &mut Sums))
    }

    pub(super) fn dual_step(
        &self,
        p: &mut [f64],
        g: &[f64],
        g_prev: &[f64],
        sigma: f64,
        theta: f64,
        sums: &mut Sums,
    ) {
        dispatch!(self.avx2, self, dual_kernel(p: &mut [f64], g: &[f64], g_prev: &[f64], sigma: f64, theta: f64, sums: &mut Sums))
    }

    pub(super) fn conjugate(&self, adj: &[f64], r: &[f64], sums: &mut Sums) {
        dispatch!(self.avx2, self, conjugate_kernel(adj: &[f64], r: &[f64], sums: &mut Sums))
    }

    /// x ← prox_{τG}(x − τ·adj) with adj = ∇*p = −div p, G the data term plus the indicator of
    /// the box; `out` receives the map shift + scale·x and r the terms
    /// rᵢ = (x_oldᵢ − x_newᵢ)/τ − adjᵢ of the primal residual.
    #[inline(always)]
    fn primal_kernel(
        &self,
        x: &mut [f64],
        out: &mut [f64],
        adj: &[f64],
        r: &mut [f64],
        tau: f64,
        sums: &mut Sums,
    ) {
        let inv_tau = 1.0 / tau;
        let (shift, scale) = (self.shift, self.scale);
        let offset = shift / scale;
        let mut terms = Terms::<3>::new();
        for (((((u, out), r), adj), f), w) in x
            .chunks_mut(BLOCK)
            .zip(out.chunks_mut(BLOCK))
            .zip(r.chunks_mut(BLOCK))
            .zip(adj.chunks(BLOCK))
            .zip(self.f.chunks(BLOCK))
            .zip(self.w.chunks(BLOCK))
        {
            let len = u.len();
            let (out, r, adj, f, w) = (
                &mut out[..len],
                &mut r[..len],
                &adj[..len],
                &f[..len],
                &w[..len],
            );
            let [data, change, norm] = &mut terms.buf;
            let (data, change, norm) = (&mut data[..len], &mut change[..len], &mut norm[..len]);
            for i in 0..len {
                let old = u[i];
                let tw = tau * w[i];
                let new = clip((old - tau * adj[i] + tw * f[i]) / (1.0 + tw), -1.0, 1.0);
                let (e, d) = (new - f[i], new - old);
                u[i] = new;
                out[i] = shift + scale * new;
                r[i] = -d * inv_tau - adj[i];
                data[i] = w[i] * e * e;
                change[i] = d * d;
                norm[i] = (offset + new) * (offset + new);
            }
            terms.flush(len);
        }
        let [data, change, norm] = terms.totals();
        sums.data = 0.5 * data;
        sums.change = change;
        sums.norm = norm;
    }

    /// p ← Π(z) with z = p + σ((1 + θ)g − θ g_prev) = p + σ∇ū, ū = u + θ(u − u_prev), Π the
    /// pointwise projection onto the dual ball (the prox of σF*). Also TV(u) from g = ∇u and the
    /// dual residual ‖(z − Π(z))/σ − g‖².
    #[inline(always)]
    fn dual_kernel(
        &self,
        p: &mut [f64],
        g: &[f64],
        g_prev: &[f64],
        sigma: f64,
        theta: f64,
        sums: &mut Sums,
    ) {
        let (a, b) = (sigma * (1.0 + theta), sigma * theta);
        let inv_sigma = 1.0 / sigma;
        let lambda = self.lambda;
        let mut terms = Terms::<2>::new();
        match self.norm {
            TvNorm::Isotropic => {
                let half = p.len() / 2;
                let (pv, ph) = p.split_at_mut(half);
                let (gv, gh) = g.split_at(half);
                let (qv, qh) = g_prev.split_at(half);
                for (((((pv, ph), gv), gh), qv), qh) in pv
                    .chunks_mut(BLOCK)
                    .zip(ph.chunks_mut(BLOCK))
                    .zip(gv.chunks(BLOCK))
                    .zip(gh.chunks(BLOCK))
                    .zip(qv.chunks(BLOCK))
                    .zip(qh.chunks(BLOCK))
                {
                    let len = pv.len();
                    let (ph, gv, gh, qv, qh) = (
                        &mut ph[..len],
                        &gv[..len],
                        &gh[..len],
                        &qv[..len],
                        &qh[..len],
                    );
                    let [tv, res] = &mut terms.buf;
                    let (tv, res) = (&mut tv[..len], &mut res[..len]);
                    for i in 0..len {
                        let x = pv[i] + a * gv[i] - b * qv[i];
                        let y = ph[i] + a * gh[i] - b * qh[i];
                        // s = 1 inside the ball (λ/λ), λ/|z| outside.
                        let r = (x * x + y * y).sqrt();
                        let s = lambda / if r > lambda { r } else { lambda };
                        pv[i] = s * x;
                        ph[i] = s * y;
                        let ex = (1.0 - s) * x * inv_sigma - gv[i];
                        let ey = (1.0 - s) * y * inv_sigma - gh[i];
                        tv[i] = (gv[i] * gv[i] + gh[i] * gh[i]).sqrt();
                        res[i] = ex * ex + ey * ey;
                    }
                    terms.flush(len);
                }
            }
            TvNorm::Anisotropic => {
                for ((p, g), q) in p
                    .chunks_mut(BLOCK)
                    .zip(g.chunks(BLOCK))
                    .zip(g_prev.chunks(BLOCK))
                {
                    let len = p.len();
                    let (g, q) = (&g[..len], &q[..len]);
                    let [tv, res] = &mut terms.buf;
                    let (tv, res) = (&mut tv[..len], &mut res[..len]);
                    for i in 0..len {
                        let z = p[i] + a * g[i] - b * q[i];
                        let new = clip(z, -lambda, lambda);
                        let e = (z - new) * inv_sigma - g[i];
                        p[i] = new;
                        tv[i] = g[i].abs();
                        res[i] = e * e;
                    }
                    terms.flush(len);
                }
            }
        }
        let [tv, res] = terms.totals();
        sums.tv = tv;
        sums.dual_res = res;
    }

    /// Σ G*ᵢ(qᵢ) with q = div p = −adj, and the primal residual ‖r + adj‖².
    #[inline(always)]
    fn conjugate_kernel(&self, adj: &[f64], r: &[f64], sums: &mut Sums) {
        let mut terms = Terms::<2>::new();
        for (((adj, r), f), w) in adj
            .chunks(BLOCK)
            .zip(r.chunks(BLOCK))
            .zip(self.f.chunks(BLOCK))
            .zip(self.w.chunks(BLOCK))
        {
            let len = adj.len();
            let (r, f, w) = (&r[..len], &f[..len], &w[..len]);
            let [conj, res] = &mut terms.buf;
            let (conj, res) = (&mut conj[..len], &mut res[..len]);
            for i in 0..len {
                // G*ᵢ(q) = sup_{v ∈ [−1, 1]} qv − ½wᵢ(v − fᵢ)², attained at the clipped
                // unconstrained maximizer fᵢ + q/wᵢ. Where wᵢ = 0 that is ±∞ (an end of the
                // box) or, for q = 0, NaN, which `clip` maps to −1 (every v attains 0 then).
                // The division must be exact: a v that is not the maximizer would understate
                // G*ᵢ and so overstate the dual objective.
                let q = -adj[i];
                let v = clip(f[i] + q / w[i], -1.0, 1.0);
                let e = v - f[i];
                conj[i] = q * v - 0.5 * w[i] * e * e;
                res[i] = (r[i] + adj[i]) * (r[i] + adj[i]);
            }
            terms.flush(len);
        }
        let [conj, res] = terms.totals();
        sums.conj = conj;
        sums.primal_res = res;
    }
}
