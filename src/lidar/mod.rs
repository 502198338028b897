//! The random-demodulation lidar: scenes, pulse and codes, the measurement operator.
//!
//! A random 0/1 pulse p (length K_p) floods the scene; each of M×N pixels sees its depth column
//! x[m,n,:] (K_s bins) convolved with p, multiplies it by its own code s[m,n,k], and one ADC samples
//! the sum: y[k] = Σ_{m,n} s[m,n,k]·(x[m,n,:] ⊛ p)[k], k < K = K_p + K_s − 1.

mod geometry;
mod scene;

pub use geometry::{Geometry, Regime};
pub use scene::{DepthMap, Scene, NO_RETURN};
