//! Adding a tile to a dataset (seed 000 §4.3, *expansion*; `format-spec/dataset.md` §4). The
//! new tile is placed (`--at`, or by its georeference against the dataset's), checked
//! against the tiling, and its shared edges settled with its neighbours under the
//! dataset's seam policy: strict refuses a disagreement, `first` keeps the neighbours'
//! samples (they were there first), `mean` changes both sides, so the neighbours are
//! committed too. The new tile's container is written complete under a name no tile uses,
//! then one manifest commit adds it: a crash before that leaves a stray file the dataset
//! does not name, which the validator lists and the next add steps around.

use std::path::Path;
use std::sync::Arc;

use super::build::sync_dir;
use super::plan::{record_of, tile_name, DatasetOptions};
use super::commit::{commit_tiles, publish, read_manifest, records, DatasetCommit, Dir, Files};
use super::manifest::MANIFEST_NAME;
use super::placement::{check_tiling, rect};
use super::reader::{Dataset, Tile};
use super::seams::{settle, Placed, SeamPolicy};
use crate::error::{Error, Result};
use crate::format::manifest::{TileRecord, SEAM_FIRST, SEAM_MEAN};
use crate::format::page_size_for;
use crate::heightfield::{Georeference, Heightfield};
use crate::model::{Model, SampleRect};
use crate::progress::Progress;
use crate::store::{write_file, Store};

/// How far from a whole step a georeferenced offset may lie (in steps).
const STEP_TOLERANCE: f64 = 1e-6;

/// Where a tile with georeference `g` lies in a dataset whose sample (0, 0) is at `d`, in
/// samples (negative: west or north of the dataset's grid).
fn place(g: &Georeference, d: &Georeference, tile: &Path) -> Result<(i64, i64)> {
    let bad = |detail: String| Error::InvalidArgument(format!("{}: {detail}", tile.display()));
    if g.crs != d.crs {
        return Err(bad(format!(
            "CRS {:?}, where the dataset has {:?}",
            g.crs, d.crs
        )));
    }
    let mut at = [0i64; 2];
    for (a, at) in at.iter_mut().enumerate() {
        if (g.step[a] - d.step[a]).abs() > STEP_TOLERANCE * d.step[a].abs() {
            return Err(bad(format!(
                "step {:?}, where the dataset has {:?}",
                g.step, d.step
            )));
        }
        let steps = (g.origin[a] - d.origin[a]) / d.step[a];
        let whole = steps.round();
        if !steps.is_finite() || (steps - whole).abs() > STEP_TOLERANCE * whole.abs().max(1.0) {
            return Err(bad(format!(
                "origin {:?} is {steps} steps from the dataset's along axis {a}, not a whole number",
                g.origin
            )));
        }
        if whole.abs() > (1u64 << 40) as f64 {
            return Err(bad(format!("{whole} samples from the dataset's grid")));
        }
        *at = whole as i64;
    }
    Ok((at[0], at[1]))
}

/// Adds the tile DEM `input` to the dataset in `dir`, at `at` or by its georeference; its
/// shared edges are settled under `options.seam` (the caller passes the dataset's own policy
/// unless told otherwise). Returns the commit, the new tile's record, and how far the grid's
/// origin moved (columns, rows) when the tile lies west or north of it: every dataset
/// coordinate then grows by as much.
pub fn add(
    dir: &Path,
    input: &Path,
    at: Option<(u64, u64)>,
    options: &DatasetOptions,
    progress: &dyn Progress,
) -> Result<(DatasetCommit, TileRecord, (u64, u64))> {
    add_or_replace(dir, input, at, options, progress, false)
}

/// Replaces the tile at the place and size of the DEM `input` (at `at`, or by its
/// georeference) with a new file built from it: a whole tile, in one dataset commit. Its
/// shared edges are settled with its neighbours as [`add`] does. The old file is removed
/// once the manifest no longer names it; a reader that opened the dataset before and opens
/// that tile after is told its state was superseded.
pub fn replace_tile(
    dir: &Path,
    input: &Path,
    at: Option<(u64, u64)>,
    options: &DatasetOptions,
    progress: &dyn Progress,
) -> Result<(DatasetCommit, TileRecord, (u64, u64))> {
    add_or_replace(dir, input, at, options, progress, true)
}

fn add_or_replace(
    dir: &Path,
    input: &Path,
    at: Option<(u64, u64)>,
    options: &DatasetOptions,
    progress: &dyn Progress,
    replace: bool,
) -> Result<(DatasetCommit, TileRecord, (u64, u64))> {
    let files = Dir(dir.to_path_buf());
    let manifest = Arc::new(files.open(MANIFEST_NAME)?);
    let (state, src) = read_manifest(&manifest)?;
    let all = records(&state, &src)?;
    let reader = Dataset::open(dir)?;
    let hf = crate::ingest::load(input, &options.ingest)?;
    if !all.is_empty() {
        let (ours, theirs) = (hf.metadata.vertical_datum, reader.vertical_datum()?);
        if ours != theirs {
            return Err(Error::input(
                input,
                format!(
                    "its heights are above {}, the dataset's above {}: a dataset's tiles \
                     share one vertical datum (--vertical-datum says what this file's are)",
                    ours.name(),
                    theirs.name()
                ),
            ));
        }
    }
    let (col0, row0) = match at {
        Some((c, r)) => (c as i64, r as i64),
        None => match (&hf.metadata.georeference, state.georeference()) {
            (Some(g), Some(d)) => place(g, &d, input)?,
            _ => {
                return Err(Error::InvalidArgument(format!(
                    "{}: give --at COL0,ROW0 (the tile or the dataset has no georeference)",
                    input.display()
                )))
            }
        },
    };
    // A tile west or north of the grid moves the grid's origin to it: every other tile's
    // dataset coordinates grow by as much (tile files hold no dataset coordinates).
    let shift = (col0.min(0).unsigned_abs(), row0.min(0).unsigned_abs());
    let (col0, row0) = (
        (col0 + shift.0 as i64) as u64,
        (row0 + shift.1 as i64) as u64,
    );
    let all: Vec<TileRecord> = all
        .iter()
        .map(|t| {
            let mut t = *t;
            t.col0 = (t.col0.get() + shift.0).into();
            t.row0 = (t.row0.get() + shift.1).into();
            t
        })
        .collect();
    let new_rect = rect(col0, row0, hf.width(), hf.height());
    // Replacing: the tile of the same place and size leaves the dataset in this commit.
    let (all, replaced): (Vec<TileRecord>, Option<TileRecord>) = if replace {
        let Some(at) = all.iter().position(|t| t.rect() == new_rect) else {
            return Err(Error::InvalidArgument(format!(
                "{}: no tile lies at columns {}..={}, rows {}..={} to replace (a replacement \
                 has the place and size of the tile it replaces)",
                input.display(),
                new_rect.col0,
                new_rect.col1,
                new_rect.row0,
                new_rect.row1
            )));
        };
        let mut rest = all;
        let old = rest.remove(at);
        (rest, Some(old))
    } else {
        (all, None)
    };
    let mut rects: Vec<SampleRect> = all.iter().map(TileRecord::rect).collect();
    rects.push(new_rect);
    let n = all.len();
    let shared = check_tiling(&rects).map_err(|e| {
        let name = |i: usize| {
            if i == n {
                input.display().to_string()
            } else {
                all[i].name().to_string()
            }
        };
        Error::InvalidArgument(match e {
            super::placement::PlacementError::Overlap {
                a,
                b,
                col0,
                row0,
                cols,
                rows,
            } => format!(
                "tiles {} and {} would overlap in {cols} x {rows} samples from dataset column \
                 {col0}, row {row0}: neighbours may share one edge row or column, no more",
                name(a),
                name(b)
            ),
            other => other.to_string(),
        })
    })?;
    // Settle every shared edge of the new tile with the tile there before it.
    let (w, h) = (hf.width(), hf.height());
    let mut samples = hf.samples().to_vec();
    let metadata = hf.metadata.clone();
    let mut neighbour_changes: Vec<super::commit::TilePatches> = Vec::new();
    for &(a, b, o) in shared.iter().filter(|(_, b, _)| *b == n) {
        debug_assert_eq!(b, n);
        let old = Tile {
            index: a as u64,
            record: all[a],
        };
        let store = reader.open_tile(&old)?;
        let r = old.rect();
        let local = SampleRect {
            col0: o.col0 - r.col0,
            row0: o.row0 - r.row0,
            col1: o.col1 - r.col0,
            row1: o.row1 - r.row0,
        };
        let theirs = store.read_window(local)?;
        let ow = (o.col1 - o.col0 + 1) as u32;
        let oh = (o.row1 - o.row0 + 1) as u32;
        let mine = Heightfield::from_fn(ow, oh, |x, y| {
            samples[((o.row0 - row0 + u64::from(y)) * u64::from(w) + o.col0 - col0 + u64::from(x))
                as usize]
        })?;
        let settled = settle(
            Placed {
                field: &theirs,
                col0: o.col0,
                row0: o.row0,
            },
            Placed {
                field: &mine,
                col0: o.col0,
                row0: o.row0,
            },
            &o,
            options.seam,
        )
        .map_err(|d| {
            Error::InvalidArgument(format!(
                "{} and tile {} disagree on their shared edge: at dataset column {}, row {} the \
                 tile holds {} and the new one {}. Give --seam first or --seam mean",
                input.display(),
                old.name(),
                d.col,
                d.row,
                d.a,
                d.b
            ))
        })?;
        let mut k = 0;
        for row in o.row0..=o.row1 {
            for col in o.col0..=o.col1 {
                samples[((row - row0) * u64::from(w) + col - col0) as usize] = settled[k];
                k += 1;
            }
        }
        if options.seam == SeamPolicy::Mean {
            let part = Heightfield::new(ow, oh, settled)?;
            if crate::dataset::seams::first_difference(
                Placed {
                    field: &theirs,
                    col0: 0,
                    row0: 0,
                },
                Placed {
                    field: &part,
                    col0: 0,
                    row0: 0,
                },
                &SampleRect {
                    col0: 0,
                    row0: 0,
                    col1: u64::from(ow) - 1,
                    row1: u64::from(oh) - 1,
                },
            )
            .is_some()
            {
                neighbour_changes.push((a, vec![(part, local.col0, local.row0)]));
            }
        }
    }
    // The new tile's container, complete and synced, under a name no file uses.
    let hf = Heightfield::new(w, h, samples)?.with_metadata(metadata.clone());
    let model = Model::build_with_progress(hf, &options.build, progress)?;
    let mut taken: std::collections::HashSet<String> = std::fs::read_dir(dir)
        .map_err(|e| Error::io(dir, e))?
        .filter_map(|e| e.ok())
        .filter_map(|e| e.file_name().to_str().map(str::to_ascii_lowercase))
        .collect();
    taken.extend(all.iter().map(|t| t.name().to_ascii_lowercase()));
    let name = tile_name(input, &taken);
    let path = dir.join(&name);
    let mut write = options.write.clone();
    if write.page_size == 0 {
        write.page_size = page_size_for(u64::from(w) * u64::from(h));
    }
    write_file(&model, &metadata, &path, &write, false)?;
    drop(model);
    let record = record_of(&Store::open(&path)?, &name, new_rect)?;
    sync_dir(dir)?;
    let outcome = (|| {
        let (open, commits, mut updated) = commit_tiles(&files, &all, &neighbour_changes)?;
        updated.push(record);
        let georeference = state.georeference().map(|g| Georeference {
            origin: [
                g.origin[0] - shift.0 as f64 * g.step[0],
                g.origin[1] - shift.1 as f64 * g.step[1],
            ],
            ..g
        });
        let new_index = updated.len() - 1;
        let store = Store::open(&path)?;
        let edges = std::sync::Arc::new(super::adjacency::TileEdges::read(&store, &record)?);
        publish::<Dir>(
            &files,
            &manifest,
            &state,
            &src,
            updated,
            georeference,
            open,
            commits,
            [(new_index, edges)].into_iter().collect(),
        )
    })();
    match outcome {
        Ok(c) => {
            // No state the manifest now holds names the replaced file (the slot of the state
            // before still does, until the next commit: readers of it are told "superseded").
            if let Some(old) = replaced {
                let _ = std::fs::remove_file(dir.join(old.name()));
                let _ = sync_dir(dir);
            }
            Ok((c, record, shift))
        }
        Err(e) => {
            // Not named by any manifest state: nothing refers to it.
            let _ = std::fs::remove_file(&path);
            Err(e)
        }
    }
}

/// The seam policy a dataset recorded.
pub fn recorded_policy(dataset: &Dataset) -> SeamPolicy {
    match dataset.state().record.seam {
        SEAM_FIRST => SeamPolicy::First,
        SEAM_MEAN => SeamPolicy::Mean,
        _ => SeamPolicy::Strict,
    }
}
