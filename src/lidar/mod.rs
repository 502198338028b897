//! The random-demodulation lidar: scenes, pulse and codes, the measurement operator.
//!
//! A random 0/1 pulse p (length K_p) floods the scene; each of M×N pixels sees its depth column
//! `x[m,n,:]` (K_s bins) convolved with p, multiplies it by its own code `s[m,n,k]`, and one ADC
//! samples the sum: `y[k] = Σ_{m,n} s[m,n,k]·(x[m,n,:] ⊛ p)[k]`, k < K = K_p + K_s − 1.

mod architectures;
mod budget;
mod codes;
mod geometry;
mod kernels;
mod metrics;
mod noise;
mod pulse;
mod rdop;
mod reconstruct;
mod scene;
mod scenes;
mod support;

pub use architectures::{coded_aperture, multi_adc, pixel_groups, tiles};
pub use budget::{
    parse_tau, Budget, MemoryBudget, OperatorRates, PerPrecision, PhysicalScales, Throughput,
    ThroughputSource, TimeBudget, DEFAULT_TAU_S,
};
pub use codes::{CodeAlphabet, Codes};
pub use geometry::{Geometry, Regime};
pub use metrics::{compare, compare_depth, depth_bin_m, relative_error, Metrics, SPEED_OF_LIGHT};
pub use noise::{
    add_gaussian, add_gaussian_snr, add_photon_noise, mean_power, quantize, sigma_for_snr,
    unmodulated_light, FullScale, NoiseModel, NoiseReport, NoiseStage, QuantizationReport,
    StageReport,
};
pub use pulse::Pulse;
pub use rdop::{composed_operator, ForwardPath, RdOperator};
pub use reconstruct::{
    is_piecewise_smooth, reconstruct, Method, ReconstructOptions, Reconstruction, SMOOTH_BINS,
    SMOOTH_FRACTION, TV_RESIDUAL_MARGIN,
};
pub use scene::{DepthMap, Scene, NO_RETURN};
pub use scenes::{
    attenuate, composite_nearest, paper_scene, paper_surfaces, random_opaque_scene,
    scene_from_pngs, semi_transparent_scene,
};
pub use support::SupportOperator;
