//! Creating a file atomically: write under a temporary name beside the target, flush, fsync,
//! rename into place, fsync the directory. A failure or a crash at any point leaves the target
//! as it was: absent, or the previous file intact.

use std::io::{BufWriter, Write};
use std::path::Path;

use crate::error::{Error, Result};

/// Creates `path` with what `fill` writes, atomically. The bytes go to a temporary file in the
/// same directory, which is flushed, synced and renamed into place, then the directory is
/// synced. On any failure the temporary file is removed and `path` is untouched. An existing
/// `path` is refused unless `overwrite`, and is then replaced in one rename.
pub fn write_atomically<T>(
    path: &Path,
    overwrite: bool,
    fill: impl FnOnce(&mut BufWriter<&std::fs::File>) -> Result<T>,
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
    let temp = tempfile::Builder::new()
        .prefix(".fmrh-")
        .suffix(".tmp")
        .tempfile_in(dir)
        .map_err(|e| Error::io(dir, e))?;
    let value = {
        let mut w = BufWriter::with_capacity(1 << 20, temp.as_file());
        let value = fill(&mut w)?;
        w.flush().map_err(|e| Error::io(temp.path(), e))?;
        value
    };
    temp.as_file()
        .sync_all()
        .map_err(|e| Error::io(temp.path(), e))?;
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
