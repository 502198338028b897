//! Writing the interchange arrays, atomically.

use std::borrow::Borrow;
use std::io::Write;
use std::path::Path;

use ndarray::{Array2, ArrayBase, Data, Dimension};
use ndarray_npy::npy::header::{Header, Layout};
use ndarray_npy::{WritableElement, WriteNpyExt};

use crate::error::{Error, Result};
use crate::lidar::{packed_len, Codes, Scene};
use crate::real::Real;

use super::super::{file_error, StagedFile};

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
/// renaming it into place: [`StagedFile::commit`] (or [`commit_all`](crate::io::commit_all) for a set of files)
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
    let first = check_sets("write_code_sets", grid, sets)?;
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

/// Checks that there is at least one code set, that each has the pixels of `grid` and that they
/// have the same number of samples; returns the first.
fn check_sets<'a, C: Borrow<Codes>>(
    context: &str,
    grid: (usize, usize),
    sets: &'a [C],
) -> Result<&'a Codes> {
    let first = sets
        .first()
        .ok_or_else(|| Error::param("sets", "need at least one code set"))?
        .borrow();
    for (i, set) in sets.iter().enumerate() {
        let set = set.borrow();
        check_grid(context, grid, set)?;
        if set.len() != first.len() {
            return Err(Error::shape(
                format!("{context}: samples of set {i} vs set 0"),
                first.len(),
                set.len(),
            ));
        }
    }
    Ok(first)
}

/// Creates the temporary file of an int8 array of shape `shape` and writes its header.
fn start_codes_file(path: &Path, shape: Vec<usize>) -> Result<StagedFile> {
    start_file::<i8>(path, shape)
}

/// Writes ±1 codes as numpy's `packbits` writes them: a uint8 array of shape (M, N, ⌈K/8⌉),
/// atomically. `np.unpackbits(b, axis=-1, count=K)` gives back S > 0; see
/// [`Codes::from_packbits`] for the bit order.
///
/// # Errors
/// As [`stage_packed_codes`], or [`Error::File`] if the file cannot be renamed into place.
pub fn write_packed_codes(
    path: impl AsRef<Path>,
    grid: (usize, usize),
    codes: &Codes,
) -> Result<()> {
    stage_packed_codes(path, grid, codes)?.commit()
}

/// Writes ±1 codes as a uint8 array of shape (M, N, ⌈K/8⌉) (see [`write_packed_codes`]) under a
/// temporary name and syncs it; see [`stage_array`].
///
/// # Errors
/// [`Error::ShapeMismatch`] if `grid` does not have the codes' number of pixels;
/// [`Error::InvalidParameter`] for codes with 0 entries, which one bit cannot hold;
/// [`Error::File`] naming `path` if the file cannot be created, written or synced.
pub fn stage_packed_codes(
    path: impl AsRef<Path>,
    grid: (usize, usize),
    codes: &Codes,
) -> Result<StagedFile> {
    stage_packed_code_sets(path, grid, std::slice::from_ref(codes), false)
}

/// Writes G sets of ±1 codes as a uint8 array of shape (G, M, N, ⌈K/8⌉), atomically: slice g
/// holds `sets[g]` as [`write_packed_codes`] writes one set.
///
/// # Errors
/// As [`stage_code_sets`], and [`Error::InvalidParameter`] for codes with 0 entries.
pub fn write_packed_code_sets<C: Borrow<Codes>>(
    path: impl AsRef<Path>,
    grid: (usize, usize),
    sets: &[C],
) -> Result<()> {
    stage_packed_code_sets(path, grid, sets, true)?.commit()
}

/// Writes packed code sets under a temporary name, with a leading axis of G when `stacked`.
///
/// # Errors
/// As [`write_packed_code_sets`].
pub fn stage_packed_code_sets<C: Borrow<Codes>>(
    path: impl AsRef<Path>,
    grid: (usize, usize),
    sets: &[C],
    stacked: bool,
) -> Result<StagedFile> {
    let path = path.as_ref();
    let first = check_sets("write_packed_code_sets", grid, sets)?;
    let (m, n) = grid;
    let mut shape = vec![m, n, packed_len(first.len())];
    if stacked {
        shape.insert(0, sets.len());
    }
    let mut staged = start_file::<u8>(path, shape)?;
    for set in sets {
        let bytes = set.borrow().to_packbits()?;
        staged
            .writer()
            .write_all(&bytes)
            .map_err(|e| file_error(path, format!("cannot write: {e}")))?;
    }
    staged.sync()?;
    Ok(staged)
}

/// Creates the temporary file of an array of `E` of shape `shape` and writes its header.
fn start_file<E: WritableElement>(path: &Path, shape: Vec<usize>) -> Result<StagedFile> {
    let header = Header {
        type_descriptor: E::type_descriptor(),
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
