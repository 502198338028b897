//! Code sets as arrays in memory, as a binding passes them and a simulation returns them: int8
//! samples −1, 0, +1 of shape (M, N, K) or (G, M, N, K), or ±1 samples packed eight to a byte
//! along the last axis as `np.packbits(S > 0, axis=-1)` writes them, (M, N, ⌈K/8⌉) or
//! (G, M, N, ⌈K/8⌉).

use ndarray::{ArrayD, ArrayViewD, Axis, IxDyn};

use super::*;
use crate::lidar::Simulation;

/// Code sets as arrays, owned.
#[derive(Debug, Clone, PartialEq)]
pub enum CodeArray {
    /// int8 samples −1, 0, +1.
    Int8(ArrayD<i8>),
    /// ±1 samples packed along the last axis.
    Packed(ArrayD<u8>),
}

/// Code sets as arrays, borrowed.
#[derive(Debug, Clone)]
pub enum CodeArrayView<'a> {
    /// int8 samples −1, 0, +1.
    Int8(ArrayViewD<'a, i8>),
    /// ±1 samples packed along the last axis.
    Packed(ArrayViewD<'a, u8>),
}

impl CodeArrayView<'_> {
    fn shape(&self) -> &[usize] {
        match self {
            CodeArrayView::Int8(a) => a.shape(),
            CodeArrayView::Packed(a) => a.shape(),
        }
    }

    /// Code set `g` (of the first axis, when there are four) as `pixels` codes of `k` samples.
    fn code_set(&self, g: usize, pixels: usize, k: usize) -> Result<Codes> {
        fn set<E: Copy>(a: &ArrayViewD<'_, E>, g: usize) -> Vec<E> {
            if a.ndim() == 4 {
                a.index_axis(Axis(0), g).iter().copied().collect()
            } else {
                a.iter().copied().collect()
            }
        }
        match self {
            CodeArrayView::Int8(a) => {
                let flat = set(a, g);
                let v = ndarray::ArrayView2::from_shape((pixels, k), &flat)
                    .map_err(|e| Error::param("codes", e.to_string()))?;
                Codes::from_dense(v)
            }
            CodeArrayView::Packed(a) => Codes::from_packbits(&set(a, g), pixels, k),
        }
    }
}

impl Acquisition {
    /// The acquisition of `pulse` with the code sets of `codes` for a scene of `depth_bins`
    /// bins: one set (M, N, ·) is one ADC, or tiles of `tiles`; G sets (G, M, N, ·) are G ADCs
    /// (one set with that axis is read as one ADC of a multi-ADC acquisition, as a codes file
    /// of that shape is). Shapes and memory (for `T`) are checked before anything is copied.
    ///
    /// # Errors
    /// [`Error::InvalidParameter`] naming `codes` (or `depth_bins`, `pulse`, `tiles`) for a
    /// shape that does not fit, codes outside −1, 0, 1, or an acquisition beyond memory.
    pub fn from_code_arrays<T: Real>(
        pulse: Vec<f64>,
        codes: CodeArrayView<'_>,
        depth_bins: usize,
        tiles: Option<TileSize>,
    ) -> Result<Acquisition> {
        limits::check_count("depth_bins", depth_bins, limits::MAX_DEPTH_BINS)?;
        let k = pulse
            .len()
            .checked_add(depth_bins - 1)
            .ok_or_else(|| Error::param("depth_bins", "too large"))?;
        let shape = codes.shape().to_vec();
        let (sets, m, n, last) = match shape[..] {
            [m, n, l] => (1, m, n, l),
            [g, m, n, l] => (g, m, n, l),
            _ => {
                return Err(Error::param(
                    "codes",
                    format!(
                        "expected a 3-D array (M, N, K) or a 4-D array (G, M, N, K), got shape \
                         {shape:?}"
                    ),
                ))
            }
        };
        let packed = matches!(codes, CodeArrayView::Packed(_));
        let want = if packed { packed_len(k) } else { k };
        if last != want {
            let reason = if packed {
                format!(
                    "packed codes of shape {shape:?} have {last} bytes per pixel, but the pulse \
                     and `depth_bins` give K = K_p + K_s - 1 = {k} samples, which pack into \
                     {want}"
                )
            } else {
                format!(
                    "int8 codes of shape {shape:?} have {last} samples per pixel, but the pulse \
                     and `depth_bins` give K = K_p + K_s - 1 = {k}"
                )
            };
            return Err(Error::param("codes", reason));
        }
        let axis = shape.len() == 4;
        if let (true, 1, Some(t)) = (axis, sets, tiles) {
            return Err(Error::param(
                "codes",
                format!(
                    "codes with a code-set axis (G, M, N, K): tiles of {t} (`tiles`) need one \
                     code set (M, N, K)"
                ),
            ));
        }
        let geometry =
            Acquisition::check_arrays::<T>((sets, m, n), depth_bins, pulse.len(), tiles, 2)?;
        let held = (0..sets)
            .map(|g| {
                codes.code_set(g, m * n, k).map(Arc::new).map_err(|e| {
                    let at = if sets > 1 {
                        format!(" (code set {g})")
                    } else {
                        String::new()
                    };
                    let reason = match e {
                        Error::InvalidParameter { reason, .. } => reason,
                        e => e.to_string(),
                    };
                    Error::param("codes", format!("{reason}{at}"))
                })
            })
            .collect::<Result<Vec<_>>>()?;
        let acq = Acquisition::new(
            geometry,
            pulse,
            CodeStore::Held(held),
            tiles,
            Streaming::Never,
        )?;
        Ok(if axis { acq.with_code_set_axis() } else { acq })
    }
}

/// The codes of `sim` as `format` gives them (none for seeded codes: their seed describes
/// them), checking `cancel` between pixels; a coded aperture's inactive pixels have zero codes.
///
/// # Errors
/// [`Error::Cancelled`] once `cancel` is raised.
pub fn code_array<T>(
    sim: &Simulation<T>,
    format: CodesFormat,
    cancel: &AtomicBool,
) -> Result<Option<CodeArray>> {
    let g = sim.spec.geometry;
    let k = g.samples(sim.spec.pulse_len);
    let sets = sim.code_sets.len();
    let shape = |last: usize| match sim.spec.architecture {
        Architecture::MultiAdc(_) => IxDyn(&[sets, g.m, g.n, last]),
        _ => IxDyn(&[g.m, g.n, last]),
    };
    let go_on = || {
        if cancel.load(Ordering::Relaxed) {
            Err(Error::Cancelled {
                what: "simulate".into(),
            })
        } else {
            Ok(())
        }
    };
    let shaped = |e: ndarray::ShapeError| Error::param("codes", e.to_string());
    match format {
        CodesFormat::Seed => Ok(None),
        CodesFormat::Packed => {
            let nb = packed_len(k);
            let mut bytes = Vec::with_capacity(sets * g.pixels() * nb);
            for c in &sim.code_sets {
                go_on()?;
                bytes.extend(c.to_packbits()?);
            }
            let a = ArrayD::from_shape_vec(shape(nb), bytes).map_err(shaped)?;
            Ok(Some(CodeArray::Packed(a)))
        }
        CodesFormat::Int8 => {
            let keep = sim.active.as_ref().map(|active| {
                let mut keep = vec![false; g.pixels()];
                for &p in active {
                    keep[p] = true;
                }
                keep
            });
            let mut dense = Vec::with_capacity(sets * g.pixels() * k);
            for c in &sim.code_sets {
                for p in 0..g.pixels() {
                    if p % 256 == 0 {
                        go_on()?;
                    }
                    if keep.as_ref().is_some_and(|keep| !keep[p]) {
                        dense.resize(dense.len() + k, 0);
                    } else {
                        dense.extend((0..k).map(|t| c.get(p, t)));
                    }
                }
            }
            let a = ArrayD::from_shape_vec(shape(k), dense).map_err(shaped)?;
            Ok(Some(CodeArray::Int8(a)))
        }
    }
}
