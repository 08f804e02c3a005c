//! Changing samples through the door: an [`Edit`] collects replacements and commits them all
//! at once or not at all, on a container (one transaction, format §11) or a dataset (every
//! tile the patches meet, one manifest commit, `dataset.md` §4).

use std::path::PathBuf;

use serde::Serialize;

use super::{Source, Terrain};
use crate::dataset::Dir;
use crate::error::{Error, Result};
use crate::heightfield::Heightfield;
use crate::model::SampleRect;
use crate::store::Container;

/// Replacements of samples, committed atomically ([`Terrain::edit`]).
///
/// Nothing is written before [`Edit::commit`]: dropping an edit, or an error, leaves the
/// terrain as it was. A crash during the commit leaves the old state or the new one, never a
/// mix. While a container's edit lives it holds the file's writer lock (a second writer, in
/// any process, is refused); readers go on reading the state they opened. The [`Terrain`]
/// it came from keeps reading the state it opened too: open it again to see the commit.
///
/// ```
/// # fn main() -> fmrh::Result<()> {
/// # let dir = tempfile::tempdir().unwrap();
/// # let path = dir.path().join("hills.fmrh");
/// let hills = fmrh::Heightfield::from_fn(200, 200, |x, y| ((x * y) % 97) as f32)?;
/// fmrh::create(&path, hills, &fmrh::CreateOptions::default())?;
/// let terrain = fmrh::Terrain::open(&path)?;
/// let mut edit = terrain.edit()?;
/// edit.replace(100, 100, fmrh::Heightfield::from_fn(20, 20, |_, _| -10.0)?)?;
/// let committed = edit.commit()?;
/// assert!(committed.blocks >= 1);
/// let after = fmrh::Terrain::open(&path)?;
/// assert_eq!(after.read(None)?.get(105, 105), Some(-10.0));
/// // The terrain opened before still reads the state it opened.
/// assert_eq!(terrain.read(None)?.get(105, 105), Some(((105 * 105) % 97) as f32));
/// # Ok(()) }
/// ```
pub struct Edit {
    target: Target,
    /// The data's extent, which every patch must lie inside.
    grid: SampleRect,
    patches: Vec<(u64, u64, Heightfield)>,
}

impl std::fmt::Debug for Edit {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Edit")
            .field("patches", &self.patches.len())
            .finish_non_exhaustive()
    }
}

enum Target {
    Container(Container),
    Dataset(PathBuf),
}

/// What a commit did ([`Edit::commit`]).
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct Committed {
    /// The state readers open from now on: the container's or the manifest's transaction id.
    pub txn_id: u64,
    /// Files changed: 1 for a container, the tiles the patches met for a dataset.
    pub files: u64,
    /// Physical blocks rewritten.
    pub blocks: u64,
    /// Coarse grids rewritten.
    pub grids: u64,
}

impl Terrain {
    /// Starts an edit of this terrain's file or dataset (a local one: a terrain read over a
    /// network is read-only). A container's file is recovered first if an interrupted writer
    /// left it so (format §11.4).
    pub fn edit(&self) -> Result<Edit> {
        let path = self.writable_path()?.to_path_buf();
        let info = self.info()?;
        let grid = SampleRect {
            col0: 0,
            row0: 0,
            col1: info.width.saturating_sub(1),
            row1: info.height.saturating_sub(1),
        };
        let target = match &self.source {
            Source::Container(_) => Target::Container(Container::open(&path)?),
            Source::Dataset(_) => Target::Dataset(path),
        };
        Ok(Edit {
            target,
            grid,
            patches: Vec::new(),
        })
    }
}

impl Edit {
    /// Replaces samples with `patch`'s (voids included: NaN samples become voids), its
    /// north-west sample at `(col, row)`. The patch must lie inside the data. Later patches
    /// win where patches overlap. Nothing is written until [`Edit::commit`].
    pub fn replace(&mut self, col: u64, row: u64, patch: Heightfield) -> Result<()> {
        let rect = SampleRect {
            col0: col,
            row0: row,
            col1: col.saturating_add(u64::from(patch.width()) - 1),
            row1: row.saturating_add(u64::from(patch.height()) - 1),
        };
        rect.check_inside(&self.grid, "data")?;
        self.patches.push((col, row, patch));
        Ok(())
    }

    /// Writes every replacement and publishes them in one commit: durable and visible to
    /// readers that open after it, all at once. With no replacement it commits nothing.
    pub fn commit(self) -> Result<Committed> {
        match self.target {
            Target::Container(container) => {
                let (files, blocks, grids) = if self.patches.is_empty() {
                    (0, 0, 0)
                } else {
                    let mut txn = container.begin_write()?;
                    for (col, row, patch) in &self.patches {
                        txn.replace_region(*col, *row, patch)?;
                    }
                    let summary = txn.commit()?;
                    (1, summary.blocks, summary.grids)
                };
                // The clean close republishes the committed state without the recovery mark:
                // its txn id is the one readers open from now on.
                let txn_id = container.close()?;
                Ok(Committed {
                    txn_id,
                    files,
                    blocks,
                    grids,
                })
            }
            Target::Dataset(dir) => {
                let Some((col, row, patch)) = merged(&dir, self.patches)? else {
                    return Ok(Committed {
                        txn_id: crate::dataset::Dataset::open(&dir)?.txn_id(),
                        files: 0,
                        blocks: 0,
                        grids: 0,
                    });
                };
                let r = crate::dataset::replace(&Dir(dir), col, row, &patch)?;
                Ok(Committed {
                    txn_id: r.txn_id,
                    files: r.tiles.len() as u64,
                    blocks: r.tiles.iter().map(|t| t.summary.blocks).sum(),
                    grids: r.tiles.iter().map(|t| t.summary.grids).sum(),
                })
            }
        }
    }
}

/// A dataset commits one rectangle at a time: several patches become one, the rectangle
/// that bounds them, holding the dataset's own samples where no patch lies (so those stay as
/// they are) and each patch's over them, in order. `None` for no patch.
fn merged(
    dir: &std::path::Path,
    patches: Vec<(u64, u64, Heightfield)>,
) -> Result<Option<(u64, u64, Heightfield)>> {
    let mut patches = patches.into_iter();
    let Some(first) = patches.next() else {
        return Ok(None);
    };
    let rest: Vec<_> = patches.collect();
    if rest.is_empty() {
        return Ok(Some(first));
    }
    let all: Vec<&(u64, u64, Heightfield)> = std::iter::once(&first).chain(&rest).collect();
    let bounds = all
        .iter()
        .map(|(c, r, p)| SampleRect {
            col0: *c,
            row0: *r,
            col1: c + u64::from(p.width()) - 1,
            row1: r + u64::from(p.height()) - 1,
        })
        .reduce(|a, b| SampleRect {
            col0: a.col0.min(b.col0),
            row0: a.row0.min(b.row0),
            col1: a.col1.max(b.col1),
            row1: a.row1.max(b.row1),
        })
        .ok_or_else(|| Error::Internal("no patch bounds".into()))?;
    let base = crate::dataset::Dataset::open(dir)?.read_window(bounds)?;
    let (w, h) = (base.width(), base.height());
    let mut samples = base.into_samples();
    for (col, row, patch) in all {
        let (dx, dy) = ((col - bounds.col0) as usize, (row - bounds.row0) as usize);
        for (j, line) in patch
            .samples()
            .chunks_exact(patch.width() as usize)
            .enumerate()
        {
            let at = (dy + j) * w as usize + dx;
            samples[at..at + line.len()].copy_from_slice(line);
        }
    }
    Ok(Some((
        bounds.col0,
        bounds.row0,
        Heightfield::new(w, h, samples)?,
    )))
}
