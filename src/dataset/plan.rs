//! The phases of a dataset build as separate steps (`docs/datasets-design.md` §1), so that
//! one process can run them all ([`super::build`]) or many machines can share them
//! (`python/fmrh/dask.py`): each step takes and gives values that travel (a [`TileScan`] as
//! bytes), and no step needs another's memory.
//!
//! 1. [`TileScan::of`] a tile: its size, georeference, datum and four border lines.
//! 2. [`plan`] from the scans' descriptions: every tile's place, file name and shared edges,
//!    the tiling checked. Only sizes and georeferences are needed, never the samples.
//! 3. [`settled_edge`] of each shared edge, from the two tiles' scans under the seam policy
//!    (any machine holding both scans computes the same samples), and [`build_tile`] of
//!    each tile with its settled edges, into a container file.
//! 4. [`assemble`]: the adjacent-cluster tables from the built tiles' edge lists, and the
//!    manifest that publishes them, written last.

use std::collections::HashSet;
use std::path::{Path, PathBuf};
use std::sync::Arc;

use super::adjacency::{tables_of, TileEdges};
use super::manifest::{write_state, Contents};
use super::placement::{check_tiling, place_by_georeference, rect, PlacementError};
use super::seams::{settle, Placed, SeamPolicy};
use crate::error::{Error, Result};
use crate::format::manifest::{
    tile_name_is_valid, TileRecord, SEAM_FIRST, SEAM_MEAN, SEAM_STRICT, TILE_NAME_LEN,
};
use crate::format::page_size_for;
use crate::geoid::VerticalDatum;
use crate::heightfield::{Georeference, Heightfield};
use crate::ingest::IngestOptions;
use crate::model::{BuildOptions, Model, SampleRect};
use crate::progress::Progress;
use crate::store::io::FileIo;
use crate::store::{write_file, AnySource, Store, WriteOptions};

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
    /// Cut every input wider or taller than this many samples into windows of at most this
    /// many a side, each a tile (neighbours share an edge row or column). `None`: only an
    /// input too large for the memory budget is cut, into tiles of `tile_side_for` (`build.rs`) samples.
    pub tile_size: Option<u32>,
}

/// The record of a tile file `name` at `rect`, whose container is `store`: pinned at its
/// state, with its root's height range.
pub(super) fn record_of<S: crate::store::Source>(
    store: &Store<S>,
    name: &str,
    rect: SampleRect,
) -> Result<TileRecord> {
    let root = store.node(0)?;
    Ok(TileRecord::new(
        name,
        rect,
        store.pin(),
        (root.min_height, root.max_height),
    ))
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

/// What a build keeps of a tile after reading it once: its size, where it lies, what its
/// heights are above, and its four border lines.
#[derive(Clone, Debug, PartialEq)]
pub struct TileScan {
    /// Samples along a row.
    pub width: u32,
    /// Rows.
    pub height: u32,
    /// Where its sample (0, 0) lies, if it says.
    pub georeference: Option<Georeference>,
    /// Metres between its samples, if it says.
    pub spacing_m: Option<[f64; 2]>,
    /// What its heights are above.
    pub vertical_datum: VerticalDatum,
    /// North row, south row, west column, east column.
    borders: [Vec<f32>; 4],
}

/// The first bytes of [`TileScan::to_bytes`].
const SCAN_MAGIC: &[u8; 8] = b"FMRHSCN1";

impl TileScan {
    /// The scan of a tile's samples.
    pub fn of(hf: &Heightfield) -> TileScan {
        let (w, h) = (hf.width() as usize, hf.height() as usize);
        let s = hf.samples();
        TileScan {
            width: hf.width(),
            height: hf.height(),
            georeference: hf.metadata.georeference.clone(),
            spacing_m: hf.metadata.spacing_m,
            vertical_datum: hf.metadata.vertical_datum,
            borders: [
                s[..w].to_vec(),
                s[(h - 1) * w..].to_vec(),
                (0..h).map(|y| s[y * w]).collect(),
                (0..h).map(|y| s[y * w + w - 1]).collect(),
            ],
        }
    }

    /// The scan without its border lines: what planning needs (sizes, places, datums), a
    /// few hundred bytes whatever the tile's size. It cannot settle an edge.
    pub fn description(&self) -> TileScan {
        TileScan {
            borders: Default::default(),
            ..self.clone()
        }
    }

    /// Whether it holds its border lines (it is not a [`TileScan::description`]).
    pub fn has_borders(&self) -> bool {
        !self.borders[0].is_empty()
    }

    /// The sample at tile `(x, y)`, which lies on a border.
    pub(super) fn border(&self, x: u64, y: u64) -> Option<f32> {
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

    /// The scan as bytes, to send to another process: `FMRHSCN1`, the description as JSON
    /// (its length first, u32 LE), then the four border lines as f32 LE, each after its
    /// length (u32 LE). Voids (NaN) travel bit for bit.
    pub fn to_bytes(&self) -> Vec<u8> {
        let head = serde_json::json!({
            "width": self.width,
            "height": self.height,
            "georeference": self.georeference,
            "spacing_m": self.spacing_m,
            "vertical_datum": self.vertical_datum.name(),
        })
        .to_string();
        let mut out = Vec::with_capacity(16 + head.len() + 4 * 2 * (self.width + self.height) as usize);
        out.extend_from_slice(SCAN_MAGIC);
        out.extend_from_slice(&(head.len() as u32).to_le_bytes());
        out.extend_from_slice(head.as_bytes());
        for b in &self.borders {
            out.extend_from_slice(&(b.len() as u32).to_le_bytes());
            for v in b {
                out.extend_from_slice(&v.to_le_bytes());
            }
        }
        out
    }

    /// A scan (or a description) from [`TileScan::to_bytes`]; anything else is an invalid
    /// argument.
    pub fn from_bytes(bytes: &[u8]) -> Result<TileScan> {
        let bad = |why: &str| Error::InvalidArgument(format!("not a tile scan: {why}"));
        let mut rest = bytes
            .strip_prefix(SCAN_MAGIC.as_slice())
            .ok_or_else(|| bad("no FMRHSCN1 mark"))?;
        let mut take = |n: usize| -> Result<&[u8]> {
            if rest.len() < n {
                return Err(bad("cut short"));
            }
            let (a, b) = rest.split_at(n);
            rest = b;
            Ok(a)
        };
        let len = |b: &[u8]| u32::from_le_bytes([b[0], b[1], b[2], b[3]]) as usize;
        let n = len(take(4)?);
        let head: serde_json::Value =
            serde_json::from_slice(take(n)?).map_err(|e| bad(&e.to_string()))?;
        let dim = |k: &str| {
            head[k]
                .as_u64()
                .and_then(|v| u32::try_from(v).ok())
                .filter(|v| *v > 0)
                .ok_or_else(|| bad(k))
        };
        let (width, height) = (dim("width")?, dim("height")?);
        let georeference = match &head["georeference"] {
            serde_json::Value::Null => None,
            g => {
                let pair = |k: &str| -> Result<[f64; 2]> {
                    let a = g[k].as_array().ok_or_else(|| bad(k))?;
                    match a.as_slice() {
                        [x, y] => Ok([
                            x.as_f64().ok_or_else(|| bad(k))?,
                            y.as_f64().ok_or_else(|| bad(k))?,
                        ]),
                        _ => Err(bad(k)),
                    }
                };
                Some(Georeference {
                    crs: g["crs"].as_str().map(str::to_string),
                    origin: pair("origin")?,
                    step: pair("step")?,
                })
            }
        };
        let spacing_m = match &head["spacing_m"] {
            serde_json::Value::Null => None,
            serde_json::Value::Array(a) if a.len() == 2 => Some([
                a[0].as_f64().ok_or_else(|| bad("spacing_m"))?,
                a[1].as_f64().ok_or_else(|| bad("spacing_m"))?,
            ]),
            _ => return Err(bad("spacing_m")),
        };
        let vertical_datum = head["vertical_datum"]
            .as_str()
            .ok_or_else(|| bad("vertical_datum"))
            .and_then(|d| VerticalDatum::parse(d).map_err(|e| bad(&e)))?;
        let mut borders: [Vec<f32>; 4] = Default::default();
        let mut described = false;
        for (i, b) in borders.iter_mut().enumerate() {
            let n = len(take(4)?);
            let want = if i < 2 { width } else { height } as usize;
            // A description has all four lines empty; a scan none.
            if i == 0 {
                described = n == 0;
            }
            if n != if described { 0 } else { want } {
                return Err(bad("a border line of the wrong length"));
            }
            *b = take(4 * n)?
                .chunks_exact(4)
                .map(|c| f32::from_le_bytes([c[0], c[1], c[2], c[3]]))
                .collect();
        }
        if !rest.is_empty() {
            return Err(bad("bytes after the last border"));
        }
        Ok(TileScan {
            width,
            height,
            georeference,
            spacing_m,
            vertical_datum,
            borders,
        })
    }
}

/// One tile as [`plan`] takes it.
#[derive(Clone, Debug)]
pub struct PlanTile<'a> {
    /// How errors name it (its input's path, and a window's place in it).
    pub name: String,
    /// Its input.
    pub input: &'a Path,
    /// The name its file is made from (an input's path; a window's made-up one).
    pub file_hint: PathBuf,
    /// Its first sample in the dataset's grid, from a layout (`None`: by its georeference).
    pub at: Option<(u64, u64)>,
    /// Its scan.
    pub scan: &'a TileScan,
}

/// Where every tile of a dataset goes (made by `plan`; the door's `plan_dataset`).
#[derive(Clone, Debug, PartialEq)]
pub struct Plan {
    /// How errors name each tile (its input), in input order.
    pub names: Vec<String>,
    /// Each tile's file name in the dataset, in input order.
    pub files: Vec<String>,
    /// Each tile's samples in the dataset's grid.
    pub rects: Vec<SampleRect>,
    /// The pairs of tiles `(a, b)`, `a < b`, that share an edge, and the edge.
    pub shared: Vec<(usize, usize, SampleRect)>,
    /// Metres between samples: the option given, else the first tile's that says.
    pub spacing_m: Option<[f64; 2]>,
    /// The georeference of dataset sample (0, 0), from the first tile that has one.
    pub georeference: Option<Georeference>,
    /// What every tile's heights are above.
    pub vertical_datum: VerticalDatum,
    /// How shared edges are settled.
    pub seam: SeamPolicy,
}

/// The error for a placement that fails, naming tiles by their inputs.
fn placement_error(e: PlacementError, names: &[&str]) -> Error {
    let name = |i: usize| names.get(i).copied().unwrap_or("?");
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

/// An error unless the tile scanned as `this` has its heights above the datum of the
/// `first` tile's.
pub fn same_datum(first: (&Path, &TileScan), this: (&Path, &TileScan)) -> Result<()> {
    if first.1.vertical_datum == this.1.vertical_datum {
        return Ok(());
    }
    Err(Error::input(
        this.0,
        format!(
            "its heights are above {}, {}'s above {}: a dataset's tiles share one vertical \
             datum (--vertical-datum says which, for every input)",
            this.1.vertical_datum.name(),
            first.0.display(),
            first.1.vertical_datum.name()
        ),
    ))
}

/// Places `tiles` (all by a layout, or all by their georeferences), checks that they tile
/// (neighbours share at most an edge row or column) and share one vertical datum, and names
/// their files (none of `taken`, which holds names in lower case).
pub fn plan(
    tiles: &[PlanTile<'_>],
    spacing_m: Option<[f64; 2]>,
    seam: SeamPolicy,
    taken: &HashSet<String>,
) -> Result<Plan> {
    if tiles.is_empty() {
        return Err(Error::InvalidArgument(
            "a dataset needs at least one tile".into(),
        ));
    }
    let names: Vec<&str> = tiles.iter().map(|t| t.name.as_str()).collect();
    let first = &tiles[0];
    for t in tiles {
        same_datum((first.input, first.scan), (t.input, t.scan))?;
    }
    let by_layout = tiles.iter().filter(|t| t.at.is_some()).count();
    let offsets: Vec<(u64, u64)> = if by_layout == tiles.len() {
        tiles.iter().filter_map(|t| t.at).collect()
    } else if by_layout != 0 {
        return Err(Error::InvalidArgument(
            "either every tile has a layout position or none has (placed by georeference)".into(),
        ));
    } else {
        let mut geo = Vec::with_capacity(tiles.len());
        for t in tiles {
            let Some(g) = t.scan.georeference.clone() else {
                return Err(Error::InvalidArgument(format!(
                    "tile {} has no georeference: place the tiles with a layout (path,col0,row0)",
                    t.name
                )));
            };
            geo.push((g, t.scan.width, t.scan.height));
        }
        place_by_georeference(&geo).map_err(|e| placement_error(e, &names))?
    };
    let rects: Vec<SampleRect> = offsets
        .iter()
        .zip(tiles)
        .map(|(&(c, r), t)| rect(c, r, t.scan.width, t.scan.height))
        .collect();
    for (r, t) in rects.iter().zip(tiles) {
        if r.col1 >= 1 << 40 || r.row1 >= 1 << 40 {
            return Err(Error::InvalidArgument(format!(
                "tile {} at column {}, row {}: a dataset grid is at most 2^40 samples a side",
                t.name, r.col0, r.row0
            )));
        }
    }
    let shared = check_tiling(&rects).map_err(|e| placement_error(e, &names))?;
    let mut taken = taken.clone();
    let files = tiles
        .iter()
        .map(|t| {
            let name = tile_name(&t.file_hint, &taken);
            taken.insert(name.to_ascii_lowercase());
            name
        })
        .collect();
    let georeference = tiles.iter().zip(&rects).find_map(|(t, r)| {
        t.scan.georeference.as_ref().map(|g| Georeference {
            crs: g.crs.clone(),
            origin: [
                g.origin[0] - r.col0 as f64 * g.step[0],
                g.origin[1] - r.row0 as f64 * g.step[1],
            ],
            step: g.step,
        })
    });
    Ok(Plan {
        names: tiles.iter().map(|t| t.name.clone()).collect(),
        files,
        rects,
        shared,
        spacing_m: spacing_m.or_else(|| tiles.iter().find_map(|t| t.scan.spacing_m)),
        georeference,
        vertical_datum: first.scan.vertical_datum,
        seam,
    })
}

/// The samples of shared edge `shared` between tiles `a` and `b` (`a < b`) of `plan` under
/// its seam policy, from their scans; a strict disagreement is an error naming both tiles
/// and the first differing sample. Any process holding both scans computes the
/// same samples.
pub fn settled_edge(
    plan: &Plan,
    (a, b, o): (usize, usize, SampleRect),
    scans: (&TileScan, &TileScan),
) -> Result<Vec<f32>> {
    let rects = &plan.rects;
    let names = (plan.names[a].as_str(), plan.names[b].as_str());
    let field = |t: usize, scan: &TileScan| -> Result<Heightfield> {
        let (w, h) = (o.col1 - o.col0 + 1, o.row1 - o.row0 + 1);
        let mut v = Vec::with_capacity((w * h) as usize);
        for row in o.row0..=o.row1 {
            for col in o.col0..=o.col1 {
                let s = scan.border(col - rects[t].col0, row - rects[t].row0);
                v.push(s.ok_or_else(|| {
                    Error::InvalidArgument(format!(
                        "tiles {} and {} overlap along a line inside {}: neighbours may share \
                         only an edge row or column of both",
                        names.0,
                        names.1,
                        if t == a { names.0 } else { names.1 }
                    ))
                })?);
            }
        }
        Heightfield::new(w as u32, h as u32, v)
    };
    let (fa, fb) = (field(a, scans.0)?, field(b, scans.1)?);
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
    settle(pa, pb, &o, plan.seam).map_err(|d| {
        Error::InvalidArgument(format!(
            "tiles {} and {} disagree on their shared edge: at dataset column {}, row {} ({} \
             column {}, row {}) one holds {} and the other {}. Give --seam first or --seam \
             mean to settle shared edges (format-spec/dataset.md §1)",
            names.0,
            names.1,
            d.col,
            d.row,
            names.1,
            d.col - rects[b].col0,
            d.row - rects[b].row0,
            d.a,
            d.b
        ))
    })
}

/// A tile built by `build_tile` (the door's `build_planned_tile`).
#[derive(Clone, Debug, PartialEq)]
pub struct TileFile {
    /// Its container's bytes.
    pub file_length: u64,
    /// Samples of its shared edges that the seam policy changed.
    pub seam_samples_changed: u64,
}

/// Builds tile `index` of `plan` from its samples `hf` (as its scan saw them) into the
/// container `path`: its shared edges set to `settled` (each edge's rectangle and samples,
/// [`settled_edge`]), `options.spacing_m` recorded if given, its model built
/// (`options.build`) and written (`options.write`).
pub fn build_tile(
    plan: &Plan,
    index: usize,
    hf: Heightfield,
    settled: &[(SampleRect, &[f32])],
    options: &DatasetOptions,
    path: &Path,
    progress: &dyn Progress,
) -> Result<TileFile> {
    let r = plan.rects[index];
    let (w, h) = (hf.width(), hf.height());
    if u64::from(w) != r.col1 - r.col0 + 1 || u64::from(h) != r.row1 - r.row0 + 1 {
        return Err(Error::InvalidArgument(format!(
            "tile {index}: {w} x {h} samples, where the plan places {} x {}: it changed since \
             it was scanned",
            r.col1 - r.col0 + 1,
            r.row1 - r.row0 + 1
        )));
    }
    let mut metadata = hf.metadata.clone();
    if let Some(s) = options.spacing_m {
        metadata.spacing_m = Some(s);
    }
    let mut samples = hf.into_samples();
    let mut changed = 0u64;
    for (o, v) in settled {
        let mut k = 0;
        for row in o.row0..=o.row1 {
            for col in o.col0..=o.col1 {
                let at = ((row - r.row0) * u64::from(w) + (col - r.col0)) as usize;
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
    let mut write = options.write.clone();
    if write.page_size == 0 {
        write.page_size = page_size_for(u64::from(w) * u64::from(h));
    }
    let summary = write_file(&model, &metadata, path, &write, false)?;
    Ok(TileFile {
        file_length: summary.file_length,
        seam_samples_changed: changed,
    })
}

fn seam_byte(p: SeamPolicy) -> u8 {
    match p {
        SeamPolicy::Strict => SEAM_STRICT,
        SeamPolicy::First => SEAM_FIRST,
        SeamPolicy::Mean => SEAM_MEAN,
    }
}

/// What `assemble` (the door's `publish_dataset`) published.
#[derive(Clone, Debug, PartialEq)]
pub struct Published {
    /// Bytes of the manifest.
    pub manifest_bytes: u64,
    /// The manifest's state: 1 for a new dataset.
    pub txn_id: u64,
    /// The files the dataset named before and names no more (a rebuild's): no reader that
    /// opens from now on reads them.
    pub superseded: Vec<String>,
}

/// Publishes the tiles of `plan`, built into the files `plan.files` under `tiles` (a
/// directory, or a URL ending in `/`): each opened and pinned at its state, the
/// adjacent-cluster tables computed from their edge lists and their neighbours', and the
/// manifest written: a new file at `manifest` (which must not exist), or with `replace` the
/// next state of the existing manifest there, committed as any dataset commit is (the file
/// locked, the body then the record synced: readers see the old dataset or the new).
pub fn assemble(plan: &Plan, tiles: &Path, manifest: &Path, replace: bool) -> Result<Published> {
    let open = |name: &str| -> Result<Store<AnySource>> {
        let location = match tiles.to_str() {
            Some(base) if crate::store::is_url(base) => {
                PathBuf::from(format!("{}/{name}", base.trim_end_matches('/')))
            }
            _ => tiles.join(name),
        };
        Store::from_source(AnySource::open(&location)?)
    };
    let mut records: Vec<TileRecord> = Vec::with_capacity(plan.files.len());
    let mut cache: std::collections::HashMap<usize, Arc<TileEdges>> = Default::default();
    for (k, name) in plan.files.iter().enumerate() {
        let store = open(name)?;
        let record = record_of(&store, name, plan.rects[k])?;
        cache.insert(k, Arc::new(TileEdges::read(&store, &record)?));
        records.push(record);
    }
    let mut edges = |k: usize| -> Result<Arc<TileEdges>> {
        cache
            .get(&k)
            .cloned()
            .ok_or_else(|| Error::InvalidArgument(format!("tile {k} of the plan is not built")))
    };
    let mut adjacency = std::collections::HashMap::new();
    for (k, record) in records.iter().enumerate() {
        let blob = tables_of(k, &plan.rects, &mut edges)?;
        if !blob.is_empty() {
            adjacency.insert(record.name().to_string(), blob);
        }
    }
    let new_names: HashSet<&str> = plan.files.iter().map(String::as_str).collect();
    let contents = Contents {
        tiles: records,
        spacing_m: plan.spacing_m,
        georeference: plan.georeference.clone(),
        seam: seam_byte(plan.seam),
        vertical_datum: Some(plan.vertical_datum),
        adjacency,
    };
    let (record, superseded) = if replace {
        let io = Arc::new(FileIo::open(manifest).map_err(|e| Error::io(manifest, e))?);
        let (state, src) = super::commit::read_manifest(&io)?;
        let old = super::commit::records(&state, &src)?;
        let (_, record) = write_state(&*io, Some((state.slot, &state.record)), &contents)?;
        let superseded = old
            .iter()
            .map(|t| t.name().to_string())
            .filter(|n| !new_names.contains(n.as_str()))
            .collect();
        (record, superseded)
    } else {
        std::fs::OpenOptions::new()
            .write(true)
            .create_new(true)
            .open(manifest)
            .map_err(|e| Error::io(manifest, e))?;
        let io = FileIo::open(manifest).map_err(|e| Error::io(manifest, e))?;
        (write_state(&io, None, &contents)?.1, Vec::new())
    };
    Ok(Published {
        manifest_bytes: std::fs::metadata(manifest)
            .map_err(|e| Error::io(manifest, e))?
            .len(),
        txn_id: record.txn_id.get(),
        superseded,
    })
}

impl Plan {
    /// The plan as JSON text, to send to the processes that build its tiles.
    pub fn to_json(&self) -> String {
        let rect = |r: &SampleRect| [r.col0, r.row0, r.col1, r.row1];
        serde_json::json!({
            "names": self.names,
            "files": self.files,
            "rects": self.rects.iter().map(rect).collect::<Vec<_>>(),
            "shared": self.shared.iter().map(|(a, b, o)| (a, b, rect(o))).collect::<Vec<_>>(),
            "spacing_m": self.spacing_m,
            "georeference": self.georeference,
            "vertical_datum": self.vertical_datum.name(),
            "seam": match self.seam {
                SeamPolicy::Strict => "strict",
                SeamPolicy::First => "first",
                SeamPolicy::Mean => "mean",
            },
        })
        .to_string()
    }

    /// A plan from [`Plan::to_json`]'s text; anything else is an invalid argument.
    pub fn from_json(text: &str) -> Result<Plan> {
        let bad = |why: &str| Error::InvalidArgument(format!("not a dataset plan: {why}"));
        let v: serde_json::Value = serde_json::from_str(text).map_err(|e| bad(&e.to_string()))?;
        let strings = |k: &str| -> Result<Vec<String>> {
            v[k].as_array()
                .ok_or_else(|| bad(k))?
                .iter()
                .map(|s| s.as_str().map(str::to_string).ok_or_else(|| bad(k)))
                .collect()
        };
        let rect = |r: &serde_json::Value| -> Result<SampleRect> {
            let n: Vec<u64> = r
                .as_array()
                .ok_or_else(|| bad("rect"))?
                .iter()
                .map(|x| x.as_u64().ok_or_else(|| bad("rect")))
                .collect::<Result<_>>()?;
            match n.as_slice() {
                [c0, r0, c1, r1] if c0 <= c1 && r0 <= r1 => Ok(SampleRect {
                    col0: *c0,
                    row0: *r0,
                    col1: *c1,
                    row1: *r1,
                }),
                _ => Err(bad("rect")),
            }
        };
        let (names, files) = (strings("names")?, strings("files")?);
        let rects: Vec<SampleRect> = v["rects"]
            .as_array()
            .ok_or_else(|| bad("rects"))?
            .iter()
            .map(rect)
            .collect::<Result<_>>()?;
        if names.len() != files.len() || rects.len() != files.len() {
            return Err(bad("names, files and rects differ in number"));
        }
        let n = files.len();
        let shared = v["shared"]
            .as_array()
            .ok_or_else(|| bad("shared"))?
            .iter()
            .map(|e| {
                let index = |i: usize| {
                    e[i].as_u64()
                        .map(|x| x as usize)
                        .filter(|x| *x < n)
                        .ok_or_else(|| bad("shared"))
                };
                Ok((index(0)?, index(1)?, rect(&e[2])?))
            })
            .collect::<Result<_>>()?;
        let pair = |x: &serde_json::Value, k: &str| -> Result<[f64; 2]> {
            match x.as_array().map(Vec::as_slice) {
                Some([a, b]) => Ok([
                    a.as_f64().ok_or_else(|| bad(k))?,
                    b.as_f64().ok_or_else(|| bad(k))?,
                ]),
                _ => Err(bad(k)),
            }
        };
        let spacing_m = match &v["spacing_m"] {
            serde_json::Value::Null => None,
            x => Some(pair(x, "spacing_m")?),
        };
        let georeference = match &v["georeference"] {
            serde_json::Value::Null => None,
            g => Some(Georeference {
                crs: g["crs"].as_str().map(str::to_string),
                origin: pair(&g["origin"], "origin")?,
                step: pair(&g["step"], "step")?,
            }),
        };
        let vertical_datum = v["vertical_datum"]
            .as_str()
            .ok_or_else(|| bad("vertical_datum"))
            .and_then(|d| VerticalDatum::parse(d).map_err(|e| bad(&e)))?;
        let seam = v["seam"]
            .as_str()
            .ok_or_else(|| bad("seam"))?
            .parse()
            .map_err(|e: String| bad(&e))?;
        Ok(Plan {
            names,
            files,
            rects,
            shared,
            spacing_m,
            georeference,
            vertical_datum,
            seam,
        })
    }
}
