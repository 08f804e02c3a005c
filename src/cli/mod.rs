//! The subcommands, one module each, and the few helpers they share: the arguments several
//! commands take ([`args`]), the progress bar, JSON output, and where outputs go.

pub mod args;
pub mod build;
pub mod dataset;
pub mod extract;
pub mod fly;
pub mod info;
pub mod mesh;
pub mod progress;
pub mod recover;
pub mod render;
pub mod replace;
pub mod scan;
pub mod scene;
pub mod serve;
pub mod sidecar;
pub mod verify;

use std::path::Path;

use serde::Serialize;

use fmrh::store::FileSource;
use fmrh::{Error, Store};

/// Prints `value` as pretty JSON.
pub fn print_json<T: Serialize>(value: &T) -> Result<(), Error> {
    let text = serde_json::to_string_pretty(value)
        .map_err(|e| Error::InvalidArgument(format!("cannot format the report: {e}")))?;
    println!("{text}");
    Ok(())
}

/// Opens a container for the read-only commands: positioned reads, the state registered
/// against reuse by writers in other processes (see `Store::open`).
pub fn open(path: &Path) -> Result<Store<FileSource>, Error> {
    Store::open(path)
}

/// The URL `path` names, when it is one (`http://`, `https://`, `s3://`): a remote
/// container or dataset.
pub fn url_of(path: &Path) -> Option<&str> {
    path.to_str().filter(|t| fmrh::store::is_url(t))
}

/// The error for a URL in a build without the `remote` feature.
#[cfg(not(feature = "remote"))]
pub fn no_remote(url: &str) -> Error {
    Error::InvalidArgument(format!(
        "{url}: this fmrh was built without the `remote` feature (HTTP range reads)"
    ))
}

/// Refuses an existing `output` unless `force` (`-`, standard output, always goes).
pub fn check_output(output: &Path, force: bool) -> Result<(), Error> {
    if output != Path::new("-") && !force && output.exists() {
        return Err(Error::InvalidArgument(format!(
            "{} exists; pass --force to replace it",
            output.display()
        )));
    }
    Ok(())
}

/// Writes `bytes` to `output`: standard output for `-`, else atomically (an existing file
/// stays whole until the new one replaces it, and only with `force`).
pub fn write_output(output: &Path, force: bool, bytes: &[u8]) -> Result<(), Error> {
    use std::io::Write;
    if output == Path::new("-") {
        let mut out = std::io::stdout().lock();
        return out
            .write_all(bytes)
            .and_then(|()| out.flush())
            .map_err(|e| Error::io("<stdout>", e));
    }
    fmrh::store::write_atomically(output, force, |w| {
        w.write_all(bytes).map_err(|e| Error::io(output, e))
    })
}

/// Whether `path` names a dataset (a directory with a MANIFEST) rather than a container; a
/// directory without one is an error, not a file to open.
pub fn is_dataset(path: &Path) -> Result<bool, Error> {
    if url_of(path).is_some() {
        // A URL names a dataset when it ends with `/` or `/MANIFEST`.
        return Ok(fmrh::dataset::is_dataset(path));
    }
    if !path.is_dir() {
        return Ok(false);
    }
    if fmrh::dataset::is_dataset(path) {
        return Ok(true);
    }
    Err(Error::input(
        path,
        "a directory without a MANIFEST: not an fmrh dataset (nor a container file)",
    ))
}
