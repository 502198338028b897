//! The random-demodulation operator A = Σ·S·P composed from the generic algebra: the reference
//! the fused [`RdOperator`] is tested against.

use std::sync::Arc;

use crate::error::Result;
use crate::operator::{
    BoxedOperator, ConvMethod, ConvMode, Convolve1D, Diagonal, HStack, Identity, OperatorExt,
};
use crate::real::Real;

use super::codes::Codes;
use super::geometry::Geometry;
use super::rdop::RdOperator;

/// A = Σ·S·P built from the generic operators: P convolves every pixel's depth column with the
/// pulse (full mode), S multiplies by the codes (a diagonal of M·N·K entries), Σ sums over
/// pixels. Meant as the reference for small problems: it stores the codes as `T` values.
///
/// # Errors
/// As [`RdOperator::new`].
pub fn composed_operator<T: Real>(
    geom: Geometry,
    pulse: &[T],
    codes: &Codes,
) -> Result<BoxedOperator<T>> {
    // Validate exactly as the fused operator does.
    RdOperator::new(geom, pulse.to_vec(), Arc::new(codes.clone()))?;
    let (npix, k) = (geom.pixels(), codes.len());
    let p = Convolve1D::new(
        npix,
        geom.ks,
        pulse.to_vec(),
        ConvMode::Full,
        ConvMethod::Auto,
    )?;
    let s_diag: Vec<T> = codes
        .to_dense()
        .iter()
        .map(|&v| T::of_f64(v as f64))
        .collect();
    let s = Diagonal::new(s_diag)?;
    let sum = HStack::new((0..npix).map(|_| Identity::<T>::new(k)).collect())?;
    Ok(sum.compose(s.compose(p)?)?.boxed())
}
