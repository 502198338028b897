//! The integration test suite: one binary, one module per area.

mod common;

mod algebra;
mod cli;
mod convolution;
mod errors;
#[cfg(feature = "lapack")]
mod lapack;
mod norm;
mod operators;
