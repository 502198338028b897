//! NumPy `.npy` arrays: the scene, pulse, codes, measurements and depth files of DESIGN.md §8.
//!
//! | file         | shape       | dtype read                       | dtype written      |
//! |--------------|-------------|----------------------------------|--------------------|
//! | scene        | (M, N, K_s) | float32, float64                 | as `T`             |
//! | pulse        | (K_p,)      | float32, float64; ≥ 0, not all 0 | as `T`             |
//! | codes        | (M, N, K)   | int8, float32, float64 in {−1, 0, 1} | int8           |
//! | measurements | (K,)        | float32, float64                 | as `T`             |
//! | depth        | (M, N)      | int32, −1 = no return            | int32              |
//!
//! The architecture variants of [`crate::lidar`] have files of their own, read and written only
//! by the functions made for them: G code sets of a multi-ADC array, (G, M, N, K) int8
//! ([`read_code_sets`], [`write_code_sets`]), and the measurements of several ADCs, (R, K) with
//! one row per ADC ([`read_measurement_rows`], written by [`write_array`]). The codes of a coded
//! aperture are ordinary (M, N, K) codes that are 0 outside the aperture
//! ([`write_masked_codes`]). The readers of the table above never accept these shapes.
//!
//! Readers check, in this order and before reading the data: that the file opens and is a `.npy`
//! file, the dtype, the number of dimensions, that no axis is empty, that the shape fits the other
//! inputs (K = K_p + K_s − 1 for codes and measurements), and that the file holds exactly the
//! bytes the shape needs (truncated files and trailing bytes are rejected). Then the values: NaN or
//! infinite entries (the first one is named by its index), negative or all-zero pulses, codes
//! outside {−1, 0, 1}, depth bins outside [−1, K_s). Floating-point data of either width is
//! converted to the requested `T`. Fortran-order (column-major) files are accepted and read
//! correctly; files are always written in C order. Every failure is an
//! [`Error::File`] whose message starts with the path.

use std::borrow::Borrow;
use std::fs::File;
use std::io::{BufReader, Seek, Write};
use std::path::Path;

use ndarray::{Array2, ArrayBase, ArrayD, Data, Dimension, Ix1, Ix2, Ix3};
use ndarray_npy::npy::header::{Header, Layout, ParseHeaderError, ReadHeaderError};
use ndarray_npy::{ReadNpyError, ReadNpyExt, ReadableElement, WritableElement, WriteNpyExt};

use crate::error::{Error, Result};
use crate::lidar::{Codes, Pulse, Scene};
use crate::real::Real;

use super::{file_error, StagedFile};

/// The element type of a `.npy` file, from its header's `descr`.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum NpyDtype {
    /// `float32` (`<f4` or `>f4`).
    Float32,
    /// `float64` (`<f8` or `>f8`).
    Float64,
    /// `int8` (`|i1`).
    Int8,
    /// `int32` (`<i4` or `>i4`).
    Int32,
    /// Anything else, described in NumPy's words where possible (e.g. `"int64"`, `"bool"`).
    Other(String),
}

impl NpyDtype {
    fn from_descr(descr: &str) -> Self {
        match descr {
            "<f4" | ">f4" => NpyDtype::Float32,
            "<f8" | ">f8" => NpyDtype::Float64,
            "|i1" | "i1" | "b" => NpyDtype::Int8,
            "<i4" | ">i4" => NpyDtype::Int32,
            other => NpyDtype::Other(describe_descr(other)),
        }
    }

    /// NumPy's name of the type: `"float32"`, `"float64"`, `"int8"`, `"int32"`, or the
    /// description of another type.
    pub fn name(&self) -> &str {
        match self {
            NpyDtype::Float32 => "float32",
            NpyDtype::Float64 => "float64",
            NpyDtype::Int8 => "int8",
            NpyDtype::Int32 => "int32",
            NpyDtype::Other(s) => s,
        }
    }

    fn item_size(&self) -> Option<usize> {
        match self {
            NpyDtype::Float32 | NpyDtype::Int32 => Some(4),
            NpyDtype::Float64 => Some(8),
            NpyDtype::Int8 => Some(1),
            NpyDtype::Other(_) => None,
        }
    }
}

impl std::fmt::Display for NpyDtype {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(self.name())
    }
}

/// A readable name for a NumPy type string such as `<i8` (`int64`) or `|b1` (`bool`).
fn describe_descr(descr: &str) -> String {
    let body = descr.trim_start_matches(['<', '>', '|', '=']);
    let mut chars = body.chars();
    let kind = chars.next();
    let size: Option<usize> = chars.as_str().parse().ok();
    let name = match (kind, size) {
        (Some('b'), Some(1)) => Some("bool".to_string()),
        (Some('i'), Some(s)) => Some(format!("int{}", 8 * s)),
        (Some('u'), Some(s)) => Some(format!("uint{}", 8 * s)),
        (Some('f'), Some(s)) => Some(format!("float{}", 8 * s)),
        (Some('c'), Some(s)) => Some(format!("complex{}", 8 * s)),
        (Some('U'), _) | (Some('S'), _) => Some("string".to_string()),
        (Some('O'), _) => Some("object".to_string()),
        _ => None,
    };
    match name {
        Some(n) => format!("{n} ('{descr}')"),
        None => format!("'{descr}'"),
    }
}

/// What a `.npy` header says about the array.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct NpyHeader {
    /// The element type.
    pub dtype: NpyDtype,
    /// The shape.
    pub shape: Vec<usize>,
    /// `true` for a Fortran-order (column-major) file.
    pub fortran_order: bool,
}

/// Formats a shape as NumPy prints it: `(4, 5, 6)`, `(7,)`.
pub fn shape_text(shape: &[usize]) -> String {
    match shape {
        [n] => format!("({n},)"),
        _ => format!(
            "({})",
            shape
                .iter()
                .map(|d| d.to_string())
                .collect::<Vec<_>>()
                .join(", ")
        ),
    }
}

/// Formats an index: `5` in one dimension, `(1, 2, 3)` otherwise.
fn index_text(index: &[usize]) -> String {
    match index {
        [i] => i.to_string(),
        _ => format!(
            "({})",
            index
                .iter()
                .map(|d| d.to_string())
                .collect::<Vec<_>>()
                .join(", ")
        ),
    }
}

/// The C-order multi-index of flat position `flat` in an array of shape `shape`.
fn unravel(mut flat: usize, shape: &[usize]) -> Vec<usize> {
    let mut idx = vec![0; shape.len()];
    for (i, &d) in idx.iter_mut().zip(shape).rev() {
        *i = flat % d.max(1);
        flat /= d.max(1);
    }
    idx
}

/// The flat position and value of the first element of a C-order array failing `ok`.
fn first_bad<A: Copy>(a: &ArrayD<A>, ok: impl Fn(A) -> bool) -> Option<(Vec<usize>, A)> {
    let found = match a.as_slice() {
        Some(flat) => flat.iter().position(|&v| !ok(v)),
        None => a.iter().position(|&v| !ok(v)),
    }?;
    let idx = unravel(found, a.shape());
    let v = a[idx.as_slice()];
    Some((idx, v))
}

/// An open `.npy` file with its parsed header, positioned at the start of the file.
struct Opened {
    header: NpyHeader,
    reader: BufReader<File>,
}

fn open_npy(path: &Path) -> Result<Opened> {
    let file = File::open(path).map_err(|e| {
        let reason = match e.kind() {
            std::io::ErrorKind::NotFound => "no such file".to_string(),
            _ => format!("cannot open: {e}"),
        };
        file_error(path, reason)
    })?;
    let meta = file
        .metadata()
        .map_err(|e| file_error(path, format!("cannot read: {e}")))?;
    if meta.is_dir() {
        return Err(file_error(path, "is a directory, expected a .npy file"));
    }
    let file_len = meta.len();
    let mut reader = BufReader::with_capacity(1 << 20, file);
    let header = Header::from_reader(&mut reader).map_err(|e| match e {
        ReadHeaderError::Io(e) if e.kind() == std::io::ErrorKind::UnexpectedEof => {
            if file_len < 6 {
                file_error(
                    path,
                    format!("not a .npy file: only {file_len} bytes, too short for a header"),
                )
            } else {
                file_error(path, "truncated .npy file: the file ends inside the header")
            }
        }
        ReadHeaderError::Io(e) => file_error(path, format!("cannot read: {e}")),
        ReadHeaderError::Parse(ParseHeaderError::MagicString) => file_error(
            path,
            "not a .npy file: it does not start with the NumPy magic string \\x93NUMPY",
        ),
        ReadHeaderError::Parse(e) => file_error(path, format!("invalid .npy header: {e}")),
    })?;
    let header_len = reader
        .stream_position()
        .map_err(|e| file_error(path, format!("cannot read: {e}")))?;
    let dtype = match header.type_descriptor.as_string() {
        Some(s) => NpyDtype::from_descr(s),
        None => NpyDtype::Other(format!("structured dtype {}", header.type_descriptor)),
    };
    let info = NpyHeader {
        dtype,
        shape: header.shape.clone(),
        fortran_order: matches!(header.layout, Layout::Fortran),
    };
    // The data must be exactly what the shape needs: reject truncated files and trailing bytes
    // here, before allocating anything for the data.
    if let Some(item) = info.dtype.item_size() {
        let shape = shape_text(&info.shape);
        let needed = info
            .shape
            .iter()
            .try_fold(item as u64, |acc, &d| acc.checked_mul(d as u64))
            .ok_or_else(|| file_error(path, format!("shape {shape} is too large")))?;
        let have = file_len.saturating_sub(header_len);
        if have < needed {
            return Err(file_error(
                path,
                format!(
                    "truncated .npy file: shape {shape} of {} needs {needed} bytes of data, \
                     the file holds {have}",
                    info.dtype
                ),
            ));
        }
        if have > needed {
            return Err(file_error(
                path,
                format!(
                    "{} unexpected bytes after the data of shape {shape} of {}",
                    have - needed,
                    info.dtype
                ),
            ));
        }
        if usize::try_from(needed).is_err() {
            return Err(file_error(path, format!("shape {shape} is too large")));
        }
    }
    reader
        .rewind()
        .map_err(|e| file_error(path, format!("cannot read: {e}")))?;
    Ok(Opened {
        header: info,
        reader,
    })
}

/// Reads the header of a `.npy` file (dtype, shape, order) without reading the data.
///
/// # Errors
/// [`Error::File`] naming `path` if it cannot be opened, is not a `.npy` file, or its size does
/// not match the header's shape and dtype (a truncated file or trailing bytes).
pub fn read_header(path: impl AsRef<Path>) -> Result<NpyHeader> {
    open_npy(path.as_ref()).map(|o| o.header)
}

fn read_error(path: &Path, e: ReadNpyError) -> Error {
    let reason = match e {
        ReadNpyError::MissingData => "truncated .npy file: the data ends early".to_string(),
        ReadNpyError::ExtraBytes(n) => format!("{n} unexpected bytes after the data"),
        ReadNpyError::Io(e) => format!("cannot read: {e}"),
        other => format!("invalid .npy file: {other}"),
    };
    file_error(path, reason)
}

/// Reads the data of an opened file as elements `E` (the dtype has been checked), in C order.
fn read_data<E: ReadableElement + Clone>(path: &Path, opened: Opened) -> Result<ArrayD<E>> {
    let a = ArrayD::<E>::read_npy(opened.reader).map_err(|e| read_error(path, e))?;
    Ok(if a.is_standard_layout() {
        a
    } else {
        a.as_standard_layout().into_owned()
    })
}

/// Checks the number of dimensions and that no axis is empty.
fn check_ndim(path: &Path, role: &str, h: &NpyHeader, ndim: usize, axes: &str) -> Result<()> {
    if h.shape.len() != ndim {
        return Err(file_error(
            path,
            format!(
                "{role} must have {ndim} dimension{} {axes}, found {} (shape {})",
                if ndim == 1 { "" } else { "s" },
                h.shape.len(),
                shape_text(&h.shape)
            ),
        ));
    }
    if h.shape.contains(&0) {
        return Err(file_error(
            path,
            format!(
                "{role} is empty: shape {} has an axis of length 0",
                shape_text(&h.shape)
            ),
        ));
    }
    Ok(())
}

fn wrong_dtype(path: &Path, role: &str, found: &NpyDtype, accepted: &str) -> Error {
    file_error(
        path,
        format!("dtype {found} is not accepted for {role}: expected {accepted}"),
    )
}

/// Converts floating-point data to `T`, naming the first NaN or infinite value (and values that
/// overflow `T`).
fn to_real<T: Real, S: Copy + Into<f64>>(
    path: &Path,
    role: &str,
    a: ArrayD<S>,
) -> Result<ArrayD<T>> {
    if let Some((i, v)) = first_bad(&a, |v| v.into().is_finite()) {
        let v: f64 = v.into();
        let what = if v.is_nan() {
            "NaN".to_string()
        } else {
            format!("infinite value {v}")
        };
        return Err(file_error(
            path,
            format!("{role} holds {what} at index {}", index_text(&i)),
        ));
    }
    let out = a.mapv(|v| T::of_f64(v.into()));
    if let Some((i, _)) = first_bad(&out, |v| v.is_finite()) {
        let v: f64 = a[i.as_slice()].into();
        return Err(file_error(
            path,
            format!(
                "{role} value {v:e} at index {} overflows {}",
                index_text(&i),
                T::NAME
            ),
        ));
    }
    Ok(out)
}

/// Reads a floating-point array of `ndim` dimensions as `T`.
fn read_real<T: Real>(path: &Path, role: &str, ndim: usize, axes: &str) -> Result<ArrayD<T>> {
    let opened = open_npy(path)?;
    let h = opened.header.clone();
    let accept = |found: &NpyDtype| wrong_dtype(path, role, found, "float32 or float64");
    if !matches!(h.dtype, NpyDtype::Float32 | NpyDtype::Float64) {
        return Err(accept(&h.dtype));
    }
    check_ndim(path, role, &h, ndim, axes)?;
    match h.dtype {
        NpyDtype::Float32 => to_real(path, role, read_data::<f32>(path, opened)?),
        NpyDtype::Float64 => to_real(path, role, read_data::<f64>(path, opened)?),
        ref other => Err(accept(other)),
    }
}

fn into_dim<T, D: Dimension>(path: &Path, a: ArrayD<T>) -> Result<ndarray::Array<T, D>> {
    let ndim = a.ndim();
    a.into_dimensionality::<D>().map_err(|_| {
        file_error(
            path,
            format!("unexpected number of dimensions {ndim} after reading"),
        )
    })
}

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
    if let Some((i, v)) = a.indexed_iter().find(|(_, v)| **v < T::zero()) {
        return Err(file_error(
            path,
            format!(
                "pulse value {v} at index {i} is negative: a pulse is light intensity, which \
                 must be ≥ 0"
            ),
        ));
    }
    if a.iter().all(|v| *v == T::zero()) {
        return Err(file_error(
            path,
            format!(
                "pulse is all zero ({} samples): nothing is transmitted",
                a.len()
            ),
        ));
    }
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
                    "measurements shape {} has {} rows, expected {r} (one per ADC)",
                    shape_text(&h.shape),
                    h.shape[0]
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
/// K = K_p + K_s − 1. Returns (M, N) and the packed codes (binary when no entry is 0, ternary
/// otherwise).
///
/// # Errors
/// [`Error::File`] naming `path` for a file that cannot be read or is not a `.npy` file, another
/// dtype or number of dimensions, an empty axis, a grid other than `expect.grid`, a last axis other
/// than K, or a value outside {−1, 0, 1} (named by its index); [`Error::InvalidParameter`] if
/// `expect` has a zero pulse length or zero depth bins.
pub fn read_codes(
    path: impl AsRef<Path>,
    expect: &ShapeExpectation,
) -> Result<((usize, usize), Codes)> {
    let path = path.as_ref();
    let (shape, codes) = read_dense_codes(path, expect, 3, "(M, N, K)")?;
    let (m, n, k) = (shape[0], shape[1], shape[2]);
    let flat = codes
        .into_shape_with_order((m * n, k))
        .map_err(|e| file_error(path, format!("cannot reshape the codes: {e}")))?;
    let packed = Codes::from_dense(flat.view()).map_err(|e| file_error(path, e.to_string()))?;
    Ok(((m, n), packed))
}

/// Reads G code sets, one per ADC of a multi-ADC array: an int8 (or float32/float64) array of
/// shape (G, M, N, K) with values in {−1, 0, 1}, K = K_p + K_s − 1, whose slice g is the
/// (M, N, K) codes of set g. Returns (M, N) and the G packed code sets, in order (each binary
/// when it has no 0 entry, ternary otherwise).
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
    let path = path.as_ref();
    let (shape, codes) = read_dense_codes(path, expect, 4, "(G, M, N, K)")?;
    let (sets, m, n, k) = (shape[0], shape[1], shape[2], shape[3]);
    let flat = codes
        .into_shape_with_order((sets, m * n, k))
        .map_err(|e| file_error(path, format!("cannot reshape the codes: {e}")))?;
    let packed = flat
        .outer_iter()
        .map(|set| Codes::from_dense(set).map_err(|e| file_error(path, e.to_string())))
        .collect::<Result<Vec<_>>>()?;
    Ok(((m, n), packed))
}

/// Reads and checks a codes file of `ndim` dimensions whose last three axes are (M, N, K): the
/// dtype, the number of dimensions, empty axes, the grid, K and the values. Returns the shape and
/// the values as int8, in C order.
fn read_dense_codes(
    path: &Path,
    expect: &ShapeExpectation,
    ndim: usize,
    axes: &str,
) -> Result<(Vec<usize>, ArrayD<i8>)> {
    if expect.pulse_len == 0 || expect.depth_bins == 0 {
        return Err(Error::param(
            "expect",
            format!(
                "pulse length and depth bins must be at least 1, got {} and {}",
                expect.pulse_len, expect.depth_bins
            ),
        ));
    }
    let opened = open_npy(path)?;
    let h = opened.header.clone();
    let role = "codes";
    if !matches!(
        h.dtype,
        NpyDtype::Int8 | NpyDtype::Float32 | NpyDtype::Float64
    ) {
        return Err(wrong_dtype(
            path,
            role,
            &h.dtype,
            "int8 (or float32/float64 holding −1, 0, 1)",
        ));
    }
    check_ndim(path, role, &h, ndim, axes)?;
    let (m, n, k) = (h.shape[ndim - 3], h.shape[ndim - 2], h.shape[ndim - 1]);
    if let Some((gm, gn)) = expect.grid {
        if (m, n) != (gm, gn) {
            return Err(file_error(
                path,
                format!(
                    "codes shape {} has {m}x{n} pixels, the scene has {gm}x{gn}",
                    shape_text(&h.shape)
                ),
            ));
        }
    }
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
    let bad_value = |idx: &[usize], v: String| {
        file_error(
            path,
            format!(
                "codes value {v} at index {} is not in {{-1, 0, 1}}",
                index_text(idx)
            ),
        )
    };
    let codes: ArrayD<i8> = match h.dtype {
        NpyDtype::Int8 => {
            let a = read_data::<i8>(path, opened)?;
            if let Some((i, v)) = first_bad(&a, |v| (-1..=1).contains(&v)) {
                return Err(bad_value(&i, v.to_string()));
            }
            a
        }
        NpyDtype::Float32 => float_codes(read_data::<f32>(path, opened)?, bad_value)?,
        NpyDtype::Float64 => float_codes(read_data::<f64>(path, opened)?, bad_value)?,
        ref other => {
            return Err(wrong_dtype(
                path,
                role,
                other,
                "int8 (or float32/float64 holding −1, 0, 1)",
            ))
        }
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

/// Writes any array as a C-order `.npy` file, atomically (see [`crate::io`]).
///
/// # Errors
/// [`Error::File`] naming `path` if the file cannot be created, written, synced or renamed; the
/// destination is then left as it was.
pub fn write_array<A, S, D>(path: impl AsRef<Path>, array: &ArrayBase<S, D>) -> Result<()>
where
    A: WritableElement + Clone,
    S: Data<Elem = A>,
    D: Dimension,
{
    stage_array(path, array)?.commit()
}

/// Writes any array as a C-order `.npy` file under a temporary name and syncs it, without
/// renaming it into place: [`StagedFile::commit`] (or [`super::commit_all`] for a set of files)
/// does that, and dropping the result removes it.
///
/// # Errors
/// As [`write_array`].
pub fn stage_array<A, S, D>(path: impl AsRef<Path>, array: &ArrayBase<S, D>) -> Result<StagedFile>
where
    A: WritableElement + Clone,
    S: Data<Elem = A>,
    D: Dimension,
{
    let path = path.as_ref();
    let c = array.as_standard_layout();
    let mut staged = StagedFile::create(path)?;
    c.write_npy(&mut *staged.writer())
        .map_err(|e| file_error(path, format!("cannot write: {e}")))?;
    staged.sync()?;
    Ok(staged)
}

/// Writes a scene, shape (M, N, K_s), with the dtype of `T`.
///
/// # Errors
/// As [`write_array`].
pub fn write_scene<T: Real + WritableElement>(
    path: impl AsRef<Path>,
    scene: &Scene<T>,
) -> Result<()> {
    write_array(path, scene.data())
}

/// Writes a pulse, shape (K_p,), with the dtype of `T`.
///
/// # Errors
/// As [`write_array`].
pub fn write_pulse<T: Real + WritableElement>(path: impl AsRef<Path>, pulse: &[T]) -> Result<()> {
    write_array(path, &ndarray::ArrayView1::from(pulse))
}

/// Writes measurements, shape (K,), with the dtype of `T`.
///
/// # Errors
/// As [`write_array`].
pub fn write_measurements<T: Real + WritableElement>(
    path: impl AsRef<Path>,
    y: &[T],
) -> Result<()> {
    write_array(path, &ndarray::ArrayView1::from(y))
}

/// Writes a depth map, shape (M, N), as int32.
///
/// # Errors
/// As [`write_array`].
pub fn write_depth(path: impl AsRef<Path>, depth: &Array2<i32>) -> Result<()> {
    write_array(path, depth)
}

/// Writes codes as an int8 array of shape (M, N, K), atomically.
///
/// # Errors
/// As [`stage_codes`], or [`Error::File`] if the file cannot be renamed into place.
pub fn write_codes(path: impl AsRef<Path>, grid: (usize, usize), codes: &Codes) -> Result<()> {
    stage_codes(path, grid, codes)?.commit()
}

/// Writes codes as an int8 array of shape (M, N, K) under a temporary name, one pixel row at a
/// time (the dense array is never held in memory), and syncs it; see [`stage_array`].
///
/// # Errors
/// [`Error::ShapeMismatch`] if `grid` does not have the codes' number of pixels; [`Error::File`]
/// naming `path` if the file cannot be created, written or synced.
pub fn stage_codes(
    path: impl AsRef<Path>,
    grid: (usize, usize),
    codes: &Codes,
) -> Result<StagedFile> {
    let path = path.as_ref();
    check_grid("write_codes", grid, codes)?;
    let (m, n) = grid;
    let mut staged = start_codes_file(path, vec![m, n, codes.len()])?;
    write_code_rows(path, staged.writer(), codes, None)?;
    staged.sync()?;
    Ok(staged)
}

/// Writes G code sets (one per ADC of a multi-ADC array) as an int8 array of shape
/// (G, M, N, K), atomically: slice g holds the codes of `sets[g]`, as [`write_codes`] writes them.
///
/// # Errors
/// As [`stage_code_sets`], or [`Error::File`] if the file cannot be renamed into place.
pub fn write_code_sets<C: Borrow<Codes>>(
    path: impl AsRef<Path>,
    grid: (usize, usize),
    sets: &[C],
) -> Result<()> {
    stage_code_sets(path, grid, sets)?.commit()
}

/// Writes G code sets as an int8 array of shape (G, M, N, K) under a temporary name, one pixel
/// row at a time, and syncs it; see [`stage_array`].
///
/// # Errors
/// [`Error::InvalidParameter`] for an empty list of sets; [`Error::ShapeMismatch`] if `grid`
/// does not have a set's number of pixels or the sets differ in their number of samples;
/// [`Error::File`] naming `path` if the file cannot be created, written or synced.
pub fn stage_code_sets<C: Borrow<Codes>>(
    path: impl AsRef<Path>,
    grid: (usize, usize),
    sets: &[C],
) -> Result<StagedFile> {
    let path = path.as_ref();
    let first = sets
        .first()
        .ok_or_else(|| Error::param("sets", "need at least one code set"))?
        .borrow();
    for (i, set) in sets.iter().enumerate() {
        let set = set.borrow();
        check_grid("write_code_sets", grid, set)?;
        if set.len() != first.len() {
            return Err(Error::shape(
                format!("write_code_sets: samples of set {i} vs set 0"),
                first.len(),
                set.len(),
            ));
        }
    }
    let (m, n) = grid;
    let mut staged = start_codes_file(path, vec![sets.len(), m, n, first.len()])?;
    for set in sets {
        write_code_rows(path, staged.writer(), set.borrow(), None)?;
    }
    staged.sync()?;
    Ok(staged)
}

/// Writes the codes of a coded aperture as an int8 array of shape (M, N, K), atomically: the
/// pixels listed in `active` keep their codes, every other pixel's codes are written as 0 (so the
/// single-ADC operator of the file is the coded-aperture operator).
///
/// # Errors
/// As [`stage_masked_codes`], or [`Error::File`] if the file cannot be renamed into place.
pub fn write_masked_codes(
    path: impl AsRef<Path>,
    grid: (usize, usize),
    codes: &Codes,
    active: &[usize],
) -> Result<()> {
    stage_masked_codes(path, grid, codes, active)?.commit()
}

/// Writes the codes of a coded aperture (0 outside the pixels `active`) as an int8 array of
/// shape (M, N, K) under a temporary name, one pixel row at a time, and syncs it; see
/// [`stage_array`].
///
/// # Errors
/// [`Error::ShapeMismatch`] if `grid` does not have the codes' number of pixels;
/// [`Error::IndexOutOfBounds`] for an active pixel not below M·N; [`Error::File`] naming `path` if
/// the file cannot be created, written or synced.
pub fn stage_masked_codes(
    path: impl AsRef<Path>,
    grid: (usize, usize),
    codes: &Codes,
    active: &[usize],
) -> Result<StagedFile> {
    let path = path.as_ref();
    check_grid("write_masked_codes", grid, codes)?;
    let mut mask = vec![false; codes.pixels()];
    for &p in active {
        *mask.get_mut(p).ok_or(Error::IndexOutOfBounds {
            context: "write_masked_codes: active pixels",
            index: p,
            len: codes.pixels(),
        })? = true;
    }
    let (m, n) = grid;
    let mut staged = start_codes_file(path, vec![m, n, codes.len()])?;
    write_code_rows(path, staged.writer(), codes, Some(&mask))?;
    staged.sync()?;
    Ok(staged)
}

/// Checks that an M × N grid has the codes' number of pixels.
fn check_grid(context: &str, grid: (usize, usize), codes: &Codes) -> Result<()> {
    let (m, n) = grid;
    if m.checked_mul(n) != Some(codes.pixels()) {
        return Err(Error::shape(
            format!("{context}: pixels of the {m}x{n} grid vs the codes"),
            codes.pixels(),
            m.saturating_mul(n),
        ));
    }
    Ok(())
}

/// Creates the temporary file of an int8 array of shape `shape` and writes its header.
fn start_codes_file(path: &Path, shape: Vec<usize>) -> Result<StagedFile> {
    let header = Header {
        type_descriptor: <i8 as WritableElement>::type_descriptor(),
        layout: Layout::Standard,
        shape,
    };
    let mut staged = StagedFile::create(path)?;
    header
        .write(&mut *staged.writer())
        .map_err(|e| file_error(path, format!("cannot write the header: {e}")))?;
    Ok(staged)
}

/// Writes the codes as int8, pixel after pixel, K bytes per pixel; the pixels whose entry in
/// `mask` is `false` are written as 0.
fn write_code_rows(
    path: &Path,
    w: &mut impl Write,
    codes: &Codes,
    mask: Option<&[bool]>,
) -> Result<()> {
    let k = codes.len();
    let mut row = vec![0u8; k];
    for p in 0..codes.pixels() {
        let bit = 1u8 << (p % 8);
        let plus = codes.plus_group(p / 8);
        if mask.is_some_and(|m| !m[p]) {
            row.fill(0);
        } else {
            match codes.minus_group(p / 8) {
                Some(minus) => {
                    for ((r, &pl), &mi) in row.iter_mut().zip(plus).zip(minus) {
                        *r = if pl & bit != 0 {
                            1
                        } else if mi & bit != 0 {
                            (-1i8) as u8
                        } else {
                            0
                        };
                    }
                }
                None => {
                    for (r, &pl) in row.iter_mut().zip(plus) {
                        *r = if pl & bit != 0 { 1 } else { (-1i8) as u8 };
                    }
                }
            }
        }
        w.write_all(&row)
            .map_err(|e| file_error(path, format!("cannot write: {e}")))?;
    }
    Ok(())
}
