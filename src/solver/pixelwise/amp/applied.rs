//! The vectors of message passing's applications in the precision they run in, and the
//! conversions around them.

use crate::real::Real;

/// The vectors of one iteration's applications, in the precision they run in: z and x̂ rounded
/// to it, Aᵀz and Ax̂.
pub(super) struct Applied<U> {
    pub(super) z: Vec<U>,
    pub(super) u: Vec<U>,
    pub(super) x: Vec<U>,
    pub(super) ax: Vec<U>,
}

impl<U: Real> Applied<U> {
    pub(super) fn zeros(m: usize, n: usize) -> Self {
        Applied {
            z: vec![U::zero(); m],
            u: vec![U::zero(); n],
            x: vec![U::zero(); n],
            ax: vec![U::zero(); m],
        }
    }
}

/// `to` = `from` rounded to `U`.
pub(super) fn convert<U: Real>(from: &[f64], to: &mut [U]) {
    for (t, v) in to.iter_mut().zip(from) {
        *t = U::of_f64(*v);
    }
}

/// The Onsager-corrected residual z ← y − Ax̂ + (z/K)·`div`, in place; returns ‖y − Ax̂‖².
pub(super) fn onsager_residual<U: Real>(z: &mut [f64], y: &[f64], ax: &[U], div: f64) -> f64 {
    let onsager = div / z.len() as f64;
    let mut rr = 0.0;
    for ((zi, &yi), ai) in z.iter_mut().zip(y).zip(ax) {
        let r = yi - ai.as_f64();
        rr += r * r;
        *zi = r + onsager * *zi;
    }
    rr
}
