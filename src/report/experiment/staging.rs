//! An experiment's output folder, written as a whole or not at all.
//!
//! Every file of an experiment (the partial files while it runs, then the tables and figures) is
//! written into a staging folder beside the output folder, `.NAME.staging-PID` for `--out NAME`.
//! [`StagedDir::commit`] moves the set into place at the end: by one rename when the output
//! folder is new, file by file (renames within one file system, which need no space) when it
//! exists. Dropping a staged folder that was not committed removes it, so an error — a full
//! disk, a figure that cannot be drawn — leaves nothing new. A process that must quit at once
//! (a second Ctrl-C) calls [`abandon_staged_and_exit`], which removes the staging folder, or
//! waits for a commit under way to finish, before it exits.

use std::path::{Path, PathBuf};
use std::sync::{Mutex, MutexGuard};

use crate::error::{Error, Result};
use crate::io::{check_output_dir, parent_dir};

/// The staging folder of the experiment under way, if any. Held while a commit moves files.
static ACTIVE: Mutex<Option<PathBuf>> = Mutex::new(None);

fn active() -> MutexGuard<'static, Option<PathBuf>> {
    ACTIVE
        .lock()
        .unwrap_or_else(|poisoned| poisoned.into_inner())
}

fn folder_error(path: &Path, reason: String) -> Error {
    Error::File {
        path: crate::io::npy::escape_all(&path.display().to_string()),
        reason,
    }
}

/// A staging folder for the files of one experiment; see the module documentation.
#[derive(Debug)]
pub struct StagedDir {
    out: PathBuf,
    staging: PathBuf,
    committed: bool,
}

impl StagedDir {
    /// Checks `out` (a new folder whose parent exists, an empty folder, or any folder with
    /// `force`) and creates the staging folder beside it.
    ///
    /// # Errors
    /// [`Error::File`] naming `out` or the staging folder: see [`check_output_dir`]; the staging
    /// folder cannot be created.
    pub fn create(out: &Path, force: bool) -> Result<Self> {
        check_output_dir(out, force, "the results in it")?;
        let name = match out.file_name() {
            Some(n) => n.to_string_lossy().into_owned(),
            None => "out".to_string(),
        };
        let base = match out.file_name() {
            Some(_) => parent_dir(out),
            None => out.to_path_buf(),
        };
        remove_stale_staging(&base, &name);
        if out.is_dir() {
            crate::io::remove_stale_temporaries(out);
        }
        let staging = base.join(format!(".{name}.staging-{}", std::process::id()));
        if staging.exists() {
            std::fs::remove_dir_all(&staging).map_err(|e| {
                folder_error(
                    &staging,
                    format!("cannot remove an old staging folder: {e}"),
                )
            })?;
        }
        std::fs::create_dir(&staging).map_err(|e| {
            folder_error(&staging, format!("cannot create the staging folder: {e}"))
        })?;
        *active() = Some(staging.clone());
        Ok(StagedDir {
            out: out.to_path_buf(),
            staging,
            committed: false,
        })
    }

    /// Where the files are written until the commit.
    pub fn dir(&self) -> &Path {
        &self.staging
    }

    /// The output folder.
    pub fn out(&self) -> &Path {
        &self.out
    }

    /// An error about a staged file, told of the file's place in the output folder: nothing new
    /// will be left there.
    pub fn explain(&self, e: Error) -> Error {
        match e {
            Error::File { path, reason } => {
                let staging = self.staging.display().to_string();
                match path.strip_prefix(&staging) {
                    Some(rest) => Error::File {
                        path: format!(
                            "{}{rest}",
                            crate::io::npy::escape_all(&self.out.display().to_string())
                        ),
                        reason: format!("{reason}; nothing was written to the output folder"),
                    },
                    None => Error::File { path, reason },
                }
            }
            other => other,
        }
    }

    /// Moves every staged file into the output folder (creating it if needed) and removes the
    /// staging folder. A second Ctrl-C arriving meanwhile waits until the set is complete.
    ///
    /// # Errors
    /// [`Error::File`] naming the file or folder that cannot be moved; the staging folder is then
    /// removed with what was not moved.
    pub fn commit(mut self) -> Result<()> {
        let mut guard = active();
        let moved = self.move_into_place();
        *guard = None;
        self.committed = moved.is_ok();
        moved
    }

    fn move_into_place(&self) -> Result<()> {
        if !self.out.exists() {
            return std::fs::rename(&self.staging, &self.out).map_err(|e| {
                folder_error(&self.out, format!("cannot create the output folder: {e}"))
            });
        }
        let entries = std::fs::read_dir(&self.staging)
            .map_err(|e| folder_error(&self.staging, format!("cannot read: {e}")))?;
        for entry in entries {
            let entry =
                entry.map_err(|e| folder_error(&self.staging, format!("cannot read: {e}")))?;
            let dest = self.out.join(entry.file_name());
            std::fs::rename(entry.path(), &dest)
                .map_err(|e| folder_error(&dest, format!("cannot move into place: {e}")))?;
        }
        std::fs::remove_dir(&self.staging)
            .map_err(|e| folder_error(&self.staging, format!("cannot remove: {e}")))
    }
}

impl Drop for StagedDir {
    fn drop(&mut self) {
        if self.committed {
            return;
        }
        let mut guard = active();
        if guard.as_deref() == Some(self.staging.as_path()) {
            *guard = None;
        }
        let _ = std::fs::remove_dir_all(&self.staging);
    }
}

/// Removes the staging folders `.NAME.staging-PID` in `base` of processes that no longer run (a
/// process killed before it could clean up, `kill -9`), best effort.
fn remove_stale_staging(base: &Path, name: &str) {
    let Ok(entries) = std::fs::read_dir(base) else {
        return;
    };
    let prefix = format!(".{name}.staging-");
    for entry in entries.flatten() {
        let file_name = entry.file_name();
        let Some(pid) = file_name
            .to_str()
            .and_then(|n| n.strip_prefix(&prefix))
            .and_then(|p| p.parse::<u32>().ok())
        else {
            continue;
        };
        if pid != std::process::id() && !crate::io::process_runs(pid) {
            let _ = std::fs::remove_dir_all(entry.path());
        }
    }
}

/// Removes the staging folder of the experiment under way (waiting for a commit under way to
/// finish first) and exits with `code`. For a handler that must quit at once: what is left is
/// the complete set of files or nothing new.
pub fn abandon_staged_and_exit(code: i32) -> ! {
    let guard = active();
    if let Some(dir) = guard.as_deref() {
        // Another thread may be creating a file in the folder at this moment: retry briefly.
        for _ in 0..50 {
            match std::fs::remove_dir_all(dir) {
                Ok(()) => break,
                Err(e) if e.kind() == std::io::ErrorKind::NotFound => break,
                Err(_) => std::thread::sleep(std::time::Duration::from_millis(10)),
            }
        }
    }
    // The guard is held until the process ends, so no commit can start.
    std::process::exit(code)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn scratch(tag: &str) -> PathBuf {
        let d = std::env::temp_dir().join(format!("rdlidar-staging-{tag}-{}", std::process::id()));
        let _ = std::fs::remove_dir_all(&d);
        std::fs::create_dir_all(&d).unwrap();
        d
    }

    #[test]
    fn a_new_folder_appears_whole_on_commit() {
        let root = scratch("new");
        let out = root.join("results");
        let s = StagedDir::create(&out, false).unwrap();
        std::fs::write(s.dir().join("a.txt"), "a").unwrap();
        std::fs::write(s.dir().join("b.txt"), "b").unwrap();
        assert!(!out.exists());
        s.commit().unwrap();
        assert_eq!(std::fs::read_to_string(out.join("b.txt")).unwrap(), "b");
        let names: Vec<_> = std::fs::read_dir(&root).unwrap().collect();
        assert_eq!(names.len(), 1, "only the output folder is left");
        std::fs::remove_dir_all(&root).ok();
    }

    #[test]
    fn an_existing_folder_gets_the_set_and_a_dropped_one_nothing() {
        let root = scratch("existing");
        let out = root.join("results");
        std::fs::create_dir(&out).unwrap();
        std::fs::write(out.join("a.txt"), "old").unwrap();
        assert!(StagedDir::create(&out, false).is_err());
        let s = StagedDir::create(&out, true).unwrap();
        std::fs::write(s.dir().join("a.txt"), "new").unwrap();
        drop(s);
        assert_eq!(std::fs::read_to_string(out.join("a.txt")).unwrap(), "old");
        assert_eq!(std::fs::read_dir(&root).unwrap().count(), 1);
        let s = StagedDir::create(&out, true).unwrap();
        std::fs::write(s.dir().join("a.txt"), "new").unwrap();
        s.commit().unwrap();
        assert_eq!(std::fs::read_to_string(out.join("a.txt")).unwrap(), "new");
        assert_eq!(std::fs::read_dir(&root).unwrap().count(), 1);
        std::fs::remove_dir_all(&root).ok();
    }
}
