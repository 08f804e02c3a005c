//! Creating a file atomically: write under a temporary name beside the target, flush, fsync,
//! rename into place, fsync the directory. A failure or a crash at any point leaves the target
//! as it was: absent, or the previous file intact.
//!
//! The temporary file is `.<target name>.<random>.fmrh-tmp` in the target's directory, created
//! with mode `0666` less the umask (what the target will have, as with `touch`), and locked
//! (`flock`) while it is written. So what a killed writer leaves is recognisable: the next
//! write of the same target removes every such file that nobody holds locked, and leaves one
//! that another writer is still filling. A process that handles SIGINT or SIGTERM (the CLI)
//! calls [`remove_temporary_files`] to remove the files it was writing before it exits.

use std::io::{BufWriter, Write};
use std::path::{Path, PathBuf};
use std::sync::Mutex;

use crate::error::{Error, Result};

/// The temporary files this process is writing now.
static IN_PROGRESS: Mutex<Vec<PathBuf>> = Mutex::new(Vec::new());

fn in_progress() -> std::sync::MutexGuard<'static, Vec<PathBuf>> {
    IN_PROGRESS.lock().unwrap_or_else(|p| p.into_inner())
}

/// Removes the temporary files this process is writing (for a signal handler that is about
/// to exit). Best effort: a file it cannot remove is left for the next write's clean-up.
pub fn remove_temporary_files() {
    for p in in_progress().drain(..) {
        if p.is_dir() {
            let _ = std::fs::remove_dir_all(p);
        } else {
            let _ = std::fs::remove_file(p);
        }
    }
}

/// The name prefix and suffix of `target`'s temporary files.
fn temp_affixes(target: &Path) -> (String, &'static str) {
    let name = target
        .file_name()
        .map(|n| n.to_string_lossy().into_owned())
        .unwrap_or_default();
    (format!(".{name}."), ".fmrh-tmp")
}

/// Removes the temporary files of `target` in `dir` that no writer holds: what a killed
/// write left. Returns how many it removed.
fn remove_stale(dir: &Path, target: &Path) -> usize {
    let (prefix, suffix) = temp_affixes(target);
    let Ok(entries) = std::fs::read_dir(dir) else {
        return 0;
    };
    let mut removed = 0;
    for entry in entries.flatten() {
        let name = entry.file_name().to_string_lossy().into_owned();
        if !(name.starts_with(&prefix) && name.ends_with(suffix)) {
            continue;
        }
        // A writer holds its file locked until it renames it: a lock we can take is nobody's.
        let Ok(file) = std::fs::File::open(entry.path()) else {
            continue;
        };
        if file.try_lock().is_ok() && std::fs::remove_file(entry.path()).is_ok() {
            removed += 1;
        }
    }
    removed
}

/// Creates `path` with what `fill` writes, atomically. The bytes go to a temporary file in the
/// same directory, which is flushed, synced and renamed into place, then the directory is
/// synced. On any failure the temporary file is removed and `path` is untouched. An existing
/// `path` is refused unless `overwrite`, and is then replaced in one rename. Temporary files
/// of `path` that a killed writer left are removed first (see the module docs).
pub fn write_atomically<T>(
    path: &Path,
    overwrite: bool,
    fill: impl FnOnce(&mut BufWriter<&std::fs::File>) -> Result<T>,
) -> Result<T> {
    write_atomically_checked(path, overwrite, fill, |_| Ok(()))
}

/// [`write_atomically`], with `check` run on the complete, synced temporary file (by its path)
/// before it is renamed into place: an error from it removes the file and leaves `path` as it
/// was. (Compaction reads its new file back there, so that a file that does not hold what it
/// was written from never replaces the one that does.)
pub fn write_atomically_checked<T>(
    path: &Path,
    overwrite: bool,
    fill: impl FnOnce(&mut BufWriter<&std::fs::File>) -> Result<T>,
    check: impl FnOnce(&Path) -> Result<()>,
) -> Result<T> {
    if !overwrite && path.exists() {
        return Err(Error::InvalidArgument(format!(
            "{} exists; pass --force to replace it",
            path.display()
        )));
    }
    let dir = match path.parent() {
        Some(d) if !d.as_os_str().is_empty() => d,
        _ => Path::new("."),
    };
    remove_stale(dir, path);
    let (prefix, suffix) = temp_affixes(path);
    let mut builder = tempfile::Builder::new();
    builder.prefix(&prefix).suffix(suffix);
    #[cfg(unix)]
    {
        use std::os::unix::fs::PermissionsExt;
        // Like any created file: 0666 less the umask (tempfile's default is 0600).
        builder.permissions(std::fs::Permissions::from_mode(0o666));
    }
    let temp = builder.tempfile_in(dir).map_err(|e| Error::io(dir, e))?;
    temp.as_file()
        .try_lock()
        .map_err(|e| Error::io(temp.path(), std::io::Error::other(e.to_string())))?;
    let temp_path = temp.path().to_path_buf();
    in_progress().push(temp_path.clone());
    // Renamed into place, or removed when `temp` drops: either way no longer ours to clean.
    let result = write_and_persist(temp, path, dir, overwrite, fill, check);
    in_progress().retain(|p| *p != temp_path);
    result
}

/// Creates the directory `path` atomically: `fill` writes its files into a temporary
/// directory beside it (`.<name>.<random>.fmrh-tmp`), which is then renamed to `path`. An
/// error or a signal removes the temporary directory and leaves `path` as it was. With
/// `overwrite`, an existing `path` is first renamed aside and removed once the new one is
/// in place: a crash between the two renames leaves the old tree beside it under a
/// temporary name, never a mix of old and new files under `path`.
pub fn write_dir_atomically<T>(
    path: &Path,
    overwrite: bool,
    fill: impl FnOnce(&Path) -> Result<T>,
) -> Result<T> {
    let refuse = || {
        Error::InvalidArgument(format!(
            "{} exists; pass --force to replace it",
            path.display()
        ))
    };
    if !overwrite && path.exists() {
        return Err(refuse());
    }
    let dir = match path.parent() {
        Some(d) if !d.as_os_str().is_empty() => d,
        _ => Path::new("."),
    };
    let (prefix, suffix) = temp_affixes(path);
    let temp = tempfile::Builder::new()
        .prefix(&prefix)
        .suffix(suffix)
        .tempdir_in(dir)
        .map_err(|e| Error::io(dir, e))?;
    let temp_path = temp.path().to_path_buf();
    in_progress().push(temp_path.clone());
    let result = fill(&temp_path).and_then(|value| {
        let kept = temp.keep();
        let placed = if path.exists() {
            if !overwrite {
                Err(refuse())
            } else {
                let old = dir.join(format!("{prefix}old-{}{suffix}", std::process::id()));
                std::fs::rename(path, &old)
                    .and_then(|()| std::fs::rename(&kept, path))
                    .map_err(|e| Error::io(path, e))
                    .map(|()| {
                        let _ = std::fs::remove_dir_all(&old);
                    })
            }
        } else {
            std::fs::rename(&kept, path).map_err(|e| Error::io(path, e))
        };
        if placed.is_err() {
            let _ = std::fs::remove_dir_all(&kept);
        }
        placed.and_then(|()| sync_dir(dir)).map(|()| value)
    });
    in_progress().retain(|p| *p != temp_path);
    result
}

fn write_and_persist<T>(
    temp: tempfile::NamedTempFile,
    path: &Path,
    dir: &Path,
    overwrite: bool,
    fill: impl FnOnce(&mut BufWriter<&std::fs::File>) -> Result<T>,
    check: impl FnOnce(&Path) -> Result<()>,
) -> Result<T> {
    let value = {
        let mut w = BufWriter::with_capacity(1 << 20, temp.as_file());
        let value = fill(&mut w)?;
        w.flush().map_err(|e| Error::io(temp.path(), e))?;
        value
    };
    temp.as_file()
        .sync_all()
        .map_err(|e| Error::io(temp.path(), e))?;
    // Unlock before the rename: the lock belongs to the open file description, which a child
    // process forked meanwhile by another thread shares until it execs. Held across the
    // rename, it would make the new file look locked (to a writer's `Container::open`) for
    // that moment.
    temp.as_file()
        .unlock()
        .map_err(|e| Error::io(temp.path(), e))?;
    check(temp.path())?;
    let persisted = if overwrite {
        temp.persist(path).map_err(|e| Error::io(path, e.error))?
    } else {
        temp.persist_noclobber(path)
            .map_err(|e| Error::io(path, e.error))?
    };
    drop(persisted);
    sync_dir(dir)?;
    Ok(value)
}

/// Makes a rename in `dir` durable.
fn sync_dir(dir: &Path) -> Result<()> {
    #[cfg(unix)]
    {
        std::fs::File::open(dir)
            .and_then(|d| d.sync_all())
            .map_err(|e| Error::io(dir, e))?;
    }
    #[cfg(not(unix))]
    let _ = dir;
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_killed_writers_file_is_removed_and_a_live_ones_kept() {
        let dir = tempfile::tempdir().unwrap();
        let target = dir.path().join("out.fmrh");
        let stale = dir.path().join(".out.fmrh.abc123.fmrh-tmp");
        std::fs::write(&stale, b"half a file").unwrap();
        let live = dir.path().join(".out.fmrh.def456.fmrh-tmp");
        std::fs::write(&live, b"being written").unwrap();
        let holder = std::fs::File::open(&live).unwrap();
        holder.lock().unwrap();
        let other = dir.path().join(".other.fmrh.abc.fmrh-tmp");
        std::fs::write(&other, b"another target's").unwrap();
        write_atomically(&target, false, |w| {
            w.write_all(b"whole").map_err(|e| Error::io("<test>", e))
        })
        .unwrap();
        assert!(!stale.exists(), "the killed writer's file stays");
        assert!(live.exists() && other.exists());
        assert_eq!(std::fs::read(&target).unwrap(), b"whole");
        assert!(in_progress().is_empty());
    }
}
