//! The integration test suite: one binary, one module per area.

mod common;

mod algebra;
mod amp;
mod architectures;
mod argmin_solvers;
mod cli;
mod cli_lidar;
mod cli_reconstruct;
mod convolution;
mod errors;
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
