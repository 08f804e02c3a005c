//! Building a dataset from tile DEMs, streaming (`docs/datasets-design.md` §1). Memory is
//! bounded by one tile plus the border rows and columns of all of them, never the dataset:
//!
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

use super::adjacency::{tables_of, TileEdges};
use super::manifest::{write_state, Contents, MANIFEST_NAME};
use super::placement::{check_tiling, place_by_georeference, rect, PlacementError};
use super::seams::{settle, Placed, SeamPolicy};
use crate::error::{Error, Result};
use crate::format::manifest::{
    tile_name_is_valid, TileRecord, SEAM_FIRST, SEAM_MEAN, SEAM_STRICT, TILE_NAME_LEN,
};
use crate::format::page_size_for;
use crate::heightfield::{Georeference, Heightfield};
use crate::ingest::{self, IngestOptions};
use crate::model::{BuildOptions, Model, SampleRect};
use crate::progress::Progress;
use crate::store::io::FileIo;
use crate::store::{write_file, Store, WriteOptions};

/// One input tile: its DEM, and where it goes (`None`: by its georeference).
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct TileInput {
    /// The DEM.
    pub path: PathBuf,
    /// Its first column and row in dataset samples, from a layout.
    pub at: Option<(u64, u64)>,
}

/// How to build a dataset.
#[derive(Clone, Debug)]
pub struct DatasetOptions {
    /// How to read each tile.
    pub ingest: IngestOptions,
    /// How to build each tile's model.
    pub build: BuildOptions,
    /// How to write each tile (a page size of 0 picks one per tile, as `fmrh build` does).
    pub write: WriteOptions,
    /// How shared edges are settled.
    pub seam: SeamPolicy,
    /// Metres between samples, overriding what the tiles say.
    pub spacing_m: Option<[f64; 2]>,
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

/// What the scan keeps of a tile.
struct Scanned {
    width: u32,
    height: u32,
    georeference: Option<Georeference>,
    /// North row, south row, west column, east column.
    borders: [Vec<f32>; 4],
}

impl Scanned {
    fn of(hf: &Heightfield) -> Scanned {
        let (w, h) = (hf.width() as usize, hf.height() as usize);
        let s = hf.samples();
        Scanned {
            width: hf.width(),
            height: hf.height(),
            georeference: hf.metadata.georeference.clone(),
            borders: [
                s[..w].to_vec(),
                s[(h - 1) * w..].to_vec(),
                (0..h).map(|y| s[y * w]).collect(),
                (0..h).map(|y| s[y * w + w - 1]).collect(),
            ],
        }
    }

    /// The sample at tile `(x, y)`, which lies on a border.
    fn border(&self, x: u64, y: u64) -> Option<f32> {
        let (w, h) = (u64::from(self.width), u64::from(self.height));
        let at = |v: &Vec<f32>, i: u64| v.get(usize::try_from(i).ok()?).copied();
        if y == 0 {
            at(&self.borders[0], x)
        } else if y == h - 1 {
            at(&self.borders[1], x)
        } else if x == 0 {
            at(&self.borders[2], y)
        } else if x == w - 1 {
            at(&self.borders[3], y)
        } else {
            None
        }
    }
}

/// A tile file name from an input's name: its stem's letters, digits, `.`, `_` and `-`
/// (others become `_`), at most 43 bytes, then `.fmrh`; `-2`, `-3`, ... when taken (`taken`
/// holds the names in use, in lower case).
pub fn tile_name(input: &Path, taken: &std::collections::HashSet<String>) -> String {
    let file = input.file_name().and_then(|n| n.to_str()).unwrap_or("tile");
    let stem = file
        .trim_end_matches(".gz")
        .rsplit_once('.')
        .map_or(file, |(s, _)| s);
    let mut clean: String = stem
        .chars()
        .map(|c| {
            if c.is_ascii_alphanumeric() || "_-".contains(c) {
                c
            } else {
                '_'
            }
        })
        .collect();
    if clean.is_empty() || clean.starts_with('.') {
        clean.insert_str(0, "tile");
    }
    clean.truncate(TILE_NAME_LEN - ".fmrh".len() - 8);
    let mut name = format!("{clean}.fmrh");
    let mut n = 2;
    // Unique without case, so the dataset means the same on a case-insensitive file system.
    while taken.contains(&name.to_ascii_lowercase()) {
        name = format!("{clean}-{n}.fmrh");
        n += 1;
    }
    debug_assert!(tile_name_is_valid(&name));
    name
}

fn seam_byte(p: SeamPolicy) -> u8 {
    match p {
        SeamPolicy::Strict => SEAM_STRICT,
        SeamPolicy::First => SEAM_FIRST,
        SeamPolicy::Mean => SEAM_MEAN,
    }
}

/// The error for a placement that fails, naming tiles by their inputs.
fn placement_error(e: PlacementError, inputs: &[TileInput]) -> Error {
    let name = |i: usize| {
        inputs
            .get(i)
            .map_or("?".into(), |t| t.path.display().to_string())
    };
    Error::InvalidArgument(match e {
        PlacementError::Overlap {
            a,
            b,
            col0,
            row0,
            cols,
            rows,
        } => format!(
            "tiles {} and {} overlap in {cols} x {rows} samples from dataset column {col0}, row \
             {row0}: neighbours may share one edge row or column, no more",
            name(a),
            name(b)
        ),
        PlacementError::Georeference { tile, detail } => format!("tile {}: {detail}", name(tile)),
        PlacementError::Layout { line, detail } => format!("layout line {line}: {detail}"),
    })
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
    // 1. Scan.
    let n = inputs.len();
    let mut scans = Vec::with_capacity(n);
    for (i, t) in inputs.iter().enumerate() {
        on_tile("scanning", i, n, &t.path);
        let hf = ingest::load(&t.path, &options.ingest)?;
        scans.push(Scanned::of(&hf));
    }
    // 2. Place.
    let offsets: Vec<(u64, u64)> = if by_layout == n {
        inputs.iter().filter_map(|t| t.at).collect()
    } else {
        let mut geo = Vec::with_capacity(n);
        for (i, s) in scans.iter().enumerate() {
            let Some(g) = s.georeference.clone() else {
                return Err(Error::InvalidArgument(format!(
                    "tile {} has no georeference: place the tiles with a layout (path,col0,row0)",
                    inputs[i].path.display()
                )));
            };
            geo.push((g, s.width, s.height));
        }
        place_by_georeference(&geo).map_err(|e| placement_error(e, inputs))?
    };
    let rects: Vec<SampleRect> = offsets
        .iter()
        .zip(&scans)
        .map(|(&(c, r), s)| rect(c, r, s.width, s.height))
        .collect();
    for (i, r) in rects.iter().enumerate() {
        if r.col1 >= 1 << 40 || r.row1 >= 1 << 40 {
            return Err(Error::InvalidArgument(format!(
                "tile {} at column {}, row {}: a dataset grid is at most 2^40 samples a side",
                inputs[i].path.display(),
                r.col0,
                r.row0
            )));
        }
    }
    let shared = check_tiling(&rects).map_err(|e| placement_error(e, inputs))?;
    let mut settled: Vec<(usize, usize, SampleRect, Vec<f32>)> = Vec::with_capacity(shared.len());
    for &(a, b, o) in &shared {
        let field = |t: usize| -> Result<Heightfield> {
            let (w, h) = (o.col1 - o.col0 + 1, o.row1 - o.row0 + 1);
            let mut v = Vec::with_capacity((w * h) as usize);
            for row in o.row0..=o.row1 {
                for col in o.col0..=o.col1 {
                    let s = scans[t].border(col - rects[t].col0, row - rects[t].row0);
                    v.push(s.ok_or_else(|| {
                        Error::InvalidArgument(format!(
                            "tiles {} and {} overlap along a line inside {}: neighbours may \
                             share only an edge row or column of both",
                            inputs[a].path.display(),
                            inputs[b].path.display(),
                            inputs[t].path.display()
                        ))
                    })?);
                }
            }
            Heightfield::new(w as u32, h as u32, v)
        };
        let (fa, fb) = (field(a)?, field(b)?);
        let pa = Placed {
            field: &fa,
            col0: o.col0,
            row0: o.row0,
        };
        let pb = Placed {
            field: &fb,
            col0: o.col0,
            row0: o.row0,
        };
        match settle(pa, pb, &o, options.seam) {
            Ok(v) => settled.push((a, b, o, v)),
            Err(d) => {
                return Err(Error::InvalidArgument(format!(
                    "tiles {} and {} disagree on their shared edge: at dataset column {}, row {} \
                     ({} column {}, row {}) one holds {} and the other {}. Give --seam first or \
                     --seam mean to settle shared edges (format-spec/dataset.md §1)",
                    inputs[a].path.display(),
                    inputs[b].path.display(),
                    d.col,
                    d.row,
                    inputs[b].path.display(),
                    d.col - rects[b].col0,
                    d.row - rects[b].row0,
                    d.a,
                    d.b
                )))
            }
        }
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
    let mut taken = std::collections::HashSet::new();
    let mut records = Vec::with_capacity(n);
    let mut built = Vec::with_capacity(n);
    let mut spacing = options.spacing_m;
    let mut georeference = None;
    for (i, t) in inputs.iter().enumerate() {
        on_tile("building", i, n, &t.path);
        let hf = ingest::load(&t.path, &options.ingest)?;
        if hf.width() != scans[i].width || hf.height() != scans[i].height {
            return Err(Error::input(&t.path, "changed while the dataset was built"));
        }
        let mut metadata = hf.metadata.clone();
        if let Some(s) = options.spacing_m {
            metadata.spacing_m = Some(s);
        }
        spacing = spacing.or(metadata.spacing_m);
        if georeference.is_none() {
            georeference = metadata.georeference.as_ref().map(|g| Georeference {
                crs: g.crs.clone(),
                origin: [
                    g.origin[0] - rects[i].col0 as f64 * g.step[0],
                    g.origin[1] - rects[i].row0 as f64 * g.step[1],
                ],
                step: g.step,
            });
        }
        let (w, h) = (hf.width(), hf.height());
        let mut samples = hf.into_samples();
        let mut changed = 0u64;
        for (a, b, o, v) in &settled {
            if *a != i && *b != i {
                continue;
            }
            let mut k = 0;
            for row in o.row0..=o.row1 {
                for col in o.col0..=o.col1 {
                    let at =
                        ((row - rects[i].row0) * u64::from(w) + (col - rects[i].col0)) as usize;
                    if samples[at].to_bits() != v[k].to_bits()
                        && !(samples[at].is_nan() && v[k].is_nan())
                    {
                        samples[at] = v[k];
                        changed += 1;
                    }
                    k += 1;
                }
            }
        }
        let hf = Heightfield::new(w, h, samples)?.with_metadata(metadata.clone());
        let model = Model::build_with_progress(hf, &options.build, progress)?;
        let name = tile_name(&t.path, &taken);
        taken.insert(name.to_ascii_lowercase());
        let path = tmp.path().join(&name);
        let mut write = options.write.clone();
        if write.page_size == 0 {
            write.page_size = page_size_for(u64::from(w) * u64::from(h));
        }
        let summary = write_file(&model, &metadata, &path, &write, false)?;
        drop(model);
        let store = Store::open(&path)?;
        let root = store.node(0)?;
        records.push(TileRecord::new(
            &name,
            rects[i],
            store.pin(),
            (root.min_height, root.max_height),
        ));
        built.push(BuiltTile {
            input: t.path.display().to_string(),
            name,
            rect: rects[i],
            file_length: summary.file_length,
            seam_samples_changed: changed,
        });
    }
    // 4. The adjacent-cluster tables, from each tile's edge lists and its east and south
    // neighbours'.
    on_tile("stitching", 0, n, &inputs[0].path);
    let mut cache: std::collections::HashMap<usize, std::sync::Arc<TileEdges>> =
        std::collections::HashMap::new();
    let mut edges = |k: usize| -> Result<std::sync::Arc<TileEdges>> {
        if let Some(e) = cache.get(&k) {
            return Ok(e.clone());
        }
        let store = Store::open(&tmp.path().join(records[k].name()))?;
        let e = std::sync::Arc::new(TileEdges::read(&store, &records[k])?);
        cache.insert(k, e.clone());
        Ok(e)
    };
    let mut adjacency = std::collections::HashMap::new();
    for (k, record) in records.iter().enumerate() {
        let blob = tables_of(k, &rects, &mut edges)?;
        if !blob.is_empty() {
            adjacency.insert(record.name().to_string(), blob);
        }
    }
    // 5. Publish.
    let manifest = tmp.path().join(MANIFEST_NAME);
    std::fs::File::create(&manifest).map_err(|e| Error::io(&manifest, e))?;
    {
        let io = FileIo::open(&manifest).map_err(|e| Error::io(&manifest, e))?;
        write_state(
            &io,
            None,
            &Contents {
                tiles: records,
                spacing_m: spacing,
                georeference,
                seam: seam_byte(options.seam),
                adjacency,
            },
        )?;
    }
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
    let columns = rects.iter().map(|r| r.col1 + 1).max().unwrap_or(0);
    let rows = rects.iter().map(|r| r.row1 + 1).max().unwrap_or(0);
    let total_bytes = manifest_bytes + built.iter().map(|t| t.file_length).sum::<u64>();
    Ok(DatasetSummary {
        tiles: built,
        columns,
        rows,
        shared_edges: shared.len(),
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
