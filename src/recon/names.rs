//! Values named on the command line (methods, threshold rules): each kind has one table of
//! values with their names, from which its list of values, its list of names, a value's name
//! and a name's value all come.

use crate::error::{Error, Result};

/// The values of a table, in its order.
pub(super) const fn values<V: Copy, const N: usize>(table: &[(V, &str); N]) -> [V; N] {
    let mut out = [table[0].0; N];
    let mut i = 0;
    while i < N {
        out[i] = table[i].0;
        i += 1;
    }
    out
}

/// The names of a table, in its order.
pub(super) const fn names<V, const N: usize>(table: &[(V, &'static str); N]) -> [&'static str; N] {
    let mut out = [""; N];
    let mut i = 0;
    while i < N {
        out[i] = table[i].1;
        i += 1;
    }
    out
}

/// The name of `value` in `table`.
///
/// # Panics
/// If the table does not list `value` (a table lists every value of its kind).
pub(super) fn name_of<V: Copy + PartialEq>(table: &[(V, &'static str)], value: V) -> &'static str {
    table
        .iter()
        .find(|(v, _)| *v == value)
        .map(|(_, n)| *n)
        .expect("the table lists every value")
}

/// The value of `table` whose name is `s`.
///
/// # Errors
/// [`Error::InvalidParameter`] (`param`) naming the unknown `what` and listing the valid names.
pub(super) fn by_name<V: Copy>(
    s: &str,
    table: &[(V, &'static str)],
    param: &'static str,
    what: &str,
) -> Result<V> {
    table
        .iter()
        .find(|(_, n)| *n == s)
        .map(|(v, _)| *v)
        .ok_or_else(|| {
            let names: Vec<&str> = table.iter().map(|(_, n)| *n).collect();
            Error::param(
                param,
                format!("unknown {what} {s:?}; expected one of {}", names.join(", ")),
            )
        })
}
