//! Building a dataset from tile DEMs, streaming (`docs/datasets-design.md` §1). Memory is
//! bounded by one tile plus the border rows and columns of all of them, never the dataset:
//!
//! 0. **Cut:** an input larger than the memory budget (a GeoTIFF or `.f32` of any size up to
//!    2^32 - 1 samples a side), or larger than `--tile-size`, becomes a grid of windows read
//!    by [`WindowedRaster`], each a tile: so a raster larger than the machine is built in
//!    the memory of one window.
//! 1. **Scan:** each tile is read once for its size, georeference and four border lines; its
//!    samples are dropped.
//! 2. **Place:** by the layout, or by the georeferences; the tiling is checked (neighbours
//!    share at most an edge row or column), and every shared edge is settled from the border
//!    lines under the seam policy. A strict disagreement stops the build here, before
//!    anything is written, naming both tiles and the first differing sample.
//! 3. **Build:** each tile is read again, its shared edges set to the settled samples, built
//!    into a container in a temporary directory, and pinned at its first state.
//! 4. **Stitch:** each tile's adjacent-cluster tables with its east and south neighbours
//!    are computed from their edge lists ([`super::adjacency`]).
//! 5. **Publish:** the manifest is written and synced, and the temporary directory renamed to
//!    the dataset's name: the dataset appears complete or not at all.

use std::path::{Path, PathBuf};

use serde::Serialize;

use super::manifest::MANIFEST_NAME;
use super::plan::{
    assemble, build_tile, plan, same_datum, settled_edge, DatasetOptions, PlanTile, TileScan,
};
use crate::error::{Error, Result};
use crate::heightfield::{check_dimensions, Heightfield};
use crate::ingest::limits::BUILD_BYTES_PER_SAMPLE;
use crate::ingest::{self, IngestOptions, WindowedRaster};
use crate::model::SampleRect;
use crate::progress::Progress;

/// One input tile: its DEM, and where it goes (`None`: by its georeference).
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct TileInput {
    /// The DEM.
    pub path: PathBuf,
    /// Its first column and row in dataset samples, from a layout.
    pub at: Option<(u64, u64)>,
}

/// One tile built.
#[derive(Clone, Debug, Serialize)]
pub struct BuiltTile {
    /// Its input.
    pub input: String,
    /// Its file in the dataset.
    pub name: String,
    /// Its samples in dataset coordinates.
    pub rect: SampleRect,
    /// Its container's bytes.
    pub file_length: u64,
    /// Samples of its shared edges that the seam policy changed.
    pub seam_samples_changed: u64,
}

/// What a build produced.
#[derive(Clone, Debug, Serialize)]
pub struct DatasetSummary {
    /// The tiles, in input order.
    pub tiles: Vec<BuiltTile>,
    /// Columns of the dataset grid.
    pub columns: u64,
    /// Rows.
    pub rows: u64,
    /// Shared edges (pairs of tiles that overlap by a row or column).
    pub shared_edges: usize,
    /// Bytes of the manifest.
    pub manifest_bytes: u64,
    /// Bytes of every file of the dataset.
    pub total_bytes: u64,
}

/// The side of the square tiles an input too large for a memory budget of `budget` bytes is
/// cut into: the largest `2^k + 1` (`k` from 13 down to 6: 8,193 to 65 samples) whose build
/// fits the budget, since a build takes about [`BUILD_BYTES_PER_SAMPLE`] bytes a sample.
/// 8,193² samples build in about 400 MB; larger tiles only make each tile slower to edit and
/// to serve.
pub fn tile_side_for(budget: u64) -> u32 {
    (6..=13)
        .rev()
        .map(|k| (1u64 << k) + 1)
        .find(|side| side * side * BUILD_BYTES_PER_SAMPLE <= budget)
        .unwrap_or(65) as u32
}

/// The inclusive `(first, last)` spans that cut `n` samples into the fewest windows of at most
/// `side` samples, as even as they can be, each sharing its last sample with the next
/// window's first.
pub fn window_spans(n: u64, side: u64) -> Vec<(u64, u64)> {
    let side = side.max(2);
    if n <= side {
        return vec![(0, n.saturating_sub(1))];
    }
    let count = (n - 1).div_ceil(side - 1);
    (0..count)
        .map(|i| ((n - 1) * i / count, (n - 1) * (i + 1) / count))
        .collect()
}

/// What becomes one tile: an input whole, or a window of one.
struct Piece {
    /// Its input.
    input: usize,
    /// Its samples in the input's (north-up) samples; `None`: the whole input.
    window: Option<SampleRect>,
    /// How errors and the report name it.
    name: String,
    /// The name its tile file is made from.
    file_hint: PathBuf,
}

/// Reads the pieces' samples, keeping the last windowed input open: the pieces of one
/// input come one after another, so each pass reads its header once, not once a window.
struct Reader<'a> {
    inputs: &'a [TileInput],
    options: &'a IngestOptions,
    open: Option<(usize, WindowedRaster)>,
}

impl Reader<'_> {
    fn load(&mut self, piece: &Piece) -> Result<Heightfield> {
        let path = &self.inputs[piece.input].path;
        let Some(window) = piece.window else {
            return ingest::load(path, self.options);
        };
        let raster = match &mut self.open {
            Some((i, raster)) if *i == piece.input => raster,
            open => &mut open
                .insert((piece.input, WindowedRaster::open(path, self.options)?))
                .1,
        };
        raster.read(window)
    }
}

/// Cuts the inputs into pieces: an input is cut into windows when it is larger than
/// `tile_size`, or, without one, when its build would not fit the memory budget (or fmrh's
/// limits on one grid). Only a GeoTIFF or `.f32` can be cut; any other input is one piece,
/// read whole under the budget.
fn cut(inputs: &[TileInput], options: &DatasetOptions) -> Result<Vec<Piece>> {
    if options.tile_size.is_some_and(|s| s < 2) {
        return Err(Error::InvalidArgument(
            "--tile-size must be at least 2 samples: neighbouring tiles share an edge".into(),
        ));
    }
    let budget = options.ingest.limits.budget();
    let mut pieces = Vec::with_capacity(inputs.len());
    for (i, t) in inputs.iter().enumerate() {
        let whole = Piece {
            input: i,
            window: None,
            name: t.path.display().to_string(),
            file_hint: t.path.clone(),
        };
        let format = match options.ingest.format {
            Some(f) => f,
            None => ingest::detect(&t.path)?,
        };
        if !ingest::window::streams(format) {
            pieces.push(whole);
            continue;
        }
        let raster = WindowedRaster::open(&t.path, &options.ingest)?;
        let (w, h) = (raster.width(), raster.height());
        let too_big = check_dimensions(w, h).is_err() || !options.ingest.limits.holds(w * h);
        let side = match options.tile_size {
            Some(s) => u64::from(s),
            None if too_big => u64::from(tile_side_for(budget)),
            None => {
                pieces.push(whole);
                continue;
            }
        };
        if w <= side && h <= side {
            pieces.push(whole);
            continue;
        }
        let stem = t
            .path
            .file_stem()
            .map_or("tile".into(), |s| s.to_string_lossy().into_owned());
        let (columns, rows) = (window_spans(w, side), window_spans(h, side));
        for (r, &(row0, row1)) in rows.iter().enumerate() {
            for (c, &(col0, col1)) in columns.iter().enumerate() {
                pieces.push(Piece {
                    input: i,
                    window: Some(SampleRect {
                        col0,
                        row0,
                        col1,
                        row1,
                    }),
                    name: format!(
                        "{} (columns {col0}..={col1}, rows {row0}..={row1})",
                        t.path.display()
                    ),
                    file_hint: PathBuf::from(format!("{stem}_{r}_{c}.tile")),
                });
            }
        }
    }
    Ok(pieces)
}

/// A piece as [`plan`] takes it.
fn plan_tile<'a>(inputs: &'a [TileInput], p: &Piece, scan: &'a TileScan) -> PlanTile<'a> {
    PlanTile {
        name: p.name.clone(),
        input: &inputs[p.input].path,
        file_hint: p.file_hint.clone(),
        at: inputs[p.input].at.map(|(c, r)| {
            let w = p.window.unwrap_or_default();
            (c + w.col0, r + w.row0)
        }),
        scan,
    }
}

/// Builds the dataset of `inputs` into the directory `out`, which must not exist. `on_tile`
/// hears each phase's tile: `(phase, index, count, input)`.
pub fn build(
    inputs: &[TileInput],
    out: &Path,
    options: &DatasetOptions,
    progress: &dyn Progress,
    on_tile: &mut dyn FnMut(&str, usize, usize, &Path),
) -> Result<DatasetSummary> {
    if inputs.is_empty() {
        return Err(Error::InvalidArgument(
            "a dataset needs at least one tile".into(),
        ));
    }
    if out.exists() {
        return Err(Error::InvalidArgument(format!(
            "{} exists: a dataset is built into a new directory",
            out.display()
        )));
    }
    let by_layout = inputs.iter().filter(|t| t.at.is_some()).count();
    if by_layout != 0 && by_layout != inputs.len() {
        return Err(Error::InvalidArgument(
            "either every tile has a layout position or none has (placed by georeference)".into(),
        ));
    }
    // 0. Cut.
    let pieces = cut(inputs, options)?;
    // 1. Scan.
    let n = pieces.len();
    let mut scans = Vec::with_capacity(n);
    let mut reader = Reader {
        inputs,
        options: &options.ingest,
        open: None,
    };
    for (i, p) in pieces.iter().enumerate() {
        on_tile("scanning", i, n, &inputs[p.input].path);
        let hf = reader.load(p)?;
        let scan = TileScan::of(&hf);
        // A datum that differs stops the scan at the tile that has it.
        if let Some(first) = scans.first() {
            let first_input: &Path = &inputs[pieces[0].input].path;
            same_datum((first_input, first), (&inputs[p.input].path, &scan))?;
        }
        scans.push(scan);
    }
    // 2. Place, and settle every shared edge before anything is written.
    let tiles: Vec<PlanTile<'_>> = pieces
        .iter()
        .zip(&scans)
        .map(|(p, s)| plan_tile(inputs, p, s))
        .collect();
    let plan = plan(&tiles, options.spacing_m, options.seam, &Default::default())?;
    let mut settled: Vec<(usize, usize, SampleRect, Vec<f32>)> =
        Vec::with_capacity(plan.shared.len());
    for &(a, b, o) in &plan.shared {
        let v = settled_edge(&plan, (a, b, o), (&scans[a], &scans[b]))?;
        settled.push((a, b, o, v));
    }
    // 3. Build, in a temporary directory beside `out`.
    let parent = match out.parent() {
        Some(p) if !p.as_os_str().is_empty() => p.to_path_buf(),
        _ => PathBuf::from("."),
    };
    let tmp = tempfile::Builder::new()
        .prefix(".fmrh-dataset-")
        .tempdir_in(&parent)
        .map_err(|e| Error::io(&parent, e))?;
    let mut built = Vec::with_capacity(n);
    for (i, p) in pieces.iter().enumerate() {
        let input = &inputs[p.input].path;
        on_tile("building", i, n, input);
        let hf = reader.load(p)?;
        if hf.width() != scans[i].width || hf.height() != scans[i].height {
            return Err(Error::input(input, "changed while the dataset was built"));
        }
        let edges: Vec<(SampleRect, &[f32])> = settled
            .iter()
            .filter(|(a, b, _, _)| *a == i || *b == i)
            .map(|(_, _, o, v)| (*o, v.as_slice()))
            .collect();
        let name = &plan.files[i];
        let file = build_tile(
            &plan,
            i,
            hf,
            &edges,
            options,
            &tmp.path().join(name),
            progress,
        )?;
        built.push(BuiltTile {
            input: p.name.clone(),
            name: name.clone(),
            rect: plan.rects[i],
            file_length: file.file_length,
            seam_samples_changed: file.seam_samples_changed,
        });
    }
    // 4. Stitch and 5. publish.
    on_tile("stitching", 0, n, &inputs[0].path);
    let manifest = tmp.path().join(MANIFEST_NAME);
    assemble(&plan, tmp.path(), &manifest, false)?;
    let manifest_bytes = std::fs::metadata(&manifest)
        .map_err(|e| Error::io(&manifest, e))?
        .len();
    sync_dir(tmp.path())?;
    let kept = tmp.keep();
    if let Err(e) = std::fs::rename(&kept, out) {
        let _ = std::fs::remove_dir_all(&kept);
        return Err(Error::io(out, e));
    }
    sync_dir(&parent)?;
    let columns = plan.rects.iter().map(|r| r.col1 + 1).max().unwrap_or(0);
    let rows = plan.rects.iter().map(|r| r.row1 + 1).max().unwrap_or(0);
    let total_bytes = manifest_bytes + built.iter().map(|t| t.file_length).sum::<u64>();
    Ok(DatasetSummary {
        tiles: built,
        columns,
        rows,
        shared_edges: plan.shared.len(),
        manifest_bytes,
        total_bytes,
    })
}

/// Makes the entries of `dir` durable (Unix; elsewhere a rename is as durable as it gets).
pub(crate) fn sync_dir(dir: &Path) -> Result<()> {
    #[cfg(unix)]
    {
        std::fs::File::open(dir)
            .and_then(|d| d.sync_all())
            .map_err(|e| Error::io(dir, e))?;
    }
    let _ = dir;
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;

    #[test]
    fn tile_sides_fit_the_budget() {
        assert_eq!(tile_side_for(u64::MAX), 8193);
        assert_eq!(tile_side_for(48 << 20), 2049);
        assert_eq!(tile_side_for(64 << 20), 2049);
        assert_eq!(tile_side_for(256 << 20), 4097);
        // Below 65² samples' build the side stays 65: a window reader refuses what the
        // budget cannot hold, with the figures.
        assert_eq!(tile_side_for(1), 65);
        for k in 6..=13u32 {
            let side = u64::from(tile_side_for((((1u64 << k) + 1).pow(2)) * 6));
            assert_eq!(side, (1 << k) + 1);
        }
    }

    #[test]
    fn window_spans_of_small_and_exact_sizes() {
        assert_eq!(window_spans(1, 65), vec![(0, 0)]);
        assert_eq!(window_spans(65, 65), vec![(0, 64)]);
        assert_eq!(window_spans(66, 65), vec![(0, 32), (32, 65)]);
        assert_eq!(window_spans(129, 65), vec![(0, 64), (64, 128)]);
        assert_eq!(window_spans(10, 4), vec![(0, 3), (3, 6), (6, 9)]);
    }

    proptest! {
        /// The spans cover `0..n` in order, each at most `side` long, neighbours sharing one
        /// sample, and no fewer could do it.
        #[test]
        fn window_spans_cover_share_and_are_fewest(n in 1u64..100_000, side in 2u64..10_000) {
            let spans = window_spans(n, side);
            prop_assert_eq!(spans[0].0, 0);
            prop_assert_eq!(spans[spans.len() - 1].1, n - 1);
            for s in &spans {
                prop_assert!(s.0 <= s.1 && s.1 - s.0 < side);
                prop_assert!(spans.len() == 1 || s.1 > s.0);
            }
            for p in spans.windows(2) {
                prop_assert_eq!(p[0].1, p[1].0);
            }
            // k windows of `side` samples sharing edges cover at most k·(side-1)+1.
            let fewer = spans.len() as u64 - 1;
            prop_assert!(fewer == 0 || fewer * (side - 1) + 1 < n);
        }
    }
}
