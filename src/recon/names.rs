//! Values named on the command line (methods, threshold rules), found by their name.

use crate::error::{Error, Result};

/// The entry of `all` whose command-line name in `names` (same order) is `s`.
///
/// # Errors
/// [`Error::InvalidParameter`] (`param`) naming the unknown `what` and listing the valid names.
pub(super) fn by_name<V: Copy>(
    s: &str,
    names: &[&str],
    all: &[V],
    param: &'static str,
    what: &str,
) -> Result<V> {
    names
        .iter()
        .position(|&n| n == s)
        .map(|i| all[i])
        .ok_or_else(|| {
            Error::param(
                param,
                format!("unknown {what} {s:?}; expected one of {}", names.join(", ")),
            )
        })
}
