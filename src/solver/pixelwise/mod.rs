//! The one-reflector family: solvers for operators whose columns come in pixels
//! ([`VoxelOperator`](crate::operator::VoxelOperator)) with at most one return per pixel —
//! message passing with the one-reflector prior ([`reflector_amp`]), model-based recovery
//! ([`model_based`], which starts from it), TV on the depth map ([`tv_depth`], which runs both
//! within depth windows) and the refinement of a one-return scene along its surfaces
//! ([`refine_surfaces`]).

mod amp;
mod model_based;
mod refine;
mod surface;
mod tv_depth;

pub use amp::{reflector_amp, ReflectorAmpParams};
pub use model_based::{model_based, ModelBasedParams};
pub use refine::{refine_surfaces, RefineParams};
pub use tv_depth::{tv_depth, TvDepthParams};

/// What restricts (or resumes) a pixelwise solve beyond its parameters.
#[derive(Debug, Clone, Copy, Default)]
pub(crate) struct PixelConstraints<'a> {
    /// Each pixel's depth within a window `lo..=hi` (`windows[p] = (lo, hi)`).
    pub windows: Option<&'a [(usize, usize)]>,
    /// Each pixel's prior, from its neighbours.
    pub priors: Option<&'a amp::PixelPriors>,
    /// Message passing continues from this state instead of starting afresh.
    pub resume: Option<&'a amp::AmpState>,
}
