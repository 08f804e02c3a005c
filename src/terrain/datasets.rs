//! Making datasets through the door: a directory of tile containers placed by a manifest,
//! built from many DEMs at once ([`build_dataset`]) or grown a tile at a time
//! ([`add_tile`]), every tile made as [`super::create`] makes a container.

use std::path::{Path, PathBuf};

use serde::Serialize;

use super::CreateOptions;
use crate::dataset::{self, DatasetCommit, DatasetOptions, DatasetSummary, SeamPolicy, TileInput};
use crate::error::{Error, Result};
use crate::ingest::IngestOptions;
use crate::model::{BuildOptions, Precision};
use crate::progress::Progress;
use crate::store::WriteOptions;

/// How [`build_dataset`] and [`add_tile`] make a dataset's tiles.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct DatasetBuildOptions {
    /// How each DEM is read.
    pub read: IngestOptions,
    /// How each tile's container is made (`page_size: None` picks one per tile by its size;
    /// `overwrite` is not used: a dataset is built into a new directory).
    pub create: CreateOptions,
    /// How a shared edge whose two tiles disagree is settled (`None` in [`add_tile`]: the
    /// policy the dataset recorded; in [`build_dataset`]: strict).
    pub seam: Option<SeamPolicy>,
    /// Metres between samples east and south, overriding what the DEMs say.
    pub spacing_m: Option<[f64; 2]>,
    /// Cut every DEM wider or taller than this many samples into tiles of at most this many
    /// a side (neighbours share an edge). `None`: only a DEM too large for the memory budget
    /// is cut.
    pub tile_size: Option<u32>,
}

impl DatasetBuildOptions {
    pub(super) fn inner(&self, seam: SeamPolicy) -> Result<DatasetOptions> {
        let c = &self.create;
        Ok(DatasetOptions {
            ingest: self.read.clone(),
            build: BuildOptions {
                block_size: c.block_size,
                thresholds: c.thresholds.clone(),
                precision: c.precision.map(Precision::new).transpose()?,
                thin: c.thin,
            },
            write: WriteOptions {
                // 0: each tile's page size by its size, as `fmrh build` chooses.
                page_size: c.page_size.unwrap_or(0),
                against_parents: !c.payloads_alone,
                ..WriteOptions::default()
            },
            seam,
            spacing_m: self.spacing_m,
            tile_size: self.tile_size,
        })
    }
}

/// What [`add_tile`] did.
#[derive(Clone, Debug, Serialize)]
pub struct TileAdded {
    /// The commit: the manifest's new state and each tile it changed.
    pub commit: DatasetCommit,
    /// How far the grid's origin moved (columns, rows), when the tile lies west or north of
    /// it: every dataset coordinate grew by as much.
    pub shift: (u64, u64),
}

/// Builds the dataset of the DEMs `tiles` into the directory `out`, which must not exist:
/// each tile `(path, None)` placed by its georeference, or every one `(path, Some((col0,
/// row0)))` at its first sample in the dataset's grid (a layout). Shared edges are settled
/// (`options.seam`), each tile's container built and written, the adjacent-cluster tables
/// computed, and the manifest published last: `out` appears complete or not at all.
/// `progress` hears each tile's phases; `on_tile` hears `(phase, index, count, input)`.
pub fn build_dataset(
    tiles: &[(PathBuf, Option<(u64, u64)>)],
    out: &Path,
    options: &DatasetBuildOptions,
    progress: &dyn Progress,
    on_tile: &mut dyn FnMut(&str, usize, usize, &Path),
) -> Result<DatasetSummary> {
    let inputs: Vec<TileInput> = tiles
        .iter()
        .map(|(path, at)| TileInput {
            path: path.clone(),
            at: *at,
        })
        .collect();
    let inner = options.inner(options.seam.unwrap_or(SeamPolicy::Strict))?;
    dataset::build(&inputs, out, &inner, progress, on_tile)
}

/// Adds the DEM `input` to the dataset in `dir` as a new tile (at `at` in the dataset's
/// grid, or by its georeference), or (`replace`) replaces the tile of its place and size
/// with it, in one manifest commit: readers see the old dataset or the new, never a mix.
pub fn add_tile(
    dir: &Path,
    input: &Path,
    at: Option<(u64, u64)>,
    replace: bool,
    options: &DatasetBuildOptions,
    progress: &dyn Progress,
) -> Result<TileAdded> {
    if options.tile_size.is_some() {
        return Err(Error::InvalidArgument(
            "tile_size cuts DEMs when a dataset is built; a tile is added whole".into(),
        ));
    }
    let seam = match options.seam {
        Some(s) => s,
        None => dataset::add::recorded_policy(&dataset::Dataset::open(dir)?),
    };
    let inner = options.inner(seam)?;
    let (commit, _, shift) = if replace {
        dataset::replace_tile(dir, input, at, &inner, progress)?
    } else {
        dataset::add(dir, input, at, &inner, progress)?
    };
    Ok(TileAdded { commit, shift })
}
