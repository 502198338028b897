//! Reading the interchange arrays, checked against each other.

use std::ops::Range;
use std::path::Path;

use ndarray::{Array2, ArrayD, Ix1, Ix2, Ix3};

use crate::error::{Error, Result};
use crate::lidar::{packed_len, Codes, Pulse, Response, Scene};
use crate::real::Real;

use super::super::file_error;
use super::{
    check_ndim, first_bad, index_text, into_dim, open_npy, read_data, read_data_rows, read_real,
    read_real_rows, shape_text, wrong_dtype, NpyDtype,
};

/// Reads a scene: a float32 or float64 array of shape (M, N, K_s), converted to `T`.
///
/// # Errors
/// [`Error::File`] naming `path` for a file that cannot be read or is not a `.npy` file, another
/// dtype, another number of dimensions, an empty axis, or a NaN or infinite value (named by its
/// index).
pub fn read_scene<T: Real>(path: impl AsRef<Path>) -> Result<Scene<T>> {
    let path = path.as_ref();
    let a = into_dim::<T, Ix3>(path, read_real(path, "a scene", 3, "(M, N, K_s)")?)?;
    Scene::new(a).map_err(|e| file_error(path, e.to_string()))
}

/// Reads the pixel rows `rows` of a scene file (as [`read_scene`] reads the whole): from a C-order
/// file only those rows' bytes. Returns the whole scene's grid (M, N, K_s) and the band's scene
/// (rows.len(), N, K_s).
///
/// # Errors
/// As [`read_scene`] (a bad value named by its index in the whole file), and [`Error::File`]
/// for a band that is empty or beyond the scene's rows.
pub fn read_scene_rows<T: Real>(
    path: impl AsRef<Path>,
    rows: Range<usize>,
) -> Result<((usize, usize, usize), Scene<T>)> {
    let path = path.as_ref();
    let (shape, a) = read_real_rows(path, ("a scene", 3, "(M, N, K_s)"), Some(rows))?;
    let a = into_dim::<T, Ix3>(path, a)?;
    let scene = Scene::new(a).map_err(|e| file_error(path, e.to_string()))?;
    Ok(((shape[0], shape[1], shape[2]), scene))
}

/// Reads a pulse: a float32 or float64 vector of length K_p, converted to `T`, nonnegative and not
/// all zero.
///
/// # Errors
/// [`Error::File`] naming `path` for a file that cannot be read or is not a `.npy` file, another
/// dtype or number of dimensions, an empty pulse, a NaN, infinite or negative value (named by its
/// index), or an all-zero pulse.
pub fn read_pulse<T: Real>(path: impl AsRef<Path>) -> Result<Pulse<T>> {
    let path = path.as_ref();
    let a = into_dim::<T, Ix1>(path, read_real(path, "a pulse", 1, "(K_p,)")?)?;
    Pulse::new(a.into_raw_vec_and_offset().0).map_err(|e| file_error(path, e.to_string()))
}

/// Reads measurements: a float32 or float64 vector, converted to `T`.
///
/// With `expect`, the length must be K = K_p + K_s − 1.
///
/// # Errors
/// [`Error::File`] naming `path` for a file that cannot be read or is not a `.npy` file, another
/// dtype or number of dimensions, a length other than K, or a NaN or infinite value (named by its
/// index).
pub fn read_measurements<T: Real>(
    path: impl AsRef<Path>,
    expect: Option<&ShapeExpectation>,
) -> Result<Vec<T>> {
    let path = path.as_ref();
    // The length is checked from the header, before reading the data.
    if let Some(e) = expect {
        let h = open_npy(path)?.header;
        let k = e.samples();
        if matches!(h.dtype, NpyDtype::Float32 | NpyDtype::Float64)
            && h.shape.len() == 1
            && h.shape[0] != k
        {
            return Err(file_error(
                path,
                format!(
                    "measurements have {} samples, expected K = K_p + K_s − 1 = {} + {} − 1 = \
                     {k} (pulse length {}, {} depth bins)",
                    h.shape[0], e.pulse_len, e.depth_bins, e.pulse_len, e.depth_bins
                ),
            ));
        }
    }
    let a = into_dim::<T, Ix1>(path, read_real(path, "measurements", 1, "(K,)")?)?;
    Ok(a.into_raw_vec_and_offset().0)
}

/// Reads the measurements of several ADCs (one per code set, or one per tile of the array): a
/// float32 or float64 array of shape (R, K), row r holding the K samples of ADC r, converted to
/// `T`.
///
/// Only two-dimensional files are accepted; the (K,) measurements of one ADC are read by
/// [`read_measurements`]. With `expect`, the row length must be K = K_p + K_s − 1; with `rows`,
/// there must be that many rows.
///
/// # Errors
/// [`Error::File`] naming `path` for a file that cannot be read or is not a `.npy` file, another
/// dtype or number of dimensions, an empty axis, a row length other than K, a number of rows other
/// than `rows`, or a NaN or infinite value (named by its index).
pub fn read_measurement_rows<T: Real>(
    path: impl AsRef<Path>,
    expect: Option<&ShapeExpectation>,
    rows: Option<usize>,
) -> Result<Array2<T>> {
    let path = path.as_ref();
    let role = "measurements";
    // The shape is checked from the header, before reading the data.
    let h = open_npy(path)?.header;
    if !matches!(h.dtype, NpyDtype::Float32 | NpyDtype::Float64) {
        return Err(wrong_dtype(path, role, &h.dtype, "float32 or float64"));
    }
    check_ndim(path, role, &h, 2, "(ADCs, K), one row per ADC")?;
    if let Some(e) = expect {
        let k = e.samples();
        if h.shape[1] != k {
            return Err(file_error(
                path,
                format!(
                    "measurements shape {} has rows of {} samples, expected K = K_p + K_s − 1 = \
                     {} + {} − 1 = {k} (pulse length {}, {} depth bins)",
                    shape_text(&h.shape),
                    h.shape[1],
                    e.pulse_len,
                    e.depth_bins,
                    e.pulse_len,
                    e.depth_bins
                ),
            ));
        }
    }
    if let Some(r) = rows {
        if h.shape[0] != r {
            return Err(file_error(
                path,
                format!(
                    "measurements shape {} has {} {}, expected {r} (one per ADC)",
                    shape_text(&h.shape),
                    h.shape[0],
                    if h.shape[0] == 1 { "row" } else { "rows" }
                ),
            ));
        }
    }
    into_dim::<T, Ix2>(
        path,
        read_real(path, role, 2, "(ADCs, K), one row per ADC")?,
    )
}

/// What codes and measurements must fit: the pulse length, the depth bins and, when a scene is
/// given, its grid.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct ShapeExpectation {
    /// K_p, the pulse length.
    pub pulse_len: usize,
    /// K_s, the depth bins.
    pub depth_bins: usize,
    /// (M, N) of the scene, if known.
    pub grid: Option<(usize, usize)>,
}

impl ShapeExpectation {
    /// K = K_p + K_s − 1.
    pub fn samples(&self) -> usize {
        self.pulse_len
            .saturating_add(self.depth_bins)
            .saturating_sub(1)
    }
}

/// Reads codes: an int8 (or float32/float64) array of shape (M, N, K) with values in {−1, 0, 1},
/// K = K_p + K_s − 1, or ±1 codes packed as `np.packbits(S > 0, axis=-1)` writes them, a uint8
/// array of shape (M, N, ⌈K/8⌉) (see [`Codes::from_packbits`]). Returns (M, N) and the packed
/// codes (binary when no entry is 0, ternary otherwise).
///
/// # Errors
/// [`Error::File`] naming `path` for a file that cannot be read or is not a `.npy` file, another
/// dtype or number of dimensions, an empty axis, a grid other than `expect.grid`, a last axis other
/// than K (⌈K/8⌉ for packed codes), a value outside {−1, 0, 1} (named by its index), or packed
/// codes whose pad bits after sample K − 1 are not zero (named by the pixel);
/// [`Error::InvalidParameter`] if `expect` has a zero pulse length or zero depth bins.
pub fn read_codes(
    path: impl AsRef<Path>,
    expect: &ShapeExpectation,
) -> Result<((usize, usize), Codes)> {
    let path = path.as_ref();
    let (grid, sets) = read_code_rows(path, expect, 3, None)?;
    let codes = sets
        .into_iter()
        .next()
        .ok_or_else(|| file_error(path, "no codes"))?;
    Ok((grid, codes))
}

/// Reads G code sets, one per ADC of a multi-ADC array: an int8 (or float32/float64) array of
/// shape (G, M, N, K) with values in {−1, 0, 1}, K = K_p + K_s − 1, whose slice g is the
/// (M, N, K) codes of set g, or packed ±1 codes, uint8 of shape (G, M, N, ⌈K/8⌉). Returns
/// (M, N) and the G packed code sets, in order (each binary when it has no 0 entry, ternary
/// otherwise).
///
/// Only four-dimensional files are accepted; a single code set (M, N, K) is read by
/// [`read_codes`].
///
/// # Errors
/// As [`read_codes`], with four dimensions (G, M, N, K) expected: the grid is axes 1 and 2, K the
/// last axis, and a bad value is named by its four-dimensional index.
pub fn read_code_sets(
    path: impl AsRef<Path>,
    expect: &ShapeExpectation,
) -> Result<((usize, usize), Vec<Codes>)> {
    read_code_rows(path.as_ref(), expect, 4, None)
}

/// Reads the codes of the band `rows` of pixel rows only, of every code set: of an (M, N, K)
/// codes file (or packed) as [`read_codes`] reads it, one code set; of a (G, M, N, K) file as
/// [`read_code_sets`] reads it, G. Returns (M, N) of the whole file and each set's codes of
/// the band's pixels (row-major). From a C-order file only the band's bytes are read (one run
/// per code set); a Fortran-order file is read whole.
///
/// # Errors
/// As [`read_codes`] and [`read_code_sets`] (bad values named by their index in the whole
/// file); [`Error::File`] when `rows` is empty or beyond the file's M rows.
pub fn read_code_band(
    path: impl AsRef<Path>,
    expect: &ShapeExpectation,
    rows: Range<usize>,
) -> Result<((usize, usize), Vec<Codes>)> {
    let path = path.as_ref();
    let ndim = super::read_header(path)?.shape.len();
    read_code_rows(path, expect, if ndim == 4 { 4 } else { 3 }, Some(rows))
}

/// The codes of a file of `ndim` dimensions, (M, N, K) or (G, M, N, K), int8 or packed, of the
/// pixel rows `rows` (all when None): the whole grid and every set's codes.
fn read_code_rows(
    path: &Path,
    expect: &ShapeExpectation,
    ndim: usize,
    rows: Option<Range<usize>>,
) -> Result<((usize, usize), Vec<Codes>)> {
    if let Some((shape, sets)) = read_packed_codes(path, expect, ndim, rows.clone())? {
        return Ok(((shape[ndim - 3], shape[ndim - 2]), sets));
    }
    let axes = if ndim == 4 {
        "(G, M, N, K)"
    } else {
        "(M, N, K)"
    };
    let (shape, codes) = read_dense_codes(path, expect, ndim, axes, rows.clone())?;
    let (m, n, k) = (shape[ndim - 3], shape[ndim - 2], shape[ndim - 1]);
    let band = rows.map_or(m, |r| r.len());
    let sets = if ndim == 4 { shape[0] } else { 1 };
    let flat = codes
        .into_shape_with_order((sets, band * n, k))
        .map_err(|e| file_error(path, format!("cannot reshape the codes: {e}")))?;
    let packed = flat
        .outer_iter()
        .map(|set| Codes::from_dense(set).map_err(|e| file_error(path, e.to_string())))
        .collect::<Result<Vec<_>>>()?;
    Ok(((m, n), packed))
}

/// Refuses a band of pixel rows that is empty or beyond the `m` rows of the codes.
fn check_band(path: &Path, shape: &[usize], m: usize, rows: &Option<Range<usize>>) -> Result<()> {
    match rows {
        Some(r) if r.is_empty() || r.end > m => Err(file_error(
            path,
            format!(
                "codes of shape {} have {m} pixel rows: rows {}..{} are not a band of them",
                shape_text(shape),
                r.start,
                r.end
            ),
        )),
        _ => Ok(()),
    }
}

/// Reads a uint8 codes file of `ndim` dimensions whose last three axes are (M, N, ⌈K/8⌉), as
/// `np.packbits(S > 0, axis=-1)` writes ±1 codes: `None` for a file of another dtype, otherwise
/// the shape and the code sets (one for three dimensions, G for four), after the same checks as
/// [`read_dense_codes`] and that every pad bit is zero.
fn read_packed_codes(
    path: &Path,
    expect: &ShapeExpectation,
    ndim: usize,
    rows: Option<Range<usize>>,
) -> Result<Option<(Vec<usize>, Vec<Codes>)>> {
    check_expectation(expect)?;
    let opened = open_npy(path)?;
    if opened.header.dtype != NpyDtype::Uint8 {
        return Ok(None);
    }
    let h = opened.header.clone();
    let axes = if ndim == 4 {
        "(G, M, N, ⌈K/8⌉)"
    } else {
        "(M, N, ⌈K/8⌉)"
    };
    check_ndim(path, "packed codes (uint8)", &h, ndim, axes)?;
    let (m, n, nb) = (h.shape[ndim - 3], h.shape[ndim - 2], h.shape[ndim - 1]);
    check_grid(path, &h.shape, (m, n), expect)?;
    let k = expect.samples();
    let want = packed_len(k);
    if nb != want {
        return Err(file_error(
            path,
            format!(
                "packed codes (uint8) shape {} does not fit: the last axis must be ⌈K/8⌉ = \
                 ⌈{k}/8⌉ = {want} bytes for K = K_p + K_s − 1 = {} + {} − 1 = {k} samples \
                 (pulse length {}, {} depth bins), found {nb}",
                shape_text(&h.shape),
                expect.pulse_len,
                expect.depth_bins,
                expect.pulse_len,
                expect.depth_bins
            ),
        ));
    }
    check_band(path, &h.shape, m, &rows)?;
    let (first, band) = rows.as_ref().map_or((0, m), |r| (r.start, r.len()));
    let a = read_data_rows::<u8>(path, opened, ndim - 3, first..first + band)?;
    let bytes = a
        .as_slice()
        .ok_or_else(|| file_error(path, "cannot read the packed codes in C order"))?;
    let pad = 8 * nb - k;
    let per_set = band * n * nb;
    if pad > 0 {
        let mask = (1u8 << pad) - 1;
        if let Some(at) = (0..bytes.len() / nb).find(|p| bytes[p * nb + nb - 1] & mask != 0) {
            let pixel = at % (band * n);
            let row = first + pixel / n;
            let index = if ndim == 4 {
                format!("({}, {row}, {})", at / (band * n), pixel % n)
            } else {
                format!("({row}, {})", pixel % n)
            };
            return Err(file_error(
                path,
                format!(
                    "packed codes: the {pad} pad bit(s) after sample {} of pixel {index} are \
                     not zero (np.packbits writes zeros there; is K = {k} right?)",
                    k - 1
                ),
            ));
        }
    }
    let sets = bytes
        .chunks_exact(per_set)
        .map(|set| {
            Codes::from_packbits(set, band * n, k).map_err(|e| file_error(path, e.to_string()))
        })
        .collect::<Result<Vec<_>>>()?;
    Ok(Some((h.shape, sets)))
}

/// Refuses an expectation with a zero pulse length or zero depth bins.
fn check_expectation(expect: &ShapeExpectation) -> Result<()> {
    if expect.pulse_len == 0 || expect.depth_bins == 0 {
        return Err(Error::param(
            "expect",
            format!(
                "pulse length and depth bins must be at least 1, got {} and {}",
                expect.pulse_len, expect.depth_bins
            ),
        ));
    }
    Ok(())
}

/// Checks the (M, N) of a codes file against the scene's grid, if known.
fn check_grid(
    path: &Path,
    shape: &[usize],
    (m, n): (usize, usize),
    expect: &ShapeExpectation,
) -> Result<()> {
    if let Some((gm, gn)) = expect.grid {
        if (m, n) != (gm, gn) {
            return Err(file_error(
                path,
                format!(
                    "codes shape {} has {m}x{n} pixels, the scene has {gm}x{gn}",
                    shape_text(shape)
                ),
            ));
        }
    }
    Ok(())
}

/// The dtypes a codes file may have, for error messages.
const CODE_DTYPES: &str =
    "int8 (or float32/float64 holding −1, 0, 1), or uint8 bits as np.packbits writes them";

/// Reads and checks a codes file of `ndim` dimensions whose last three axes are (M, N, K): the
/// dtype, the number of dimensions, empty axes, the grid, K and the values. Returns the shape and
/// the values as int8, in C order.
fn read_dense_codes(
    path: &Path,
    expect: &ShapeExpectation,
    ndim: usize,
    axes: &str,
    rows: Option<Range<usize>>,
) -> Result<(Vec<usize>, ArrayD<i8>)> {
    check_expectation(expect)?;
    let opened = open_npy(path)?;
    let h = opened.header.clone();
    let role = "codes";
    if !matches!(
        h.dtype,
        NpyDtype::Int8 | NpyDtype::Float32 | NpyDtype::Float64
    ) {
        return Err(wrong_dtype(path, role, &h.dtype, CODE_DTYPES));
    }
    check_ndim(path, role, &h, ndim, axes)?;
    let (m, n, k) = (h.shape[ndim - 3], h.shape[ndim - 2], h.shape[ndim - 1]);
    check_grid(path, &h.shape, (m, n), expect)?;
    let want = expect.samples();
    if k != want {
        return Err(file_error(
            path,
            format!(
                "codes shape {} does not fit: the last axis must be K = K_p + K_s − 1 = \
                 {} + {} − 1 = {want} (pulse length {}, {} depth bins), found {k}",
                shape_text(&h.shape),
                expect.pulse_len,
                expect.depth_bins,
                expect.pulse_len,
                expect.depth_bins
            ),
        ));
    }
    check_band(path, &h.shape, m, &rows)?;
    let band = rows.unwrap_or(0..m);
    let first = band.start;
    let bad_value = |idx: &[usize], v: String| {
        // The index in the whole file.
        let mut idx = idx.to_vec();
        idx[ndim - 3] += first;
        file_error(
            path,
            format!(
                "codes value {v} at index {} is not in {{-1, 0, 1}}",
                index_text(&idx)
            ),
        )
    };
    let codes: ArrayD<i8> = match h.dtype {
        NpyDtype::Int8 => {
            let a = read_data_rows::<i8>(path, opened, ndim - 3, band)?;
            if let Some((i, v)) = first_bad(&a, |v| (-1..=1).contains(&v)) {
                return Err(bad_value(&i, v.to_string()));
            }
            a
        }
        NpyDtype::Float32 => float_codes(
            read_data_rows::<f32>(path, opened, ndim - 3, band)?,
            bad_value,
        )?,
        NpyDtype::Float64 => float_codes(
            read_data_rows::<f64>(path, opened, ndim - 3, band)?,
            bad_value,
        )?,
        ref other => return Err(wrong_dtype(path, role, other, CODE_DTYPES)),
    };
    Ok((h.shape, codes))
}

fn float_codes<S: Copy + Into<f64> + std::fmt::Display>(
    a: ArrayD<S>,
    bad: impl Fn(&[usize], String) -> Error,
) -> Result<ArrayD<i8>> {
    if let Some((i, v)) = first_bad(&a, |v| {
        let x: f64 = v.into();
        x == -1.0 || x == 0.0 || x == 1.0
    }) {
        return Err(bad(&i, v.to_string()));
    }
    Ok(a.mapv(|v| v.into() as i8))
}

/// Reads a depth map: an int32 array of shape (M, N) whose entries are depth bins, −1 for no
/// return. With `depth_bins` = K_s, bins must lie in [−1, K_s).
///
/// # Errors
/// [`Error::File`] naming `path` for a file that cannot be read or is not a `.npy` file, another
/// dtype or number of dimensions, an empty axis, or an entry out of range (named by its index).
pub fn read_depth(path: impl AsRef<Path>, depth_bins: Option<usize>) -> Result<Array2<i32>> {
    let path = path.as_ref();
    let opened = open_npy(path)?;
    let h = opened.header.clone();
    if h.dtype != NpyDtype::Int32 {
        return Err(wrong_dtype(path, "a depth map", &h.dtype, "int32"));
    }
    check_ndim(path, "a depth map", &h, 2, "(M, N)")?;
    let a = into_dim::<i32, Ix2>(path, read_data::<i32>(path, opened)?)?;
    let top = depth_bins.map_or(i64::MAX, |k| k as i64);
    if let Some(((i, j), d)) = a
        .indexed_iter()
        .find(|(_, &d)| d < -1 || i64::from(d) >= top)
    {
        let range = match depth_bins {
            Some(k) => format!("[-1, {k})"),
            None => "≥ -1".to_string(),
        };
        return Err(file_error(
            path,
            format!(
                "depth bin {d} at index ({i}, {j}) is out of range: expected {range} (-1 = no \
                 return)"
            ),
        ));
    }
    Ok(a)
}

/// The system's response a specification names ([`Response::parse_with`]), a measured one's
/// samples read from its `.npy` file (a float32 or float64 vector).
///
/// # Errors
/// [`Error::InvalidParameter`] (`kernel`) for a bad specification or samples;
/// [`Error::File`] naming the file that cannot be read or is not a vector of floats.
pub fn read_response(spec: &str) -> Result<Response> {
    Response::parse_with(spec, &|path| {
        let a = into_dim::<f64, Ix1>(path, read_real(path, "a measured response", 1, "(S,)")?)?;
        Ok(a.to_vec())
    })
}

/// Reads continuous depths as `range.npy` holds them: float32 or float64, (M, N) or (R, M, N)
/// for several returns per pixel, in bins, NaN where there is no return; returned in f64.
///
/// # Errors
/// [`Error::File`] naming `path` for a file that cannot be read or is not a `.npy` file, another
/// dtype or number of dimensions, an empty axis, or an infinite value (named by its index).
pub fn read_range(path: impl AsRef<Path>) -> Result<ArrayD<f64>> {
    let path = path.as_ref();
    let role = "a range map";
    let opened = open_npy(path)?;
    let h = opened.header.clone();
    let ndim = if h.shape.len() == 3 { 3 } else { 2 };
    check_ndim(path, role, &h, ndim, "(M, N) or (R, M, N)")?;
    let a: ArrayD<f64> = match h.dtype {
        NpyDtype::Float64 => read_data::<f64>(path, opened)?,
        NpyDtype::Float32 => read_data::<f32>(path, opened)?.mapv(f64::from),
        other => return Err(wrong_dtype(path, role, &other, "float32 or float64")),
    };
    if let Some((i, v)) = first_bad(&a, |v| !v.is_infinite()) {
        return Err(file_error(
            path,
            format!(
                "{role} holds the infinite value {v} at index {}",
                index_text(&i)
            ),
        ));
    }
    Ok(a)
}
