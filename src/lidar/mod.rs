//! The random-demodulation lidar: scenes, pulse and codes, the measurement operator.
//!
//! A random 0/1 pulse p (length K_p) floods the scene; each of M×N pixels sees its depth column
//! `x[m,n,:]` (K_s bins) convolved with p, multiplies it by its own code `s[m,n,k]`, and one ADC
//! samples the sum: `y[k] = Σ_{m,n} s[m,n,k]·(x[m,n,:] ⊛ p)[k]`, k < K = K_p + K_s − 1.

mod architectures;
mod blocks;
mod cancel;
mod codes;
mod composed;
mod continuous;
mod footprint;
mod geometry;
pub(crate) mod kernels;
mod measurement;
mod noise;
mod points;
mod pulse;
mod rdop;
mod response;
mod returns;
pub(crate) mod sampling;
mod scene;
mod scenes;
mod seeded;
mod simulate;
mod streamed;
mod support;
mod weighted;

pub use architectures::{
    aperture_pixels, coded_aperture, multi_adc, pixel_groups, tiles, Architecture, TileSize,
};
pub use blocks::BlockOperator;
pub use cancel::Cancellable;
pub use codes::{packed_len, CodeAlphabet, Codes};
pub use continuous::{paper_returns, random_returns, transparent_returns, TRANSPARENT_SPACING};
pub use geometry::{Geometry, Regime};
pub use measurement::{LidarOperator, MultiAdcOperator};
pub use noise::{
    add_gaussian, add_gaussian_snr, add_photon_noise, mean_power, quantize, sigma_for_snr,
    unmodulated_light, unmodulated_light_of, FullScale, NoiseModel, NoiseReport, NoiseStage,
    QuantizationReport, StageReport,
};
pub use pulse::{zero_mean, Pulse};
pub use response::{Measured, Response, GAUSSIAN_REACH, MAX_MEASURED_SAMPLES, MAX_OVERSAMPLING};
pub use returns::Returns;

/// The instruction set the fused operator's kernels run with on this machine (`"avx512"`,
/// `"avx2+fma"` or `"generic"`), as [`RdOperator::isa`] reports it: the best the CPU has, capped
/// by the environment variable [`ISA_VAR`] (`RDLIDAR_ISA`).
pub fn kernel_isa() -> &'static str {
    kernels::Isa::detect().name()
}
pub use composed::composed_operator;
pub use footprint::{gather_limit, GatherLimit, KernelWork, OperatorWork};
pub use kernels::ISA_VAR;
pub use points::{points, Camera, PointCloud};
pub use rdop::{ForwardPath, RdOperator};
pub use sampling::{depth_bin_m, parse_tau, DEFAULT_TAU_S, SPEED_OF_LIGHT};
pub use scene::{DepthMap, Scene, NO_RETURN, UNOBSERVED};
#[cfg(feature = "images")]
pub(crate) use scenes::checked;
pub use scenes::{
    attenuate, composite_nearest, paper_scene, paper_surfaces, random_opaque_scene,
    semi_transparent_scene,
};
pub use seeded::{SeededCodes, SEEDED_CODES_GENERATOR};
pub use simulate::{
    simulate, simulate_cancellable, simulate_split, simulate_split_supplied, simulate_supplied,
    AdcQuantization, PhotonNoise, SceneSpec, Seeds, Simulation, SimulationSpec,
};
pub use streamed::{StreamedOperator, STREAM_BLOCK_BYTES};
pub use support::SupportOperator;
pub use weighted::RowWeighted;
