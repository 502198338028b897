//! # rdlidar
//!
//! Compressive time-of-flight lidar by random demodulation: matrix-free linear operators and
//! sparse-recovery solvers.
//!
//! The crate is built on a small operator algebra ([`operator`]): a [`LinearOperator`] trait whose
//! implementors write a forward and an adjoint kernel, and combinators (composition, adjoint,
//! scaling, sums, stacks, block-diagonal, normal operator) whose adjoints are derived from their
//! parts. Every operator is checked by the public [`operator::dot_test`].
//!
//! ```
//! use rdlidar::operator::{ConvMethod, ConvMode, Convolve1D, Diagonal, LinearOperator, OperatorExt};
//!
//! # fn main() -> rdlidar::Result<()> {
//! // Convolve each of 3 rows of length 8 with a pulse, then weight the 3·10 outputs.
//! let conv = Convolve1D::new(3, 8, vec![1.0, 0.0, 1.0], ConvMode::Full, ConvMethod::Auto)?;
//! let weights = Diagonal::new(vec![0.5f64; 30])?;
//! let op = weights.compose(&conv)?;              // weights · conv
//! let report = rdlidar::operator::dot_test(&op, 1)?;
//! assert!(report.gap < 1e-12);
//!
//! let at = (&op).adjoint();                      // the adjoint view, derived automatically
//! assert_eq!((at.nrows(), at.ncols()), (24, 30));
//! let dense = op.to_dense();                     // materialized for inspection
//! assert_eq!(dense.dim(), (30, 24));
//! # Ok(())
//! # }
//! ```
//!
//! ## Layers
//! [`operator`] (the generic algebra) ← [`solver`] (generic solvers and the pixelwise family) ←
//! [`recon`] (lidar pipelines: methods, `auto`, peaks, metrics) → [`lidar`] (physics: geometry,
//! scenes, pulse, codes, the fused operator, architectures, noise, simulation) → [`operator`].
//! [`io`] reads and writes the interchange files; `report` (experiments, figures, cost model)
//! sits on top. See `docs/architecture.md`.
//!
//! ## Features
//! - `cli` (default): the `rdlidar` binary (clap, Ctrl-C handling); implies `report`.
//! - `report`: experiments, tables, figures (plotters) and the cost model; implies `images` and
//!   `progress`.
//! - `progress`: terminal progress bars for the solvers (indicatif).
//! - `images`: scenes from PNG depth maps ([`io::scene_from_pngs`]).
//! - `lapack`: dense LAPACK routines through `ndarray-linalg` and the system OpenBLAS
//!   (Debian: `libopenblas-dev`), used for least-squares references.
//!
//! `cargo build --no-default-features` builds the library alone: operators, solvers, the lidar
//! model, reconstruction and `.npy` files, with none of the command line's dependencies.
//!
//! ## Random numbers
//! Every random quantity is drawn from a ChaCha8 generator (`rand_chacha`) seeded explicitly, so
//! results are reproducible across runs and machines.

#![warn(missing_docs)]

pub mod acquisition;
#[cfg(feature = "mpi")]
pub mod distributed;
pub mod error;
pub mod io;
#[cfg(feature = "lapack")]
pub mod lapack;
pub mod lidar;
pub mod limits;
pub mod linalg;
pub mod operator;
pub mod real;
pub mod recon;
#[cfg(feature = "report")]
pub mod report;
pub mod settings;
pub(crate) mod simd;
pub mod solver;
pub mod space;
pub mod units;

pub use error::{Error, Result};
pub use operator::{LinearOperator, OperatorExt};
pub use real::Real;

/// The README's example, compiled and run as a doctest.
#[cfg(doctest)]
#[doc = include_str!("../README.md")]
pub struct ReadmeDoctests;
