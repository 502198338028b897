//! The crate's error type.

use thiserror::Error as ThisError;

/// Everything that can go wrong in `rdlidar`, as a typed value.
///
/// Building an operator expression whose shapes do not fit, invalid parameters and failed checks
/// are reported here; applying an operator to buffers of the wrong length is a programming error and
/// panics instead (see [`crate::operator::LinearOperator`]).
#[derive(Debug, Clone, PartialEq, ThisError)]
#[non_exhaustive]
pub enum Error {
    /// Two parts of an expression (or an operator and a buffer) disagree on a length.
    #[error("shape mismatch in {context}: expected {expected}, found {found}")]
    ShapeMismatch {
        /// Where the mismatch was found, e.g. `"compose: ncols of left vs nrows of right"`.
        context: String,
        /// The length that was required.
        expected: usize,
        /// The length that was given.
        found: usize,
    },
    /// A parameter is outside its valid range.
    #[error("invalid parameter {name}: {reason}")]
    InvalidParameter {
        /// The parameter's name.
        name: &'static str,
        /// What is wrong with it.
        reason: String,
    },
    /// An index is not below the length it indexes.
    #[error("index {index} out of bounds for length {len} in {context}")]
    IndexOutOfBounds {
        /// Where the index was used.
        context: &'static str,
        /// The offending index.
        index: usize,
        /// The length it must be below.
        len: usize,
    },
    /// A value that must be finite is NaN or infinite.
    #[error("non-finite value in {what}")]
    NonFinite {
        /// What contained it.
        what: String,
    },
    /// A dense linear-algebra routine failed (e.g. LAPACK did not converge).
    #[error("linear algebra failure: {reason}")]
    LinearAlgebra {
        /// What the routine reported.
        reason: String,
    },
    /// A file cannot be read or written, or its contents are not what was expected (wrong dtype
    /// or shape, invalid values, truncated or not a `.npy` file).
    #[error("{path}: {reason}")]
    File {
        /// The file, as given.
        path: String,
        /// What is wrong, e.g. `"dtype int32 is not accepted for a scene: expected float32 or float64"`.
        reason: String,
    },
    /// An iterative solver cannot continue (zero curvature, non-finite values, …).
    #[error("{solver}: numerical breakdown: {reason}")]
    Breakdown {
        /// The solver.
        solver: &'static str,
        /// What happened.
        reason: String,
    },
    /// A request needs more memory than the machine has available (see [`crate::limits`]).
    #[error(
        "{request}: needs {} ({needed} bytes: {parts}), more than the {} of memory available; \
         {change}",
        crate::units::bytes(*needed),
        crate::units::bytes(*available)
    )]
    TooLarge {
        /// What was asked, with its flags, e.g. `"--size 100000x100000x100 --pulse-len 10"`.
        request: String,
        /// The bytes it needs.
        needed: u128,
        /// Those bytes part by part, e.g. `"scene 8.0 TB, codes 125 GB"`.
        parts: String,
        /// The bytes available.
        available: u128,
        /// What to change, e.g. `"lower --size or --pulse-len"`.
        change: String,
    },
    /// A computation was cancelled by its caller (e.g. Ctrl-C) before it finished.
    #[error("{what}: cancelled")]
    Cancelled {
        /// What was cancelled.
        what: String,
    },
    /// The adjoint identity ⟨Ax, y⟩ = ⟨x, A*y⟩ does not hold within tolerance.
    #[error("dot test failed: relative gap {gap:.3e} above tolerance {tolerance:.3e}")]
    DotTestFailed {
        /// The measured relative gap.
        gap: f64,
        /// The tolerance it was compared with.
        tolerance: f64,
    },
}

/// `Result` with the crate's [`Error`].
pub type Result<T, E = Error> = std::result::Result<T, E>;

impl Error {
    pub(crate) fn shape(context: impl Into<String>, expected: usize, found: usize) -> Self {
        Error::ShapeMismatch {
            context: context.into(),
            expected,
            found,
        }
    }

    pub(crate) fn param(name: &'static str, reason: impl Into<String>) -> Self {
        Error::InvalidParameter {
            name,
            reason: reason.into(),
        }
    }
}
