//! The space of the unknowns: where the inner products, norms and global selections over vectors
//! of the unknowns are computed.
//!
//! A solver holds the unknowns x (and every vector of their length: gradients, proxies, previous
//! iterates) as its part of a vector that may be split into parts, one per process, as PETSc's
//! `Vec` or pylops-mpi's `DistributedArray` split it. Elementwise work needs no communication;
//! what combines entries of different parts does: an inner product, a norm, the largest entries,
//! a median. Those go through the operator's [`Space`]
//! ([`LinearOperator::space`](crate::LinearOperator::space)), so that a solver is written once
//! and runs on whole vectors ([`Whole`], the default) and on split ones alike.
//!
//! The measurements y (and every vector of their length) are whole in every part.
//!
//! A [`Space`] has four collective primitives; the functions of this module build the solvers'
//! reductions on them. Every part must call the same collectives in the same order, so a solver
//! decides only on reduced values (never, e.g., on whether its own part of a support is empty).

use std::ops::Range;

use crate::real::Real;

/// How the parts of a vector of unknowns combine. The methods are collective: every part calls
/// them, in the same order.
pub trait Space: Send + Sync + std::fmt::Debug {
    /// How many parts the unknowns are split into (1: whole).
    fn parts(&self) -> usize;

    /// This part's index, from 0 to [`Space::parts`] − 1, in the order of the parts.
    fn part(&self) -> usize;

    /// Replaces each entry of `values` by its sum over the parts, added in part order.
    fn sum(&self, values: &mut [f64]);

    /// Replaces each entry of `values` by its maximum over the parts.
    fn max(&self, values: &mut [f64]);

    /// Every part's `local` values, concatenated in part order.
    fn gather(&self, local: &[f64]) -> Vec<f64>;

    /// Every part's `local` bytes, concatenated in part order (for data that are not numbers:
    /// texts, bit-packed codes). The default goes through [`Space::gather`], a value per byte.
    fn gather_bytes(&self, local: &[u8]) -> Vec<u8> {
        let sent: Vec<f64> = local.iter().map(|&b| f64::from(b)).collect();
        self.gather(&sent).into_iter().map(|b| b as u8).collect()
    }

    /// The number of unknowns in the parts before this one, given this part's `local_len`
    /// (the global index of this part's first unknown).
    fn offset(&self, local_len: usize) -> usize;
}

/// The unknowns in one piece: every reduction is local.
#[derive(Debug, Clone, Copy, Default)]
pub struct Whole;

impl Space for Whole {
    fn parts(&self) -> usize {
        1
    }
    fn part(&self) -> usize {
        0
    }
    fn sum(&self, _values: &mut [f64]) {}
    fn max(&self, _values: &mut [f64]) {}
    fn gather(&self, local: &[f64]) -> Vec<f64> {
        local.to_vec()
    }
    fn gather_bytes(&self, local: &[u8]) -> Vec<u8> {
        local.to_vec()
    }
    fn offset(&self, _local_len: usize) -> usize {
        0
    }
}

/// The one [`Whole`] space, for operators to return.
pub static WHOLE: Whole = Whole;

/// Part `part` of `rows` rows split into `parts` bands as evenly as possible, in order (the first
/// parts take one row more when they do not divide evenly); empty for parts beyond the rows.
pub fn band(rows: usize, parts: usize, part: usize) -> Range<usize> {
    let parts = parts.max(1);
    let (base, extra) = (rows / parts, rows % parts);
    let start = part * base + part.min(extra);
    let len = base + usize::from(part < extra);
    start.min(rows)..(start + len).min(rows)
}

/// This part's [`band`] of `rows` rows.
pub fn my_band(space: &dyn Space, rows: usize) -> Range<usize> {
    band(rows, space.parts(), space.part())
}

/// The first failure over the parts: `local` is this part's (None when it succeeded); every
/// part receives the failure of the lowest-numbered part that failed, with that part's index,
/// or None when every part succeeded. Two collectives (a maximum, then a gather of the one
/// message), so that parts that must all stop agree on it and one of them can report it.
pub fn first_failure(space: &dyn Space, local: Option<&str>) -> Option<(usize, String)> {
    if space.parts() == 1 {
        return local.map(|m| (0, m.to_string()));
    }
    // The lowest failing part, as the maximum of parts − index over the failing parts.
    let mine = local.map_or(0.0, |_| (space.parts() - space.part()) as f64);
    let top = max(space, mine);
    if top == 0.0 {
        return None;
    }
    let failed = space.parts() - top as usize;
    let sent: Vec<f64> = match local {
        Some(m) if space.part() == failed => m.bytes().map(f64::from).collect(),
        _ => Vec::new(),
    };
    let bytes: Vec<u8> = space.gather(&sent).into_iter().map(|b| b as u8).collect();
    Some((failed, String::from_utf8_lossy(&bytes).into_owned()))
}

/// The sum over the parts of a local value.
pub fn sum(space: &dyn Space, local: f64) -> f64 {
    let mut v = [local];
    space.sum(&mut v);
    v[0]
}

/// The sums over the parts of several local values, in one collective.
pub fn sums<const N: usize>(space: &dyn Space, mut local: [f64; N]) -> [f64; N] {
    space.sum(&mut local);
    local
}

/// The maximum over the parts of a local value.
pub fn max(space: &dyn Space, local: f64) -> f64 {
    let mut v = [local];
    space.max(&mut v);
    v[0]
}

/// Whether `local` holds in every part.
pub fn all(space: &dyn Space, local: bool) -> bool {
    max(space, f64::from(u8::from(!local))) == 0.0
}

/// The number of unknowns over every part, or of any count of local items.
pub fn count(space: &dyn Space, local: usize) -> usize {
    sum(space, local as f64) as usize
}

/// Σ aᵢbᵢ over the whole vectors, accumulated in `f64`.
pub fn dot<T: Real>(space: &dyn Space, a: &[T], b: &[T]) -> f64 {
    sum(space, crate::linalg::dot(a, b))
}

/// ‖a‖² over the whole vector.
pub fn norm2_sq<T: Real>(space: &dyn Space, a: &[T]) -> f64 {
    sum(space, crate::linalg::norm2_sq(a))
}

/// ‖a‖ over the whole vector.
pub fn norm2<T: Real>(space: &dyn Space, a: &[T]) -> f64 {
    norm2_sq(space, a).sqrt()
}

/// ‖a − b‖² over the whole vectors.
pub fn dist2_sq<T: Real>(space: &dyn Space, a: &[T], b: &[T]) -> f64 {
    sum(space, crate::linalg::dist2_sq(a, b))
}

/// max |aᵢ| over the whole vector (0 for an empty one).
pub fn norm_inf<T: Real>(space: &dyn Space, a: &[T]) -> f64 {
    max(space, crate::linalg::norm_inf(a))
}

/// ‖x − prev‖ / ‖x‖ over the whole vectors, accumulated in `f64`: 0 when the two are equal, +∞
/// when only `x` is zero.
pub fn relative_change<T: Real>(space: &dyn Space, x: &[T], prev: &[T]) -> f64 {
    let [d, xx] = sums(
        space,
        [crate::linalg::dist2_sq(x, prev), crate::linalg::dot(x, x)],
    );
    if d == 0.0 {
        0.0
    } else if xx == 0.0 {
        f64::INFINITY
    } else {
        (d / xx).sqrt()
    }
}

/// The local indices, increasing, of this part's share of the `k` entries of largest `score`
/// over the whole vector; among equal scores the lower global index wins. All indices when `k`
/// is at least the whole length.
pub fn largest_by(space: &dyn Space, score: &[f64], k: usize) -> Vec<usize> {
    let order = |a: &(f64, usize), b: &(f64, usize)| b.0.total_cmp(&a.0).then(a.1.cmp(&b.1));
    // This part's own top k, with their global indices.
    let base = space.offset(score.len());
    let mut local: Vec<(f64, usize)> = score.iter().copied().zip(base..).collect();
    if k < local.len() {
        if k > 0 {
            local.select_nth_unstable_by(k - 1, order);
        }
        local.truncate(k);
    }
    if space.parts() > 1 {
        // The k-th best of every part's candidates is the threshold of the whole.
        let flat: Vec<f64> = local.iter().flat_map(|&(s, i)| [s, i as f64]).collect();
        let mut all: Vec<(f64, usize)> = space
            .gather(&flat)
            .chunks_exact(2)
            .map(|c| (c[0], c[1] as usize))
            .collect();
        if k < all.len() {
            if k > 0 {
                all.select_nth_unstable_by(k - 1, order);
            }
            all.truncate(k);
        }
        let end = base + score.len();
        local = all
            .into_iter()
            .filter(|c| (base..end).contains(&c.1))
            .collect();
    }
    let mut idx: Vec<usize> = local.into_iter().map(|c| c.1 - base).collect();
    idx.sort_unstable();
    idx
}

/// [`largest_by`] magnitude.
pub fn largest_indices<T: Real>(space: &dyn Space, v: &[T], k: usize) -> Vec<usize> {
    let score: Vec<f64> = v.iter().map(|e| e.as_f64().abs()).collect();
    largest_by(space, &score, k)
}

/// H_k over the whole vector: keeps the `k` entries of largest magnitude (see
/// [`largest_indices`]) and zeroes the rest.
pub fn hard_threshold<T: Real>(space: &dyn Space, x: &mut [T], k: usize) {
    if k >= count(space, x.len()) {
        return;
    }
    let keep = largest_indices(space, x, k);
    let mut next = keep.iter().copied().peekable();
    for (i, v) in x.iter_mut().enumerate() {
        if next.peek() == Some(&i) {
            next.next();
        } else {
            *v = T::zero();
        }
    }
}

/// Every part's values, for a statistic of the whole (a median, a robust spread): the local
/// values themselves when the space is whole.
pub fn whole_values(space: &dyn Space, local: Vec<f64>) -> Vec<f64> {
    if space.parts() > 1 {
        space.gather(&local)
    } else {
        local
    }
}

/// Every part's text, in part order, on every part (for results that are not numbers, such as
/// a sweep's rows). A collective: two gathers, one of the lengths, one of the bytes.
pub fn gather_text(space: &dyn Space, local: &str) -> Vec<String> {
    if space.parts() == 1 {
        return vec![local.to_string()];
    }
    let lengths = space.gather(&[local.len() as f64]);
    let bytes = space.gather_bytes(local.as_bytes());
    let mut at = 0;
    lengths
        .iter()
        .map(|&len| {
            let end = (at + len as usize).min(bytes.len());
            let text = String::from_utf8_lossy(&bytes[at..end]).into_owned();
            at = end;
            text
        })
        .collect()
}

/// The rows of an image within `radius` rows of this part's rows: (those above, those below),
/// each of `row_len` values, in image order, fewer at the image's edges. The image's rows are
/// split into parts of whole consecutive rows, in part order; `local` holds this part's rows.
/// Both empty when the space is whole.
///
/// Every part sends its first and last `radius` rows (not the rows between), since a row within
/// `radius` rows of another part's rows is among them.
pub fn neighbour_rows(
    space: &dyn Space,
    local: &[f64],
    row_len: usize,
    radius: usize,
) -> (Vec<f64>, Vec<f64>) {
    if space.parts() == 1 || row_len == 0 || radius == 0 {
        return (Vec::new(), Vec::new());
    }
    let rows = local.len() / row_len;
    let first = space.offset(local.len()) / row_len;
    let end = first + rows;
    // [first row, rows, rows sent from the start, rows sent from the end, the rows sent]
    let head = radius.min(rows);
    let tail = radius.min(rows - head);
    let mut sent = vec![first as f64, rows as f64, head as f64, tail as f64];
    sent.extend_from_slice(&local[..head * row_len]);
    sent.extend_from_slice(&local[(rows - tail) * row_len..]);
    let all = space.gather(&sent);
    let (mut above, mut below) = (Vec::new(), Vec::new());
    let mut at = 0;
    while at < all.len() {
        let [start, count, head, tail] = [0, 1, 2, 3].map(|k| all[at + k] as usize);
        let body = &all[at + 4..at + 4 + (head + tail) * row_len];
        let image_rows = (start..start + head).chain(start + count - tail..start + count);
        for (row, values) in image_rows.zip(body.chunks_exact(row_len)) {
            // Parts come in image order, so the rows arrive in image order.
            if row < first && row + radius >= first {
                above.extend_from_slice(values);
            } else if row >= end && row < end + radius {
                below.extend_from_slice(values);
            }
        }
        at += 4 + (head + tail) * row_len;
    }
    (above, below)
}

/// The key of `v` in the order of [`f64::total_cmp`], as an unsigned integer.
fn order_key(v: f64) -> u64 {
    let bits = v.to_bits();
    if bits >> 63 == 1 {
        !bits
    } else {
        bits | (1 << 63)
    }
}

/// The value whose [`order_key`] is `key`.
fn from_order_key(key: u64) -> f64 {
    f64::from_bits(if key >> 63 == 1 {
        key & !(1 << 63)
    } else {
        !key
    })
}

/// The `k`-th smallest (from 0) of the values of every part, in the order of
/// [`f64::total_cmp`]; `k` must be below their count. Reorders `local`. Over split values, a
/// bisection on the values' order keys, one counting collective per bit (64): no part holds more
/// than its own values.
pub fn kth_smallest(space: &dyn Space, local: &mut [f64], k: usize) -> f64 {
    if space.parts() == 1 {
        return *local.select_nth_unstable_by(k, f64::total_cmp).1;
    }
    let keys: Vec<u64> = local.iter().map(|&v| order_key(v)).collect();
    // The smallest key with more than k values at or below it.
    let (mut lo, mut hi) = (0u64, u64::MAX);
    while lo < hi {
        let mid = lo + (hi - lo) / 2;
        if count(space, keys.iter().filter(|&&key| key <= mid).count()) > k {
            hi = mid;
        } else {
            lo = mid + 1;
        }
    }
    from_order_key(lo)
}

/// The median of the values of every part, as [`linalg::median`](crate::linalg::median) gives
/// it for them together (NaN when there are none). Reorders `local`.
pub fn median(space: &dyn Space, local: &mut [f64]) -> f64 {
    if space.parts() == 1 {
        return crate::linalg::median(local);
    }
    let n = count(space, local.len());
    if n == 0 {
        return f64::NAN;
    }
    let upper = kth_smallest(space, local, n / 2);
    if n % 2 == 1 {
        upper
    } else {
        0.5 * (kth_smallest(space, local, n / 2 - 1) + upper)
    }
}

/// [`linalg::robust_sigma`](crate::linalg::robust_sigma) of the values of every part about
/// `center`: 1.4826 · their median absolute deviation (0 when there are none). Overwrites `local`
/// with the absolute deviations.
pub fn robust_sigma(space: &dyn Space, local: &mut [f64], center: f64) -> f64 {
    if space.parts() == 1 {
        return crate::linalg::robust_sigma(local, center);
    }
    if count(space, local.len()) == 0 {
        return 0.0;
    }
    local.iter_mut().for_each(|x| *x = (*x - center).abs());
    1.4826 * median(space, local)
}
