//! Building one dataset on many machines through the door: [`build_dataset`](super::build_dataset)'s
//! phases as separate calls whose inputs and outputs travel between processes (a scan as
//! bytes, the plan as JSON), for a scheduler such as Dask (`python/fmrh/dask.py`) to run:
//!
//! 1. [`scan_tile`] each DEM, anywhere (a worker): its size, georeference and borders.
//! 2. [`plan_dataset`] once, from the scans: where each tile goes, its file name, which
//!    tiles share edges; nothing is read.
//! 3. [`build_planned_tile`] each tile, anywhere, given its own scan and its neighbours':
//!    shared edges settled (every worker settles an edge to the same samples), the
//!    container written to a path the caller then puts at the destination.
//! 4. [`publish_dataset`] once every tile is in: the manifest, written last, is the commit
//!    point. Until then the destination's old dataset (if any) is what readers see.
//!
//! The tiles and manifest equal what [`build_dataset`](super::build_dataset) writes for
//! the same DEMs and options, byte for byte (the scans and plan are the same values).

use std::collections::HashSet;
use std::path::{Path, PathBuf};

use super::DatasetBuildOptions;
use crate::dataset::plan::{self, PlanTile};
pub use crate::dataset::plan::{Plan, Published, TileFile, TileScan};
use crate::dataset::SeamPolicy;
use crate::error::{Error, Result};
use crate::progress::Progress;

/// Reads the DEM `input` once and keeps what planning and settling need ([`TileScan`]).
pub fn scan_tile(input: &Path, options: &DatasetBuildOptions) -> Result<TileScan> {
    Ok(TileScan::of(&crate::ingest::load(input, &options.read)?))
}

/// A DEM to plan: its path, its place from a layout (`None`: by its georeference), its scan.
pub type Planned = (PathBuf, Option<(u64, u64)>, TileScan);

/// Plans the dataset of `tiles` (each a DEM, its place from a layout or `None` for its
/// georeference, and its scan): places them, checks the tiling and the datums, and names
/// their files, none of `taken` (the names a dataset being rebuilt uses now, so that its
/// readers keep their files until the new manifest is published).
pub fn plan_dataset(
    tiles: &[Planned],
    options: &DatasetBuildOptions,
    taken: &[String],
) -> Result<Plan> {
    let taken: HashSet<String> = taken.iter().map(|n| n.to_ascii_lowercase()).collect();
    let plan_tiles: Vec<PlanTile<'_>> = tiles
        .iter()
        .map(|(path, at, scan)| PlanTile {
            name: path.display().to_string(),
            input: path,
            file_hint: path.clone(),
            at: *at,
            scan,
        })
        .collect();
    plan::plan(
        &plan_tiles,
        options.spacing_m,
        options.seam.unwrap_or(SeamPolicy::Strict),
        &taken,
    )
}

/// Builds tile `index` of `plan` from the DEM `input` into the container `out` (which must
/// not exist): its shared edges settled from `scans`, which must hold its own scan and every
/// neighbour's it shares an edge with (by index in the plan).
pub fn build_planned_tile(
    plan: &Plan,
    index: usize,
    input: &Path,
    scans: &[(usize, TileScan)],
    options: &DatasetBuildOptions,
    out: &Path,
    progress: &dyn Progress,
) -> Result<TileFile> {
    if index >= plan.files.len() {
        return Err(Error::InvalidArgument(format!(
            "tile {index}: the plan has {} tiles",
            plan.files.len()
        )));
    }
    let scan = |k: usize| {
        let s = scans
            .iter()
            .find(|(i, _)| *i == k)
            .map(|(_, s)| s)
            .ok_or_else(|| {
                Error::InvalidArgument(format!(
                    "tile {index} shares an edge with tile {k}, whose scan was not given"
                ))
            })?;
        if !s.has_borders() {
            return Err(Error::InvalidArgument(format!(
                "tile {k}'s scan is a description, without the border lines settling needs"
            )));
        }
        Ok(s)
    };
    let mut settled = Vec::new();
    for &(a, b, o) in plan
        .shared
        .iter()
        .filter(|(a, b, _)| *a == index || *b == index)
    {
        settled.push((
            o,
            plan::settled_edge(plan, (a, b, o), (scan(a)?, scan(b)?))?,
        ));
    }
    let hf = crate::ingest::load(input, &options.read)?;
    let own = scan(index)?;
    if hf.width() != own.width || hf.height() != own.height {
        return Err(Error::input(input, "changed while the dataset was built"));
    }
    let edges: Vec<_> = settled.iter().map(|(o, v)| (*o, v.as_slice())).collect();
    let inner = options.inner(plan.seam)?;
    plan::build_tile(plan, index, hf, &edges, &inner, out, progress)
}

/// Publishes `plan`'s tiles, built into its files under `tiles` (a directory, or a URL
/// ending in `/`): the adjacent-cluster tables from their edge lists, then the manifest at
/// `manifest` (a local file): a new one, or with `replace` the next state of a dataset's
/// existing manifest, committed as every dataset commit is. Its `superseded` files are
/// the old state's that the new one no longer names.
pub fn publish_dataset(
    plan: &Plan,
    tiles: &Path,
    manifest: &Path,
    replace: bool,
) -> Result<Published> {
    plan::assemble(plan, tiles, manifest, replace)
}
