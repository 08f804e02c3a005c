//! Compaction: a container's current state rewritten as a fresh build of it would be, in a
//! new file renamed over the old one.
//!
//! Edits leave pages behind: a replaced payload's pages go to the free list, and a commit
//! reuses them only where its new payloads fit. `compact` writes the state again from its
//! samples, with the file's own block size, thresholds, precision, thinning and page size:
//! the model is the one the editor keeps (a fresh build of the same samples, the editor's
//! invariant), so every sample reads the same and every scene answers the same.
//!
//! **Atomicity.** The rewrite holds the writer's lock on the old file the whole time, so no
//! commit can land in it and be lost; it writes the new file beside it, syncs it, checks that
//! it reads back every sample bit for bit, and renames it over the old one (then syncs the
//! directory). A crash before the rename leaves the old file and a hidden temporary, never a
//! half-written container under the name. Readers that opened the old file keep reading it
//! (the inode lives while they hold it); readers that open after the rename read the new
//! one. A writer that opened the old file just before the rename and took the lock just
//! after finds it no longer at its path and opens again (`FileIo::open`).

use std::path::Path;

use serde::Serialize;

use super::container::editor_of;
use super::Container;
use crate::error::{Error, Result};
use crate::store::write::write_file_checked;
use crate::store::{FileSource, Store, WriteOptions};

/// How to rewrite.
#[derive(Clone, Debug, Default)]
pub struct CompactOptions {
    /// Code every payload alone (as `build --payloads-alone`); by default payloads are coded
    /// against their parents' grids where that is smaller, as a default build codes them.
    pub payloads_alone: bool,
}

/// What a compaction did.
#[derive(Clone, Debug, Serialize)]
pub struct Compacted {
    /// The file's length before.
    pub bytes_before: u64,
    /// The file's length after.
    pub bytes_after: u64,
    /// The txn id of the state rewritten (the new file's state is txn 1 of a fresh file).
    pub txn_before: u64,
    /// Pages the old file held on its free list.
    pub free_pages_before: u64,
}

/// Writes the state `store` holds as a fresh build of it would be to `dest` (atomically:
/// complete or not at all; an existing `dest` only if `overwrite`), with the file's own block
/// size, thresholds, precision, thinning and page size. The new file is read back before it
/// takes `dest`'s name: unless it holds every sample bit for bit, it is removed and `dest` is
/// left as it was. Returns the new file's length.
pub(crate) fn rewrite<S: crate::store::Source>(
    store: &Store<S>,
    dest: &Path,
    overwrite: bool,
    options: &CompactOptions,
) -> Result<u64> {
    let samples = store.read_window(store.domain().data_rect())?;
    let editor = editor_of(store, samples.clone())?;
    let metadata = store.header().metadata.clone();
    let write = WriteOptions {
        page_size: store.page_size(),
        against_parents: !options.payloads_alone,
        ..WriteOptions::default()
    };
    let check = |written: &Path| {
        let fresh = Store::<FileSource>::open(written)?;
        let again = fresh.read_window(fresh.domain().data_rect())?;
        let same = again.samples().len() == samples.samples().len()
            && again
                .samples()
                .iter()
                .zip(samples.samples())
                .all(|(a, b)| a.to_bits() == b.to_bits());
        if same {
            Ok(())
        } else {
            Err(Error::Internal(format!(
                "{}: the compacted file does not read back the samples it was written from",
                dest.display()
            )))
        }
    };
    let summary = write_file_checked(editor.model(), &metadata, dest, &write, overwrite, check)?;
    Ok(summary.file_length)
}

/// Rewrites the container at `path` as a fresh build of its current state (see the module
/// doc). Refused while another writer holds the file.
pub fn compact(path: &Path, options: &CompactOptions) -> Result<Compacted> {
    let container = Container::open(path)?;
    let snapshot = container.read()?;
    let store = &*snapshot;
    let bytes_before = std::fs::metadata(path).map_err(|e| Error::io(path, e))?.len();
    let txn_before = store.txn_id();
    let free_pages_before = store.free_pages()?.len() as u64;
    let bytes_after = rewrite(store, path, true, options)?;
    drop(snapshot);
    // The lock on the old file goes with it; the path names the new one already.
    container.abandon();
    Ok(Compacted {
        bytes_before,
        bytes_after,
        txn_before,
        free_pages_before,
    })
}
