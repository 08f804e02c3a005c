//! Changing a dataset atomically across its files (`format-spec/dataset.md` §4): each tile
//! the change touches is committed as a container commits, keeping the state the manifest
//! pins (its slot, its pages and its length), then one manifest record switches the dataset
//! to the new pins. A crash before that record is durable leaves every tile old to a dataset
//! reader; after, every tile new. The next change first republishes the pinned state of any
//! tile an interrupted change moved on.
//!
//! The files are reached through [`Files`], so the simulated disks of the tests run the same
//! code as the directory on a real file system.

use std::path::PathBuf;
use std::sync::Arc;

use serde::Serialize;

use super::adjacency::{tables_of, TileEdges};
use super::manifest::{write_state, Contents, ManifestState, MANIFEST_NAME};
use crate::error::{Error, Result};
use crate::format::commit::Slot;
use crate::format::manifest::{StatePin, TileRecord, SEAM_FIRST, SEAM_MEAN, SEAM_STRICT};
use crate::format::COMMIT_RECOVERY_NEEDED;
use crate::heightfield::Heightfield;
use crate::model::SampleRect;
use crate::store::io::{FileIo, Io};
use crate::store::txn::IoSource;
use crate::store::{CommitSummary, Container};

/// How a dataset writer reaches its files, each opened for writing (and locked).
pub trait Files {
    /// An open file.
    type File: Io + 'static;
    /// Opens the file `name` of the dataset (the manifest, or a tile) for writing.
    fn open(&self, name: &str) -> Result<Self::File>;
}

/// The files of a dataset directory.
pub struct Dir(pub PathBuf);

impl Files for Dir {
    type File = FileIo;

    fn open(&self, name: &str) -> Result<FileIo> {
        let path = self.0.join(name);
        FileIo::open(&path).map_err(|e| match e.kind() {
            std::io::ErrorKind::NotFound => Error::input(&path, "no such file in the dataset"),
            _ => Error::io(&path, e),
        })
    }
}

/// What a change did to one tile.
#[derive(Clone, Debug, Serialize)]
pub struct TileCommit {
    /// The tile's index.
    pub index: u64,
    /// Its file.
    pub name: String,
    /// Whether its pinned state was republished first (an earlier change was interrupted
    /// after committing this tile).
    pub republished: bool,
    /// The container commit.
    pub summary: CommitSummary,
}

/// What a change to a dataset did.
#[derive(Clone, Debug, Serialize)]
pub struct DatasetCommit {
    /// The manifest's txn id after the change.
    pub txn_id: u64,
    /// Each tile changed.
    pub tiles: Vec<TileCommit>,
}

/// The manifest state `io` holds.
pub(crate) fn read_manifest<I: Io>(io: &Arc<I>) -> Result<(ManifestState, IoSource<Arc<I>>)> {
    let len = io.len().map_err(|e| Error::io(io.name(), e))?;
    let src = IoSource::new(Arc::new(Arc::clone(io)), len);
    Ok((ManifestState::read(&src)?, src))
}

/// Every tile record of `state`.
pub(crate) fn records<S: crate::store::Source>(
    state: &ManifestState,
    src: &S,
) -> Result<Vec<TileRecord>> {
    let mut out = Vec::new();
    for p in 0..state.head.pages.len() {
        out.extend(state.page(src, p)?.iter().copied());
    }
    Ok(out)
}

/// Makes the state `pin` names the latest of the tile on `io`, if an interrupted change left
/// a newer one: a copy of its record, marked recovery-needed, with the next txn id, in the
/// other slot. Returns whether it wrote one. Fails (D-4) when neither slot holds the state.
pub fn republish<I: Io>(io: &Arc<I>, pin: StatePin) -> Result<bool> {
    let len = io.len().map_err(|e| Error::io(io.name(), e))?;
    let src = IoSource::new(Arc::new(Arc::clone(io)), len);
    let slots = crate::store::slots::read_slots(&src)?;
    let valid: Vec<(u64, &crate::format::CommitRecord)> = (0u64..)
        .zip(&slots)
        .filter_map(|(i, s)| match s {
            Slot::Valid(r) => Some((i, &**r)),
            _ => None,
        })
        .collect();
    let Some(&(at, pinned)) = valid
        .iter()
        .filter(|(_, r)| pin.matches(r))
        .max_by_key(|(_, r)| r.txn_id.get())
    else {
        return Err(crate::store::slots::pinned_missing(&src, pin));
    };
    let latest = valid.iter().map(|(_, r)| r.txn_id.get()).max().unwrap_or(0);
    if latest == pinned.txn_id.get() {
        return Ok(false);
    }
    let copy = pinned.copy_as(latest + 1, pinned.flags.get() | COMMIT_RECOVERY_NEEDED);
    let p = u64::from(pinned.page_size.get());
    let e = |err| Error::io(io.name(), err);
    io.write_at((1 - at) * p, zerocopy::IntoBytes::as_bytes(&copy))
        .map_err(e)?;
    io.sync().map_err(e)?;
    Ok(true)
}

/// The part of `patch` (placed at dataset `(col0, row0)`) inside `rect`, and where it goes
/// in the tile.
pub(crate) fn part_in(
    patch: &Heightfield,
    col0: u64,
    row0: u64,
    rect: &SampleRect,
) -> Option<(Heightfield, u64, u64)> {
    let p = SampleRect {
        col0,
        row0,
        col1: col0 + u64::from(patch.width()) - 1,
        row1: row0 + u64::from(patch.height()) - 1,
    };
    let o = p.intersect(rect)?;
    let w = u64::from(patch.width());
    let part = Heightfield::from_fn(
        (o.col1 - o.col0 + 1) as u32,
        (o.row1 - o.row0 + 1) as u32,
        |x, y| {
            patch.samples()
                [((o.row0 - row0 + u64::from(y)) * w + o.col0 - col0 + u64::from(x)) as usize]
        },
    )
    .ok()?;
    Some((part, o.col0 - rect.col0, o.row0 - rect.row0))
}

/// Replaces the samples of `patch` at dataset `(col0, row0)`, in every tile it meets (both
/// tiles of a shared edge it covers), atomically across the files.
pub fn replace<F: Files>(
    files: &F,
    col0: u64,
    row0: u64,
    patch: &Heightfield,
) -> Result<DatasetCommit> {
    let manifest = Arc::new(files.open(MANIFEST_NAME)?);
    let (state, src) = read_manifest(&manifest)?;
    let all = records(&state, &src)?;
    let columns = state.record.columns.get();
    let rows = state.record.rows.get();
    let p = SampleRect {
        col0,
        row0,
        col1: col0.saturating_add(u64::from(patch.width()) - 1),
        row1: row0.saturating_add(u64::from(patch.height()) - 1),
    };
    if p.col1 >= columns || p.row1 >= rows {
        return Err(Error::InvalidArgument(format!(
            "a {} x {} patch at column {col0}, row {row0} does not fit the {columns} x {rows} \
             dataset",
            patch.width(),
            patch.height()
        )));
    }
    // Every sample of the patch must lie in a tile: a hole stores nothing.
    for row in p.row0..=p.row1 {
        let mut col = p.col0;
        while col <= p.col1 {
            match all
                .iter()
                .map(TileRecord::rect)
                .find(|r| r.contains(col, row))
            {
                Some(r) => col = r.col1 + 1,
                None => {
                    return Err(Error::InvalidArgument(format!(
                        "the patch covers dataset column {col}, row {row}, where no tile lies \
                         (a hole): add a tile there first"
                    )))
                }
            }
        }
    }
    let mut changes = Vec::new();
    for (i, t) in all.iter().enumerate() {
        if let Some(part) = part_in(patch, col0, row0, &t.rect()) {
            changes.push((i, vec![part]));
        }
    }
    let (open, commits, updated) = commit_tiles(files, &all, &changes)?;
    publish::<F>(
        files,
        &manifest,
        &state,
        &src,
        updated,
        state.georeference(),
        open,
        commits,
        std::collections::HashMap::new(),
    )
}

/// Patches for one tile, each in the tile's own samples: the samples, and the column and
/// row of its first one.
pub type TilePatches = (usize, Vec<(Heightfield, u64, u64)>);

/// Tiles committed but not yet published by the manifest: their containers, still open
/// (so that no clean close overwrites the pinned state's slot).
pub(crate) type Committed<F> = Vec<Container<Arc<<F as Files>::File>>>;

/// What [`commit_tiles`] returns: the open containers, what each commit did, and the tile
/// records with the new pins.
pub(crate) type TilesCommitted<F> = (Committed<F>, Vec<TileCommit>, Vec<TileRecord>);

/// Commits `changes` (tile index, and the patches in its own samples) to their tiles, each
/// keeping the state the manifest pins (§4 step 1). On an error, every tile committed so
/// far is abandoned (left marked, its pinned state whole) and the error returned.
pub(crate) fn commit_tiles<F: Files>(
    files: &F,
    all: &[TileRecord],
    changes: &[TilePatches],
) -> Result<TilesCommitted<F>> {
    let mut open: Committed<F> = Vec::with_capacity(changes.len());
    let mut commits = Vec::with_capacity(changes.len());
    let mut updated = all.to_vec();
    let result = (|| -> Result<()> {
        for (i, parts) in changes {
            let t = all[*i];
            let io = Arc::new(files.open(t.name())?);
            let republished = republish(&io, t.pin())?;
            let (container, _) = Container::open_io(io)?;
            let base = container.read()?;
            if StatePin::of(base.commit_record()) != t.pin() {
                return Err(Error::Internal(format!(
                    "tile {} opened off its pin",
                    t.name()
                )));
            }
            container.set_min_length(base.commit_record().file_length.get());
            drop(base);
            let mut txn = container.begin_write()?;
            for (part, c, r) in parts {
                txn.replace_region(*c, *r, part)?;
            }
            let summary = txn.commit()?;
            let now = container.read()?;
            let root = now.node(0)?;
            updated[*i] = TileRecord::new(
                t.name(),
                t.rect(),
                now.pin(),
                (root.min_height, root.max_height),
            );
            drop(now);
            open.push(container);
            commits.push(TileCommit {
                index: *i as u64,
                name: t.name().to_string(),
                republished,
                summary,
            });
        }
        Ok(())
    })();
    match result {
        Ok(()) => Ok((open, commits, updated)),
        Err(e) => {
            open.into_iter().for_each(Container::abandon);
            Err(e)
        }
    }
}

/// The adjacent-cluster tables of the state `records` describe: recomputed for every tile
/// whose state changed (`changed`, by index into `records`) and every tile with a border to
/// one (a tile stores its east and south borders), carried over from `state` for the rest.
/// `edges` gives the edges of a changed tile; any other tile is opened at its pin.
fn tables_after<F: Files>(
    files: &F,
    state: &ManifestState,
    src: &dyn crate::store::Source,
    records: &[TileRecord],
    changed: &std::collections::BTreeSet<usize>,
    edges: &mut dyn FnMut(usize) -> Option<Result<Arc<TileEdges>>>,
) -> Result<std::collections::HashMap<String, Vec<u8>>> {
    let rects: Vec<_> = records.iter().map(TileRecord::rect).collect();
    // A tile stores its east and south borders: the tiles west and north of a changed one
    // (sharing or abutting its edge) store borders with it.
    let mut affected = changed.clone();
    for (k, r) in rects.iter().enumerate() {
        let west_or_north = |c: &crate::model::SampleRect| {
            (r.col1 == c.col0 || r.col1 + 1 == c.col0) && r.row0.max(c.row0) < r.row1.min(c.row1)
                || (r.row1 == c.row0 || r.row1 + 1 == c.row0)
                    && r.col0.max(c.col0) < r.col1.min(c.col1)
        };
        if changed.iter().any(|&c| west_or_north(&rects[c])) {
            affected.insert(k);
        }
    }
    let mut by_name = std::collections::HashMap::new();
    let mut out = std::collections::HashMap::new();
    for p in 0..state.head.pages.len() {
        for t in state.page(src, p)?.iter() {
            by_name.insert(t.name().to_string(), *t);
        }
    }
    let mut cache: std::collections::HashMap<usize, Arc<TileEdges>> =
        std::collections::HashMap::new();
    let mut edges_of = |k: usize| -> Result<Arc<TileEdges>> {
        if let Some(e) = cache.get(&k) {
            return Ok(Arc::clone(e));
        }
        let e = match edges(k) {
            Some(e) => e?,
            None => {
                let t = &records[k];
                let io = Arc::new(files.open(t.name())?);
                let len = io.len().map_err(|e| Error::io(io.name(), e))?;
                let store = crate::store::open::open_at(
                    IoSource::new(Arc::new(io), len),
                    crate::store::open::Walk::Lean,
                    Some(t.pin()),
                )?;
                Arc::new(TileEdges::read(&store, t)?)
            }
        };
        cache.insert(k, Arc::clone(&e));
        Ok(e)
    };
    for (k, t) in records.iter().enumerate() {
        let blob = if affected.contains(&k) {
            tables_of(k, &rects, &mut edges_of)?
        } else {
            match by_name.get(t.name()) {
                Some(old) => state.adjacency(src, old)?,
                None => tables_of(k, &rects, &mut edges_of)?,
            }
        };
        if !blob.is_empty() {
            out.insert(t.name().to_string(), blob);
        }
    }
    Ok(out)
}

/// Publishes `records` as the state after `state` (§4 steps 2 and 3), its adjacent-cluster
/// tables brought up to date, then closes the tiles committed for it; abandons them if
/// anything fails first. `extra` gives the edges of tiles new to the dataset (by index).
#[allow(clippy::too_many_arguments)]
pub(crate) fn publish<F: Files>(
    files: &F,
    manifest: &Arc<F::File>,
    state: &ManifestState,
    src: &dyn crate::store::Source,
    records: Vec<TileRecord>,
    georeference: Option<crate::heightfield::Georeference>,
    open: Committed<F>,
    tiles: Vec<TileCommit>,
    extra: std::collections::HashMap<usize, Arc<TileEdges>>,
) -> Result<DatasetCommit> {
    let outcome = (|| -> Result<(u8, crate::format::manifest::ManifestRecord)> {
        let mut changed: std::collections::BTreeSet<usize> =
            tiles.iter().map(|t| t.index as usize).collect();
        changed.extend(extra.keys().copied());
        let mut edges = |k: usize| -> Option<Result<Arc<TileEdges>>> {
            if let Some(e) = extra.get(&k) {
                return Some(Ok(Arc::clone(e)));
            }
            let at = tiles.iter().position(|t| t.index as usize == k)?;
            Some((|| {
                let snap = open[at].read()?;
                Ok(Arc::new(TileEdges::read(&snap, &records[k])?))
            })())
        };
        let adjacency = tables_after(files, state, src, &records, &changed, &mut edges)?;
        let contents = Contents {
            tiles: records.clone(),
            spacing_m: state.record.spacing_m(),
            georeference,
            seam: match state.record.seam {
                SEAM_FIRST => SEAM_FIRST,
                SEAM_MEAN => SEAM_MEAN,
                _ => SEAM_STRICT,
            },
            vertical_datum: state.vertical_datum(),
            adjacency,
        };
        write_state(&**manifest, Some((state.slot, &state.record)), &contents)
    })();
    match outcome {
        Ok((_, record)) => {
            // The dataset is at its new state: the tiles may now close cleanly (a clean copy
            // of a new state matches its pin).
            for c in open {
                let _ = c.close();
            }
            Ok(DatasetCommit {
                txn_id: record.txn_id.get(),
                tiles,
            })
        }
        Err(e) => {
            open.into_iter().for_each(Container::abandon);
            Err(e)
        }
    }
}

/// What recovering a dataset did.
#[derive(Clone, Debug, Default, Serialize)]
pub struct DatasetRecovery {
    /// The manifest's txn id.
    pub txn_id: u64,
    /// Tiles whose pinned state was republished (an interrupted change had moved them on).
    pub republished: Vec<String>,
    /// Tiles a container recovery changed (bytes cut, a torn slot cleared, or a mark).
    pub recovered: Vec<String>,
}

/// Recovers a dataset after a crash: every tile an interrupted change moved on gets its
/// pinned state back, and every tile is recovered as a container is (and closed cleanly).
pub fn recover<F: Files>(files: &F) -> Result<DatasetRecovery> {
    let manifest = Arc::new(files.open(MANIFEST_NAME)?);
    let (state, src) = read_manifest(&manifest)?;
    let mut out = DatasetRecovery {
        txn_id: state.record.txn_id.get(),
        ..DatasetRecovery::default()
    };
    for t in records(&state, &src)? {
        let io = Arc::new(files.open(t.name())?);
        if republish(&io, t.pin())? {
            out.republished.push(t.name().to_string());
        }
        let (container, recovery) = Container::open_io(io)?;
        if recovery.marked || recovery.truncated > 0 || recovery.slot_cleared {
            out.recovered.push(t.name().to_string());
        }
        container.close()?;
    }
    Ok(out)
}
