//! The integration test suite: one binary, one module per area.

mod common;

mod algebra;
mod convolution;
mod errors;
mod norm;
mod operators;
