//! Files: the `.npy` arrays other tools exchange with the crate (their shapes and dtypes are in
//! docs/guide.md, Conventions, and docs/architectures.md) and atomic writes.
//!
//! Every problem with a file is reported as [`Error::File`], whose message
//! starts with the file's path.
//!
//! Writes are atomic: the data goes to a temporary file in the destination's directory
//! (`.NAME.tmp-<pid>-<n>`), which is flushed, synced to disk and then renamed over the destination.
//! On any error the temporary file is removed, so a destination is either left as it was or
//! replaced by a complete file, never by a partial one. A destination that exists and is not a
//! regular file (a device such as `/dev/null`, a FIFO) is written in place, never renamed over;
//! a socket is refused. A process that must quit at once (Ctrl-C) removes its temporary files
//! with [`abandon_staged_files`]; those of a process that was killed (`kill -9`) are recognised
//! by the process id in their name and removed by the next write into their folder
//! ([`remove_stale_temporaries`]).
//!
//! ```no_run
//! use rdlidar::io::{read_pulse, write_measurements};
//!
//! # fn main() -> rdlidar::Result<()> {
//! let pulse = read_pulse::<f64>("pulse.npy")?;      // float32 or float64 on disk
//! write_measurements("copy.npy", pulse.as_slice())?; // written atomically, as float64
//! # Ok(())
//! # }
//! ```

pub mod meta;
pub mod npy;
mod ply;
#[cfg(feature = "images")]
mod png;

use std::ffi::OsStr;
use std::fs::{File, OpenOptions};
use std::io::{BufWriter, Write};
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicUsize, Ordering};
use std::sync::{Mutex, MutexGuard};

use crate::error::{Error, Result};

pub use npy::{
    read_code_band, read_code_sets, read_codes, read_depth, read_header, read_measurement_rows,
    read_measurements, read_pulse, read_range, read_response, read_scene, read_scene_rows,
    shape_text, stage_array, stage_code_sets, stage_codes, stage_masked_codes,
    stage_packed_code_sets, stage_packed_codes, write_array, write_code_sets, write_codes,
    write_depth, write_masked_codes, write_measurements, write_packed_code_sets,
    write_packed_codes, write_pulse, write_scene, NpyDtype, NpyHeader, ShapeExpectation,
};
pub use ply::{ply_bytes, stage_points};
#[cfg(feature = "images")]
pub use png::{png_dimensions, returns_from_pngs, scene_from_pngs};

/// An [`Error::File`] for `path`, on one line: control and non-printable characters of the path
/// and of the reason (which may quote the file) are escaped.
pub(crate) fn file_error(path: &Path, reason: impl Into<String>) -> Error {
    Error::File {
        path: npy::escape_all(&path.display().to_string()),
        reason: npy::escape_all(&reason.into()),
    }
}

/// The folder a path's file lives in (`.` for a bare file name).
pub fn parent_dir(path: &Path) -> PathBuf {
    match path.parent() {
        Some(d) if !d.as_os_str().is_empty() => d.to_path_buf(),
        _ => PathBuf::from("."),
    }
}

/// Whether `a` and `b` name the same existing file: after symbolic links and, on Unix, through
/// hard links (the same device and inode). A path that does not exist names no file.
pub fn same_file(a: &Path, b: &Path) -> bool {
    let (Ok(ma), Ok(mb)) = (std::fs::metadata(a), std::fs::metadata(b)) else {
        return false;
    };
    #[cfg(unix)]
    {
        use std::os::unix::fs::MetadataExt;
        ma.dev() == mb.dev() && ma.ino() == mb.ino()
    }
    #[cfg(not(unix))]
    {
        let _ = (ma, mb);
        match (a.canonicalize(), b.canonicalize()) {
            (Ok(ca), Ok(cb)) => ca == cb,
            _ => false,
        }
    }
}

/// Whether the output paths `a` and `b` name one destination: the same existing file (after
/// symbolic and hard links), or, for paths that do not exist yet, the same name in the same
/// folder however spelt (`x.npy`, `./x.npy`, an absolute path, a path through a symbolic
/// link to the folder).
pub fn same_destination(a: &Path, b: &Path) -> bool {
    if same_file(a, b) {
        return true;
    }
    fn resolved(p: &Path) -> Option<PathBuf> {
        if let Ok(c) = p.canonicalize() {
            return Some(c);
        }
        let dir = parent_dir(p).canonicalize().ok()?;
        Some(dir.join(p.file_name()?))
    }
    match (resolved(a), resolved(b)) {
        (Some(x), Some(y)) => x == y,
        _ => a == b,
    }
}

/// Checks, before any work, that outputs can be written into the folder `dir`: an existing
/// folder must be empty unless `force` (`replaced` names what `--force` would replace), a new one
/// needs an existing parent. The temporary files of writers that no longer run (see
/// [`remove_stale_temporaries`]) do not count. Nothing is created.
///
/// # Errors
/// [`Error::File`] naming `dir`: it is not a folder, it is not empty (without `force`), it cannot
/// be read, or its parent does not exist.
pub fn check_output_dir(dir: &Path, force: bool, replaced: &str) -> Result<()> {
    if dir.exists() {
        if !dir.is_dir() {
            return Err(file_error(dir, "exists and is not a folder (`out`)"));
        }
        if holds_files(dir)? && !force {
            return Err(file_error(
                dir,
                format!(
                    "the output folder exists and is not empty: `force` replaces \
                     {replaced}, or another `out` writes elsewhere"
                ),
            ));
        }
        return Ok(());
    }
    let parent = parent_dir(dir);
    if !parent.is_dir() {
        return Err(file_error(
            dir,
            format!(
                "the parent folder {} does not exist (`out`)",
                parent.display()
            ),
        ));
    }
    Ok(())
}

/// What an existing path that is not a regular file is, in words: `"a FIFO"`, `"a socket"`, `"a
/// character device"`, `"a block device"`, `"a folder"`. `None` for a regular file (after
/// symbolic links) and for a path that does not exist.
pub fn special_file_kind(path: &Path) -> Option<&'static str> {
    let meta = std::fs::metadata(path).ok()?;
    let kind = meta.file_type();
    if kind.is_file() {
        return None;
    }
    if kind.is_dir() {
        return Some("a folder");
    }
    #[cfg(unix)]
    {
        use std::os::unix::fs::FileTypeExt;
        if kind.is_fifo() {
            return Some("a FIFO");
        }
        if kind.is_socket() {
            return Some("a socket");
        }
        if kind.is_char_device() {
            return Some("a character device");
        }
        if kind.is_block_device() {
            return Some("a block device");
        }
    }
    Some("not a regular file")
}

/// Whether the folder `dir` holds anything but the temporary files of writers that no longer
/// run (see [`remove_stale_temporaries`]): what makes an output folder not empty.
///
/// # Errors
/// [`Error::File`] naming `dir` if it cannot be read.
pub fn holds_files(dir: &Path) -> Result<bool> {
    let mut entries = std::fs::read_dir(dir)
        .map_err(|e| file_error(dir, format!("cannot read the folder: {e}")))?;
    Ok(entries.any(|entry| match entry {
        Ok(entry) => !stale_temporary(dir, &entry.file_name()),
        Err(_) => true,
    }))
}

/// Opens an existing destination that is not a regular file for writing in place. A FIFO
/// without a reader is refused at once instead of waiting for one: it is opened without
/// blocking (ENXIO when nobody reads), then switched back to blocking writes. A socket is
/// refused: it cannot be opened as a file.
fn open_in_place(dest: &Path) -> Result<File> {
    let kind = special_file_kind(dest).unwrap_or("not a regular file");
    if kind == "a socket" {
        return Err(file_error(
            dest,
            "is a socket, not a file: an output cannot be written to a socket",
        ));
    }
    let fail = |e: std::io::Error| {
        file_error(
            dest,
            format!("is {kind}, which cannot be opened for writing: {e}"),
        )
    };
    #[cfg(unix)]
    {
        use std::os::unix::fs::OpenOptionsExt;
        use std::os::unix::io::AsRawFd;
        let file = OpenOptions::new()
            .write(true)
            .custom_flags(libc::O_NONBLOCK)
            .open(dest)
            .map_err(|e| {
                if e.raw_os_error() == Some(libc::ENXIO) && kind == "a FIFO" {
                    file_error(dest, "is a FIFO that nobody reads: start its reader first")
                } else {
                    fail(e)
                }
            })?;
        // SAFETY: `file` owns a valid descriptor for the duration of both calls.
        let flags = unsafe { libc::fcntl(file.as_raw_fd(), libc::F_GETFL) };
        if flags < 0
            || unsafe { libc::fcntl(file.as_raw_fd(), libc::F_SETFL, flags & !libc::O_NONBLOCK) }
                < 0
        {
            return Err(fail(std::io::Error::last_os_error()));
        }
        Ok(file)
    }
    #[cfg(not(unix))]
    {
        OpenOptions::new().write(true).open(dest).map_err(fail)
    }
}

/// Distinguishes the temporary files of one process.
static TEMP_COUNTER: AtomicUsize = AtomicUsize::new(0);

/// The temporary files of this process's staged files, from their creation until they are
/// renamed into place or removed. The lock is held while one is created, renamed or removed,
/// so that [`abandon_staged_files`] sees every one and none appears after it.
static LIVE: Mutex<Vec<PathBuf>> = Mutex::new(Vec::new());

fn live() -> MutexGuard<'static, Vec<PathBuf>> {
    LIVE.lock().unwrap_or_else(|poisoned| poisoned.into_inner())
}

/// What [`abandon_staged_files`] returns: while it is held, no staged file can be created,
/// renamed into place or dropped (those calls wait for it). The process is to exit holding it.
#[derive(Debug)]
#[must_use = "the process must exit while it holds this, or staged files wait forever"]
pub struct AbandonedStaging {
    _live: MutexGuard<'static, Vec<PathBuf>>,
}

/// Removes the temporary file of every staged file of this process not yet renamed into place,
/// waiting first for a set being renamed by [`commit_all`] to be complete: for a process that
/// must quit at once (Ctrl-C, SIGTERM), which exits while it holds the value returned. Each
/// destination is then either as it was or a complete file, and no temporary file is left.
pub fn abandon_staged_files() -> AbandonedStaging {
    let live = live();
    for tmp in live.iter() {
        let _ = std::fs::remove_file(tmp);
    }
    AbandonedStaging { _live: live }
}

/// Whether the process `pid` runs (on this machine). Without a way to know, every process runs.
pub(crate) fn process_runs(pid: u32) -> bool {
    #[cfg(unix)]
    {
        let Ok(pid) = libc::pid_t::try_from(pid) else {
            return false;
        };
        if pid <= 0 {
            return false;
        }
        // SAFETY: signal 0 only checks that the process exists and may be signalled.
        let sent = unsafe { libc::kill(pid, 0) };
        sent == 0 || std::io::Error::last_os_error().raw_os_error() == Some(libc::EPERM)
    }
    #[cfg(not(unix))]
    {
        let _ = pid;
        true
    }
}

/// Whether `name`, in the folder `dir`, is the temporary file of a staged file (`.NAME.tmp-PID-N`)
/// whose writer no longer runs: a process killed while it wrote (`kill -9`, a power cut, or a
/// version of this crate without an interrupt handler). No one can complete or rename it.
fn stale_temporary(dir: &Path, name: &OsStr) -> bool {
    let Some(name) = name.to_str() else {
        return false;
    };
    let Some((head, tail)) = name.rsplit_once(".tmp-") else {
        return false;
    };
    let Some((pid, n)) = tail.split_once('-') else {
        return false;
    };
    let digits = |s: &str| !s.is_empty() && s.bytes().all(|b| b.is_ascii_digit());
    if head.len() < 2 || !head.starts_with('.') || !digits(pid) || !digits(n) {
        return false;
    }
    let Ok(pid) = pid.parse::<u32>() else {
        return true;
    };
    if pid == std::process::id() {
        let path = dir.join(name);
        return !live().contains(&path);
    }
    !process_runs(pid)
}

/// Removes the temporary files of staged files in `dir` whose writers no longer run (see
/// [`check_output_dir`]), so that a write into a folder a killed process was writing leaves
/// nothing of it. Best effort: a file that cannot be removed stays. Returns how many were
/// removed.
pub fn remove_stale_temporaries(dir: &Path) -> usize {
    let Ok(entries) = std::fs::read_dir(dir) else {
        return 0;
    };
    entries
        .flatten()
        .filter(|entry| stale_temporary(dir, &entry.file_name()))
        .filter(|entry| std::fs::remove_file(entry.path()).is_ok())
        .count()
}

/// A file written under a temporary name next to its destination and renamed into place by
/// [`StagedFile::commit`].
///
/// Dropping a staged file that was not committed removes the temporary file, so an error at any
/// point (including a panic that unwinds) leaves nothing behind.
///
/// ```no_run
/// use std::io::Write;
/// use rdlidar::io::StagedFile;
///
/// # fn main() -> rdlidar::Result<()> {
/// let mut f = StagedFile::create("out/notes.txt")?;
/// writeln!(f.writer(), "complete or absent").map_err(|e| f.io_error("cannot write", e))?;
/// f.commit()?; // flush, fsync, rename
/// # Ok(())
/// # }
/// ```
///
/// A destination that exists and is not a regular file (a character device such as
/// `/dev/null`, a FIFO) is never renamed over: it is opened and written in place, and
/// committing only flushes it. A socket is refused, and so is a destination that stopped being
/// a regular file while the temporary file was written.
#[derive(Debug)]
pub struct StagedFile {
    dest: PathBuf,
    /// The temporary file; `None` when the destination is written in place.
    tmp: Option<PathBuf>,
    /// `None` once the file has been synced and closed.
    writer: Option<BufWriter<File>>,
    committed: bool,
}

impl StagedFile {
    /// Creates the temporary file for `dest` in `dest`'s directory.
    ///
    /// # Errors
    /// [`Error::File`] naming `dest` if it has no file name, is a socket, or the temporary file
    /// cannot be created (e.g. the directory does not exist or is not writable).
    pub fn create(dest: impl AsRef<Path>) -> Result<Self> {
        let dest = dest.as_ref().to_path_buf();
        let name = dest
            .file_name()
            .ok_or_else(|| file_error(&dest, "not a file name"))?
            .to_string_lossy()
            .into_owned();
        if dest.is_dir() {
            return Err(file_error(&dest, "is a directory, expected a file name"));
        }
        if let Ok(meta) = std::fs::metadata(&dest) {
            if !meta.is_file() {
                let file = open_in_place(&dest)?;
                return Ok(StagedFile {
                    dest,
                    tmp: None,
                    writer: Some(BufWriter::with_capacity(1 << 20, file)),
                    committed: false,
                });
            }
        }
        let dir = match dest.parent() {
            Some(p) if !p.as_os_str().is_empty() => p.to_path_buf(),
            _ => PathBuf::from("."),
        };
        let pid = std::process::id();
        let mut attempts = 0;
        loop {
            let n = TEMP_COUNTER.fetch_add(1, Ordering::Relaxed);
            let tmp = dir.join(format!(".{name}.tmp-{pid}-{n}"));
            let mut live = live();
            match OpenOptions::new().write(true).create_new(true).open(&tmp) {
                Ok(file) => {
                    live.push(tmp.clone());
                    return Ok(StagedFile {
                        dest,
                        tmp: Some(tmp),
                        writer: Some(BufWriter::with_capacity(1 << 20, file)),
                        committed: false,
                    });
                }
                Err(e) if e.kind() == std::io::ErrorKind::AlreadyExists && attempts < 64 => {
                    attempts += 1;
                }
                Err(e) => {
                    let what = if dir.is_dir() {
                        format!("cannot create a file in {}", dir.display())
                    } else {
                        format!("directory {} does not exist", dir.display())
                    };
                    return Err(file_error(&dest, format!("{what}: {e}")));
                }
            }
        }
    }

    /// The destination path.
    pub fn path(&self) -> &Path {
        &self.dest
    }

    /// The buffered writer of the temporary file.
    ///
    /// # Panics
    /// After [`StagedFile::sync`], which closes it.
    pub fn writer(&mut self) -> &mut BufWriter<File> {
        self.writer
            .as_mut()
            .expect("the staged file is still open for writing")
    }

    /// An [`Error::File`] naming the destination, for an I/O error met while writing.
    pub fn io_error(&self, what: &str, e: std::io::Error) -> Error {
        file_error(&self.dest, format!("{what}: {e}"))
    }

    /// Flushes the data and syncs the temporary file to disk, then closes it. Idempotent.
    ///
    /// # Errors
    /// [`Error::File`] naming the destination if flushing or syncing fails (e.g. a full disk).
    pub fn sync(&mut self) -> Result<()> {
        if let Some(w) = self.writer.take() {
            let file = w
                .into_inner()
                .map_err(|e| file_error(&self.dest, format!("cannot write: {}", e.error())))?;
            // A device or a FIFO written in place has nothing to sync to disk.
            if self.tmp.is_some() {
                file.sync_all()
                    .map_err(|e| file_error(&self.dest, format!("cannot sync to disk: {e}")))?;
            }
        }
        Ok(())
    }

    /// Whether the destination is written in place (it exists and is not a regular file).
    pub fn in_place(&self) -> bool {
        self.tmp.is_none()
    }

    /// Syncs the data (if not done yet) and renames the temporary file over the destination.
    ///
    /// # Errors
    /// [`Error::File`] naming the destination if syncing or renaming fails, or if the
    /// destination is no longer a regular file (a FIFO or a socket made there meanwhile); the
    /// temporary file is removed and the destination left as it was.
    pub fn commit(mut self) -> Result<()> {
        self.sync()?;
        let mut live = live();
        let renamed = self.rename_into_place(&mut live);
        drop(live);
        // On an error, `self` is dropped after the lock and removes its temporary file.
        renamed
    }

    /// Renames the synced temporary file over the destination, `live` (the list of temporary
    /// files, locked) told. A destination written in place is only marked committed.
    fn rename_into_place(&mut self, live: &mut Vec<PathBuf>) -> Result<()> {
        let Some(tmp) = self.tmp.clone() else {
            self.committed = true;
            return Ok(());
        };
        if let Some(kind) = special_file_kind(&self.dest) {
            return Err(file_error(
                &self.dest,
                format!("is now {kind}, no longer a regular file: not replaced"),
            ));
        }
        std::fs::rename(&tmp, &self.dest)
            .map_err(|e| file_error(&self.dest, format!("cannot rename into place: {e}")))?;
        self.committed = true;
        live.retain(|p| p != &tmp);
        // Make the rename itself durable where directories can be synced (best effort).
        if let Some(dir) = self.dest.parent() {
            let dir = if dir.as_os_str().is_empty() {
                Path::new(".")
            } else {
                dir
            };
            if let Ok(d) = File::open(dir) {
                let _ = d.sync_all();
            }
        }
        Ok(())
    }
}

impl Drop for StagedFile {
    fn drop(&mut self) {
        if !self.committed {
            self.writer.take();
            if let Some(tmp) = &self.tmp {
                let mut live = live();
                let _ = std::fs::remove_file(tmp);
                live.retain(|p| p != tmp);
            }
        }
    }
}

/// Writes `dest` atomically: `write` fills a [`StagedFile`]'s writer, then the file is synced and
/// renamed into place.
///
/// # Errors
/// [`Error::File`] naming `dest` when the file cannot be created, written, synced or renamed;
/// any error returned by `write`. In every error case `dest` is left as it was.
pub fn write_atomic<F>(dest: impl AsRef<Path>, write: F) -> Result<()>
where
    F: FnOnce(&mut BufWriter<File>) -> Result<()>,
{
    let mut staged = StagedFile::create(dest)?;
    write(staged.writer())?;
    staged.commit()
}

/// Writes `contents` under a temporary name next to `dest` and syncs it, without renaming it into
/// place (see [`StagedFile`]).
///
/// # Errors
/// [`Error::File`] naming `dest` when the file cannot be created, written or synced.
pub fn stage_bytes(dest: impl AsRef<Path>, contents: &[u8]) -> Result<StagedFile> {
    let mut staged = StagedFile::create(dest)?;
    staged
        .writer()
        .write_all(contents)
        .map_err(|e| staged.io_error("cannot write", e))?;
    staged.sync()?;
    Ok(staged)
}

/// Syncs staged files, then renames them into place, in order. The renames are made together:
/// a process quitting at once meanwhile ([`abandon_staged_files`]) waits for the whole set.
///
/// If a rename fails, the files not yet renamed are removed and the error returned; the files
/// renamed before it stay in place (the caller decides whether to remove them). The returned
/// paths on success are the destinations, in order.
///
/// # Errors
/// [`Error::File`] naming the file whose sync or rename failed.
pub fn commit_all(mut files: Vec<StagedFile>) -> Result<Vec<PathBuf>> {
    for f in &mut files {
        f.sync()?;
    }
    let mut done = Vec::with_capacity(files.len());
    let renamed = {
        let mut live = live();
        files.iter_mut().try_for_each(|f| {
            f.rename_into_place(&mut live)?;
            done.push(f.dest.clone());
            Ok::<(), Error>(())
        })
    };
    // Dropped without the lock: the files not renamed remove their temporary files.
    drop(files);
    renamed.map(|()| done)
}

/// Writes `contents` to `dest` atomically (see [`write_atomic`]).
///
/// # Errors
/// As [`write_atomic`].
pub fn write_bytes_atomic(dest: impl AsRef<Path>, contents: &[u8]) -> Result<()> {
    let dest = dest.as_ref();
    write_atomic(dest, |w| {
        w.write_all(contents)
            .map_err(|e| file_error(dest, format!("cannot write: {e}")))
    })
}
