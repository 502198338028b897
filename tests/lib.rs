//! The integration test suite: one binary, one module per area.

mod common;

mod algebra;
mod architectures;
mod argmin_solvers;
mod cli;
mod cli_experiments;
mod cli_lidar;
mod cli_reconstruct;
mod convolution;
mod errors;
mod experiments;
#[cfg(feature = "lapack")]
mod lapack;
mod metrics;
mod model_based;
mod noise;
mod norm;
mod operators;
mod plot;
mod rdop;
mod reconstruct;
mod scenes;
mod solvers;
mod sparse_solvers;
mod tight_frame;
mod tv;
