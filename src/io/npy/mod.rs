//! NumPy `.npy` arrays: the scene, pulse, codes, measurements and depth files other tools read
//! and write (docs/guide.md, Conventions).
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

use std::fs::File;
use std::io::{BufReader, Read, Seek, SeekFrom};
use std::ops::Range;
use std::path::Path;

use ndarray::{ArrayD, Axis, Dimension, IxDyn, ShapeBuilder};

use crate::error::{Error, Result};
use crate::real::Real;

use super::file_error;

mod header;
mod read;
mod write;

use header::HeaderError;
pub use header::{escape_all, MAX_HEADER_BYTES, MAX_NESTING};

pub use read::{
    read_code_band, read_code_sets, read_codes, read_depth, read_measurement_rows,
    read_measurements, read_pulse, read_range, read_response, read_scene, read_scene_rows,
    ShapeExpectation,
};
pub use write::{
    stage_array, stage_code_sets, stage_codes, stage_masked_codes, stage_packed_code_sets,
    stage_packed_codes, write_array, write_code_sets, write_codes, write_depth, write_masked_codes,
    write_measurements, write_packed_code_sets, write_packed_codes, write_pulse, write_scene,
};

/// The element type of a `.npy` file, from its header's `descr`.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum NpyDtype {
    /// `float32` (`<f4` or `>f4`).
    Float32,
    /// `float64` (`<f8` or `>f8`).
    Float64,
    /// `int8` (`|i1`).
    Int8,
    /// `uint8` (`|u1`): codes packed eight samples to a byte, as `np.packbits` writes them.
    Uint8,
    /// `int32` (`<i4` or `>i4`).
    Int32,
    /// Anything else, described in NumPy's words where possible (e.g. `"int64"`, `"bool"`).
    Other(String),
}

impl NpyDtype {
    /// The dtype of a `descr` string and whether its data are little-endian (`=` and no
    /// prefix mean this machine's order; one-byte types have none).
    fn from_descr(descr: &str) -> (Self, bool) {
        let native = cfg!(target_endian = "little");
        let (order, body) = match descr.chars().next() {
            Some('<') => (true, &descr[1..]),
            Some('>') => (false, &descr[1..]),
            Some('=') | Some('|') => (native, &descr[1..]),
            _ => (native, descr),
        };
        let dtype = match body {
            "f4" => NpyDtype::Float32,
            "f8" => NpyDtype::Float64,
            "i1" | "b" => NpyDtype::Int8,
            "u1" | "B" => NpyDtype::Uint8,
            "i4" => NpyDtype::Int32,
            _ => NpyDtype::Other(describe_descr(descr)),
        };
        (dtype, order)
    }

    /// NumPy's name of the type: `"float32"`, `"float64"`, `"int8"`, `"int32"`, or the
    /// description of another type.
    pub fn name(&self) -> &str {
        match self {
            NpyDtype::Float32 => "float32",
            NpyDtype::Float64 => "float64",
            NpyDtype::Int8 => "int8",
            NpyDtype::Uint8 => "uint8",
            NpyDtype::Int32 => "int32",
            NpyDtype::Other(s) => s,
        }
    }

    fn item_size(&self) -> Option<usize> {
        match self {
            NpyDtype::Float32 | NpyDtype::Int32 => Some(4),
            NpyDtype::Float64 => Some(8),
            NpyDtype::Int8 | NpyDtype::Uint8 => Some(1),
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
    let descr = header::escape_quoted(descr);
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

/// An open `.npy` file with its parsed header, positioned at the start of the data.
struct Opened {
    header: NpyHeader,
    /// Little-endian data (`false` for big-endian files).
    little_endian: bool,
    /// Where the data start in the file.
    data_offset: u64,
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
    let mut reader = BufReader::with_capacity(1 << 16, file);
    let raw = header::read_header(&mut reader).map_err(|e| match e {
        HeaderError::Truncated if file_len < 10 => file_error(
            path,
            format!("not a .npy file: only {file_len} bytes, too short for a header"),
        ),
        HeaderError::Truncated => {
            file_error(path, "truncated .npy file: the file ends inside the header")
        }
        HeaderError::NotNpy => file_error(
            path,
            "not a .npy file: it does not start with the NumPy magic string \\x93NUMPY",
        ),
        HeaderError::Invalid(reason) => file_error(path, reason),
        HeaderError::Io(e) => file_error(path, format!("cannot read: {e}")),
    })?;
    let (dtype, little_endian) = match &raw.descr {
        Some(s) => NpyDtype::from_descr(s),
        None => (NpyDtype::Other(raw.structured.clone()), true),
    };
    let info = NpyHeader {
        dtype,
        shape: raw.shape,
        fortran_order: raw.fortran_order,
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
        let have = file_len.saturating_sub(raw.data_offset);
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
    Ok(Opened {
        header: info,
        little_endian,
        data_offset: raw.data_offset,
        reader,
    })
}

/// Reads the header of a `.npy` file (dtype, shape, order) without reading the data.
///
/// # Errors
/// [`Error::File`] naming `path` if it cannot be opened, is not a `.npy` file, its header is
/// malformed (see [`MAX_HEADER_BYTES`] and [`MAX_NESTING`] for the bounds), or its size does not
/// match the header's shape and dtype (a truncated file or trailing bytes).
pub fn read_header(path: impl AsRef<Path>) -> Result<NpyHeader> {
    open_npy(path.as_ref()).map(|o| o.header)
}

/// An element type of the data section, decoded from its bytes.
trait Element: Copy + Default {
    const SIZE: usize;
    fn decode(bytes: &[u8], little_endian: bool) -> Self;
}

macro_rules! element {
    ($t:ty) => {
        impl Element for $t {
            const SIZE: usize = std::mem::size_of::<$t>();
            fn decode(bytes: &[u8], little_endian: bool) -> Self {
                let mut b = [0u8; std::mem::size_of::<$t>()];
                b.copy_from_slice(bytes);
                if little_endian {
                    <$t>::from_le_bytes(b)
                } else {
                    <$t>::from_be_bytes(b)
                }
            }
        }
    };
}
element!(f32);
element!(f64);
element!(i8);
element!(u8);
element!(i32);

/// Reads the data of an opened file as elements `E` (the dtype and the file's length have been
/// checked), in C order. The data are decoded in blocks, so no second copy of the file is held.
fn read_data<E: Element>(path: &Path, opened: Opened) -> Result<ArrayD<E>> {
    let rows = 0..opened.header.shape.first().copied().unwrap_or(0);
    read_data_rows(path, opened, 0, rows)
}

/// Reads the slice `rows` of axis `axis` of an opened file's data as elements `E`, in C order:
/// for a C-order file, only those bytes (one contiguous run per index of the axes before
/// `axis`); a Fortran-order file is read whole and sliced.
fn read_data_rows<E: Element>(
    path: &Path,
    mut opened: Opened,
    axis: usize,
    rows: Range<usize>,
) -> Result<ArrayD<E>> {
    let full = opened.header.shape.clone();
    let fortran = opened.header.fortran_order;
    let mut shape = full.clone();
    if !fortran && axis < shape.len() {
        shape[axis] = rows.len();
    }
    let len: usize = shape.iter().product();
    // The data, and the converted copy the readers make of it, must fit in memory.
    crate::limits::MemoryPlan::new()
        .add("data and its conversion", len as u128, 2 * E::SIZE.max(4))
        .check(
            &format!(
                "{}: reading an array of shape {}",
                escape_all(&path.display().to_string()),
                shape_text(&shape)
            ),
            "use a smaller file or free memory",
        )?;
    let mut values: Vec<E> = Vec::new();
    values
        .try_reserve_exact(len)
        .map_err(|_| file_error(path, format!("not enough memory for {} values", len)))?;
    if fortran || axis >= full.len() || rows == (0..full[axis]) {
        read_values(path, &mut opened, len, &mut values)?;
    } else {
        let inner: usize = full[axis + 1..].iter().product();
        let outer: usize = full[..axis].iter().product();
        for o in 0..outer {
            let first = (o * full[axis] + rows.start) * inner * E::SIZE;
            opened
                .reader
                .seek(SeekFrom::Start(opened.data_offset + first as u64))
                .map_err(|e| file_error(path, format!("cannot read: {e}")))?;
            read_values(path, &mut opened, rows.len() * inner, &mut values)?;
        }
    }
    let dim = IxDyn(&shape);
    let mut a = if fortran {
        ArrayD::from_shape_vec(dim.f(), values)
    } else {
        ArrayD::from_shape_vec(dim, values)
    }
    .map_err(|e| file_error(path, format!("cannot shape the data: {e}")))?;
    if fortran && axis < full.len() {
        a.slice_axis_inplace(Axis(axis), rows.into());
    }
    Ok(if a.is_standard_layout() {
        a
    } else {
        a.as_standard_layout().into_owned()
    })
}

/// Decodes the next `len` elements of an opened file into `values`, in blocks.
fn read_values<E: Element>(
    path: &Path,
    opened: &mut Opened,
    len: usize,
    values: &mut Vec<E>,
) -> Result<()> {
    let mut block = vec![0u8; (1 << 16) * E::SIZE];
    let mut left = len;
    while left > 0 {
        let n = left.min(1 << 16);
        let bytes = &mut block[..n * E::SIZE];
        opened
            .reader
            .read_exact(bytes)
            .map_err(|e| match e.kind() {
                std::io::ErrorKind::UnexpectedEof => {
                    file_error(path, "truncated .npy file: the data ends early")
                }
                _ => file_error(path, format!("cannot read: {e}")),
            })?;
        values.extend(
            bytes
                .chunks_exact(E::SIZE)
                .map(|b| E::decode(b, opened.little_endian)),
        );
        left -= n;
    }
    Ok(())
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
/// overflow `T`) by its index in the file, of which `a` starts at index `first` of axis 0.
fn to_real<T: Real, S: Copy + Into<f64>>(
    path: &Path,
    role: &str,
    a: ArrayD<S>,
    first: usize,
) -> Result<ArrayD<T>> {
    let in_file = |i: &[usize]| {
        let mut i = i.to_vec();
        if let Some(row) = i.first_mut() {
            *row += first;
        }
        index_text(&i)
    };
    if let Some((i, v)) = first_bad(&a, |v| v.into().is_finite()) {
        let v: f64 = v.into();
        let what = if v.is_nan() {
            "NaN".to_string()
        } else {
            format!("infinite value {v}")
        };
        return Err(file_error(
            path,
            format!("{role} holds {what} at index {}", in_file(&i)),
        ));
    }
    let out = a.mapv(|v| T::of_f64(v.into()));
    if let Some((i, _)) = first_bad(&out, |v| v.is_finite()) {
        let v: f64 = a[i.as_slice()].into();
        return Err(file_error(
            path,
            format!(
                "{role} value {v:e} at index {} overflows {}",
                in_file(&i),
                T::NAME
            ),
        ));
    }
    let underflow = a.iter().zip(out.iter()).position(|(&s, &t)| {
        let s: f64 = s.into();
        s != 0.0 && t == T::zero()
    });
    if let Some(flat) = underflow {
        let i = unravel(flat, a.shape());
        let v: f64 = a[i.as_slice()].into();
        return Err(file_error(
            path,
            format!(
                "{role} value {v:e} at index {} underflows {} (it would read as 0); compute \
                 in f64 (`precision`)",
                in_file(&i),
                T::NAME
            ),
        ));
    }
    Ok(out)
}

/// Reads a floating-point array of `ndim` dimensions as `T`.
fn read_real<T: Real>(path: &Path, role: &str, ndim: usize, axes: &str) -> Result<ArrayD<T>> {
    read_real_rows(path, (role, ndim, axes), None).map(|(_, a)| a)
}

/// [`read_real`] of the slice `rows` of axis 0 only (all of it for `None`), reading only those
/// bytes of a C-order file; also the file's shape.
fn read_real_rows<T: Real>(
    path: &Path,
    (role, ndim, axes): (&str, usize, &str),
    rows: Option<Range<usize>>,
) -> Result<(Vec<usize>, ArrayD<T>)> {
    let opened = open_npy(path)?;
    let h = opened.header.clone();
    let accept = |found: &NpyDtype| wrong_dtype(path, role, found, "float32 or float64");
    if !matches!(h.dtype, NpyDtype::Float32 | NpyDtype::Float64) {
        return Err(accept(&h.dtype));
    }
    check_ndim(path, role, &h, ndim, axes)?;
    let m = h.shape.first().copied().unwrap_or(0);
    let rows = rows.unwrap_or(0..m);
    if rows.is_empty() || rows.end > m {
        return Err(file_error(
            path,
            format!(
                "{role} of shape {} has {m} rows: rows {}..{} are not a band of them",
                shape_text(&h.shape),
                rows.start,
                rows.end
            ),
        ));
    }
    let first = rows.start;
    let a = match h.dtype {
        NpyDtype::Float32 => to_real(
            path,
            role,
            read_data_rows::<f32>(path, opened, 0, rows)?,
            first,
        ),
        NpyDtype::Float64 => to_real(
            path,
            role,
            read_data_rows::<f64>(path, opened, 0, rows)?,
            first,
        ),
        ref other => Err(accept(other)),
    }?;
    Ok((h.shape, a))
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
