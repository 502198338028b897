//! What an acquisition holds at once: whether codes are streamed, and the memory plan of a
//! request.

use super::*;

/// The memory of the codes held at once and of the operators over them, in `T`.
fn operator_memory<T: Real>(held: Geometry, sets: usize, pulse_len: usize) -> u128 {
    RdOperator::<T>::estimated_memory_bytes(
        held,
        pulse_len,
        CodeAlphabet::Ternary,
        rayon::current_num_threads(),
    )
    .map_or(u128::MAX, |b| b as u128)
    .saturating_mul(sets as u128)
}

/// Why codes cannot be streamed.
pub(crate) enum NoStream {
    /// They are held arrays, not described by a seed.
    NotSeeded,
    /// They are the codes of several ADCs or tiles.
    Architecture(Architecture),
}

impl NoStream {
    /// The message, with `asked` naming the request (a flag, an argument).
    pub(crate) fn describe(&self, asked: &str) -> String {
        match self {
            NoStream::NotSeeded => format!(
                "{asked} regenerates codes described by a seed, but these are a codes array: \
                 pass the meta.json of a simulation whose `codes_format` is seed"
            ),
            NoStream::Architecture(a) => format!(
                "{asked} streams the codes of one ADC, but this acquisition is {}: its {} are \
                 generated one at a time already",
                a.kind(),
                if matches!(a, Architecture::Tiles(_)) {
                    "tiles"
                } else {
                    "code sets"
                }
            ),
        }
    }
}

/// Whether codes (`seeded` or held) of `architecture` are regenerated block by block on every
/// application, as `streaming` asks.
pub(crate) fn streams(
    streaming: Streaming,
    seeded: bool,
    architecture: Architecture,
    geometry: Geometry,
    k: usize,
) -> std::result::Result<bool, NoStream> {
    let seeded_single = seeded && architecture == Architecture::Single;
    let held_bytes = (geometry.pixels() as u128).saturating_mul(packed_len(k) as u128);
    match streaming {
        Streaming::Never => Ok(false),
        Streaming::Auto => Ok(seeded_single && held_bytes > STREAM_ABOVE_BYTES),
        Streaming::Always if seeded_single => Ok(true),
        Streaming::Always if !seeded => Err(NoStream::NotSeeded),
        Streaming::Always => Err(NoStream::Architecture(architecture)),
    }
}

/// What a request does with an acquisition, for its memory plan.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Use {
    /// Applies the whole operator (forward, adjoint, a dot test): a tiled acquisition holds
    /// the whole array's codes and every tile's copy of its own.
    Operator,
    /// Reconstructs: a tiled acquisition holds only the tiles being solved (one per thread)
    /// beside the array's codes, if they are held at all.
    Reconstruct,
}

/// The codes held at once, as (grid, count) pairs of code sets with their operators' buffers:
/// what [`plan`] counts.
pub(crate) fn held(
    g: Geometry,
    k: usize,
    architecture: Architecture,
    seeded: bool,
    streamed: bool,
    request: Use,
) -> Vec<(Geometry, usize)> {
    if streamed {
        return vec![(stream_block(g, k), 1)];
    }
    match (architecture, request) {
        (Architecture::Tiles(_), Use::Operator) => vec![(g, 2)],
        (Architecture::Tiles(t), Use::Reconstruct) => {
            let tile = Geometry::new(t.m.min(g.m), t.n.min(g.n), g.ks).unwrap_or(g);
            let threads = rayon::current_num_threads();
            if seeded {
                vec![(tile, threads)]
            } else {
                vec![(g, 1), (tile, threads)]
            }
        }
        (a, _) => vec![(g, a.code_sets())],
    }
}

/// The grid of one block of streamed codes.
fn stream_block(g: Geometry, k: usize) -> Geometry {
    let per_pixel = packed_len(k).max(1);
    let block = (STREAM_BLOCK_BYTES / per_pixel).max(8).min(g.pixels());
    Geometry::new(1, block, g.ks).unwrap_or(g)
}

/// The memory plan of a request in `T`: the code sets `held` held at once (grid and count)
/// with their operators' buffers, `scenes` scenes of `g` and two copies of `rows`·K
/// measurements.
pub(crate) fn plan<T: Real>(
    g: Geometry,
    pulse_len: usize,
    held: &[(Geometry, usize)],
    rows: usize,
    scenes: u128,
) -> MemoryPlan {
    let size = std::mem::size_of::<T>();
    let codes = held.iter().fold(0u128, |a, &(grid, sets)| {
        a.saturating_add(operator_memory::<T>(grid, sets, pulse_len))
    });
    MemoryPlan::new()
        .add("codes and operator", codes, 1)
        .add("scenes", scenes.saturating_mul(g.voxels() as u128), size)
        .add(
            "measurements",
            (rows as u128).saturating_mul(g.samples(pulse_len) as u128) * 2,
            size,
        )
}
