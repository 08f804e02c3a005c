//! Compacting a dataset (issue 39, point 4): every tile's pinned state rewritten as a fresh
//! build of it would be, published by one manifest commit.
//!
//! Each tile is rewritten ([`crate::store::txn::compact::rewrite`]: the file's own options,
//! read back sample for sample before it takes its name) into a **new** file under a name no
//! file uses, never over the old one: the old files are the state every reader and the
//! manifest's current record pin, and must stay whole until one manifest record switches
//! every pin to the new files (`format-spec/dataset.md` §4). Then the old files are removed.
//!
//! * A crash before the manifest record is durable leaves the dataset as it was, plus new
//!   files that no state names: the validator lists them as strays, and the next change steps
//!   around their names.
//! * After it, the dataset is the compacted one. The old files are removed; a reader that
//!   opened the dataset before and opens one of them after is told its state was superseded
//!   (exit 75), as after a whole-tile replacement, and opens again.
//! * The manifest's writer lock is held throughout, so no other change can land in between
//!   and be lost.
//!
//! The adjacent-cluster tables are computed afresh from the new files (the same model makes
//! the same tables; computing them costs one read of each tile's edges).

use std::collections::{HashMap, HashSet};
use std::path::Path;
use std::sync::Arc;

use serde::Serialize;

use super::adjacency::TileEdges;
use super::build::sync_dir;
use super::plan::{record_of, tile_name};
use super::commit::{publish, read_manifest, records, Dir, Files};
use super::manifest::MANIFEST_NAME;
use super::reader::{Dataset, Tile};
use crate::error::{Error, Result};
use crate::format::manifest::TileRecord;
use crate::store::txn::rewrite;
use crate::store::{CompactOptions, Store};

/// What compacting one tile did.
#[derive(Clone, Debug, Serialize)]
pub struct TileCompacted {
    /// Its file before.
    pub name_before: String,
    /// Its file after.
    pub name_after: String,
    /// Bytes of the file before.
    pub bytes_before: u64,
    /// Bytes of the new file.
    pub bytes_after: u64,
}

/// What compacting a dataset did.
#[derive(Clone, Debug, Serialize)]
pub struct DatasetCompacted {
    /// The manifest's txn id after.
    pub txn_id: u64,
    /// Each tile.
    pub tiles: Vec<TileCompacted>,
    /// Bytes of every file of the dataset before (tiles and manifest).
    pub bytes_before: u64,
    /// Bytes after.
    pub bytes_after: u64,
}

/// The file name stem of a tile name: `n43e006-2.fmrh` → `n43e006`, so that compacting
/// again alternates between two names rather than growing one.
fn stem(name: &str) -> &str {
    let stem = name.strip_suffix(".fmrh").unwrap_or(name);
    match stem.rsplit_once('-') {
        Some((s, n)) if !s.is_empty() && !n.is_empty() && n.bytes().all(|b| b.is_ascii_digit()) => {
            s
        }
        _ => stem,
    }
}

fn file_len(path: &Path) -> Result<u64> {
    Ok(std::fs::metadata(path)
        .map_err(|e| Error::io(path, e))?
        .len())
}

/// Compacts the dataset in `dir` (see the module doc). `on_tile` hears each tile as it is
/// rewritten: `(index, count, name)`.
pub fn compact(
    dir: &Path,
    options: &CompactOptions,
    on_tile: &mut dyn FnMut(usize, usize, &str),
) -> Result<DatasetCompacted> {
    let files = Dir(dir.to_path_buf());
    // Opened for writing: the dataset's writer lock, held to the end.
    let manifest = Arc::new(files.open(MANIFEST_NAME)?);
    let (state, src) = read_manifest(&manifest)?;
    let all = records(&state, &src)?;
    let reader = Dataset::open(dir)?;
    let mut bytes_before = file_len(&dir.join(MANIFEST_NAME))?;
    let mut taken: HashSet<String> = std::fs::read_dir(dir)
        .map_err(|e| Error::io(dir, e))?
        .filter_map(|e| e.ok())
        .filter_map(|e| e.file_name().to_str().map(str::to_ascii_lowercase))
        .collect();
    taken.extend(all.iter().map(|t| t.name().to_ascii_lowercase()));
    let mut written: Vec<String> = Vec::with_capacity(all.len());
    let mut updated: Vec<TileRecord> = Vec::with_capacity(all.len());
    let mut report: Vec<TileCompacted> = Vec::with_capacity(all.len());
    let mut edges: HashMap<usize, Arc<TileEdges>> = HashMap::new();
    let result = (|| -> Result<()> {
        for (i, t) in all.iter().enumerate() {
            on_tile(i, all.len(), t.name());
            let old = reader.open_tile(&Tile {
                index: i as u64,
                record: *t,
            })?;
            let before = file_len(&dir.join(t.name()))?;
            bytes_before += before;
            let name = tile_name(Path::new(&format!("{}.fmrh", stem(t.name()))), &taken);
            taken.insert(name.to_ascii_lowercase());
            let path = dir.join(&name);
            let after = rewrite(&old, &path, false, options)?;
            written.push(name.clone());
            drop(old);
            let store = Store::open(&path)?;
            let record = record_of(&store, &name, t.rect())?;
            edges.insert(i, Arc::new(TileEdges::read(&store, &record)?));
            updated.push(record);
            report.push(TileCompacted {
                name_before: t.name().to_string(),
                name_after: name,
                bytes_before: before,
                bytes_after: after,
            });
        }
        sync_dir(dir)
    })();
    let outcome = result.and_then(|()| {
        publish::<Dir>(
            &files,
            &manifest,
            &state,
            &src,
            updated,
            state.georeference(),
            Vec::new(),
            Vec::new(),
            std::mem::take(&mut edges),
        )
    });
    match outcome {
        Ok(commit) => {
            // No state the manifest now holds names the old files (the slot of the state
            // before still does, until the next commit: readers of it are told "superseded").
            drop(reader);
            for t in &all {
                let _ = std::fs::remove_file(dir.join(t.name()));
            }
            sync_dir(dir)?;
            let bytes_after = file_len(&dir.join(MANIFEST_NAME))?
                + report.iter().map(|t| t.bytes_after).sum::<u64>();
            Ok(DatasetCompacted {
                txn_id: commit.txn_id,
                tiles: report,
                bytes_before,
                bytes_after,
            })
        }
        Err(e) => {
            // Not named by any manifest state: nothing refers to them.
            for name in &written {
                let _ = std::fs::remove_file(dir.join(name));
            }
            Err(e)
        }
    }
}

#[cfg(test)]
mod tests {
    use super::stem;

    #[test]
    fn stems_drop_one_numbered_suffix() {
        assert_eq!(stem("n43e006.fmrh"), "n43e006");
        assert_eq!(stem("n43e006-2.fmrh"), "n43e006");
        assert_eq!(stem("ps4k_0_1-13.fmrh"), "ps4k_0_1");
        assert_eq!(stem("a-b.fmrh"), "a-b");
        assert_eq!(stem("-2.fmrh"), "-2");
    }
}
