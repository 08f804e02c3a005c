//! A terrain as a live Cesium tileset: the global-geodetic pyramid (`super::geodetic`)
//! over a container or dataset, each tile cut on request as an error-bounded TIN
//! (`super::tin_tile`) from the blocks of the coarsest error level its budget allows
//! (`Terrain::cut`), its `layer.json`, and which tiles exist.
//!
//! **Levels and budgets.** Cesium refines a level-`z` tile when its geometric error,
//! `geometric_error(z)` (77 km at level 0, halved each level), seen from the camera, passes
//! its screen-space error. A tile here spends half of that on the blocks it is cut from
//! (the error level within `geometric_error(z) / 2`), and the other half (or
//! `--max-error`, if smaller) on the TIN against its grid. The *data's level* is the first
//! whose 65² grid is as fine as the data's samples: from it down, tiles are cut from the
//! exact blocks (`e* = 0`) with the data level's budget. A grid's lines do not fall on the
//! sample lines, so a grid as fine as the samples still misses a cliff between two of its
//! points (75 m on 3" SRTM at its data level, 12); the deepest level, `maxzoom`, is
//! [`FINER`] levels past it, where grids are 4 times finer than the samples and the
//! largest measured error falls to the budget's size (6 m on that SRTM tile). Every tile
//! reports what it measured.
//!
//! **Which tiles.** Both roots, and at each level from 1 to `maxzoom` the tiles meeting
//! the data's longitude and latitude box: one rectangle of tiles a level, listed in
//! `layer.json`'s `available` and in the roots' `metadata` extension (CesiumJS reads a
//! tile's metadata only in a layer that takes availability from tiles).
//!
//! Nothing here speaks HTTP: the server (`fmrh serve`) asks for a tile's bytes and the
//! layer's JSON.

use serde_json::{json, Value};

use super::geodetic::{self, GeodeticTile};
use super::geodetic_mesh::{level_for_step, Placement};
use super::quantized_mesh;
use super::tin_tile::{self, Edges, Quanta, TinTile};
use crate::error::{Error, Result};
use crate::model::SampleRect;
use crate::scene::surface::{GridBlock, Surface};
use crate::geoid::{Lift, VerticalDatum};
use crate::heightfield::Georeference;

/// The deepest level a tileset goes to, whatever the data (a 65² grid at level 24 is 7 cm
/// a cell at the equator).
pub const MAX_ZOOM: u8 = 24;

/// A terrain's tileset: where it lies, how deep it goes and how its heights quantize.
#[derive(Clone, Debug)]
pub struct Tileset {
    placement: Placement,
    data: SampleRect,
    data_box: [f64; 4],
    quanta: Quanta,
    /// The first level whose 65² grid is as fine as the data's samples.
    data_level: u8,
    maxzoom: u8,
    max_error: Option<f64>,
    datum: VerticalDatum,
}

/// Levels past the data's own: the deepest tiles' grids are `2^FINER` times finer than the
/// data's samples, so that resampling the data onto a grid (whose lines do not fall on
/// sample lines) costs little next to the budget.
pub const FINER: u8 = 2;

/// What a tileset needs of a terrain: where its samples lie, how many, and its heights'
/// range (`Terrain::info`'s).
#[derive(Clone, Debug)]
pub struct DataShape {
    /// The georeference: a tileset needs one that can be placed on the globe.
    pub georeference: Option<Georeference>,
    /// Samples along a row.
    pub width: u64,
    /// Samples down a column.
    pub height: u64,
    /// The lowest and highest real height.
    pub height_range: Option<[f32; 2]>,
}

/// A block a tile is cut from (`Terrain::cut`'s): its footprint, level, grid and `e*`.
#[derive(Clone, Debug)]
pub struct CutBlock {
    /// Inclusive samples.
    pub rect: SampleRect,
    /// Its level in its file's tree.
    pub level: u8,
    /// Samples between grid points.
    pub stride: u64,
    /// Grid points along a row of `heights`.
    pub width: u32,
    /// Rows of `heights`.
    pub height: u32,
    /// The grid, row-major from the north-west corner.
    pub heights: std::sync::Arc<[f32]>,
    /// Its measured error `e*`.
    pub error: f64,
}

impl CutBlock {
    /// The block as the surface reads it.
    pub fn grid(&self) -> GridBlock<'_> {
        GridBlock {
            rect: self.rect,
            stride: self.stride,
            grid_width: self.width,
            grid_height: self.height,
            heights: &self.heights,
            error: self.error,
        }
    }
}

/// The samples of `data` (placed by `placement`) under the longitude and latitude box
/// `b`, widened by two samples (a projected box's edges bow between the points placed);
/// `None` when the box misses `data_box` or cannot be placed.
pub(crate) fn window_in(
    placement: &Placement,
    data: SampleRect,
    data_box: [f64; 4],
    b: [f64; 4],
) -> Option<SampleRect> {
    let [dw0, ds0, de0, dn0] = data_box;
    if b[0] > de0 || b[2] < dw0 || b[1] > dn0 || b[3] < ds0 {
        return None;
    }
    let clip = [b[0].max(dw0), b[1].max(ds0), b[2].min(de0), b[3].min(dn0)];
    let [c0, r0, c1, r1] = placement.span_of(clip)?;
    let lo = |x: f64, max: u64| ((x - 2.0).floor().max(0.0) as u64).min(max);
    let hi = |x: f64, max: u64| ((x + 2.0).ceil().max(0.0) as u64).min(max);
    let rect = SampleRect {
        col0: lo(c0, data.col1),
        row0: lo(r0, data.row1),
        col1: hi(c1, data.col1),
        row1: hi(r1, data.row1),
    };
    (rect.col0 <= rect.col1 && rect.row0 <= rect.row1).then_some(rect)
}

/// The [`Edges`] of tiles already meshed, for one state of one terrain and one tileset:
/// a tile cut after its neighbours takes their edges from here instead of meshing them
/// again. Dropped whole past [`EdgeCache::MAX`] tiles.
#[derive(Debug, Default)]
pub struct EdgeCache {
    map: std::sync::Mutex<std::collections::HashMap<GeodeticTile, Edges>>,
}

impl EdgeCache {
    /// Tiles kept (a few hundred bytes each).
    pub const MAX: usize = 1 << 17;

    fn get(&self, t: GeodeticTile) -> Option<Edges> {
        let map = self.map.lock().unwrap_or_else(|p| p.into_inner());
        map.get(&t).cloned()
    }

    fn put(&self, learnt: Vec<(GeodeticTile, Edges)>) {
        let mut map = self.map.lock().unwrap_or_else(|p| p.into_inner());
        if map.len() + learnt.len() > Self::MAX {
            map.clear();
        }
        map.extend(learnt);
    }
}

impl Tileset {
    /// The tileset of a terrain shaped as `data`; `max_error` caps every level's TIN
    /// budget. An error when the data cannot be placed on the globe.
    pub fn new(data: &DataShape, max_error: Option<f64>, datum: VerticalDatum) -> Result<Tileset> {
        let info = data;
        let georeference = info.georeference.as_ref().ok_or_else(|| {
            Error::InvalidArgument(
                "no georeference: the data cannot be placed on the globe, so it has no \
                 Cesium terrain"
                    .into(),
            )
        })?;
        if let Some(m) = max_error {
            if m.is_nan() || m < 0.0 {
                return Err(Error::InvalidArgument(format!(
                    "--max-error {m}: must be a number of metres >= 0"
                )));
            }
        }
        let lift = datum
            .lift()
            .map_err(|why| Error::InvalidArgument(format!("no Cesium terrain: {why}")))?;
        let placement = Placement::new(georeference, 1.0)?.with_geoid(lift == Lift::Egm96);
        if info.width == 0 || info.height == 0 {
            return Err(Error::InvalidArgument("the terrain has no samples".into()));
        }
        let data = SampleRect {
            col0: 0,
            row0: 0,
            col1: info.width - 1,
            row1: info.height - 1,
        };
        let data_box = placement.box_of(&data).ok_or_else(|| {
            Error::InvalidArgument("the data's corners cannot be placed on the globe".into())
        })?;
        let [w, s, e, n] = data_box;
        // The finer of the data's two steps, in degrees (a box's extent over its samples).
        let step = ((e - w) / info.width.max(2).saturating_sub(1) as f64)
            .min((n - s) / info.height.max(2).saturating_sub(1) as f64);
        let data_level = if step > 0.0 && step.is_finite() {
            level_for_step(step).min(MAX_ZOOM)
        } else {
            0
        };
        let maxzoom = (data_level + FINER).min(MAX_ZOOM);
        let [lo, hi] = info.height_range.unwrap_or([0.0, 0.0]);
        // Heights and sea level off the data, lifted by the geoid where they are (EGM96's
        // undulations lie within -107 m and +86 m).
        let (lift_lo, lift_hi) = if lift == Lift::Egm96 {
            (-110.0, 90.0)
        } else {
            (0.0, 0.0)
        };
        let quanta = Quanta::for_range(
            f64::from(lo).min(0.0) + lift_lo,
            f64::from(hi).max(0.0) + lift_hi,
        );
        Ok(Tileset {
            placement,
            data,
            data_box,
            quanta,
            data_level,
            maxzoom,
            max_error,
            datum,
        })
    }

    /// What the data's heights are above.
    pub fn datum(&self) -> VerticalDatum {
        self.datum
    }

    /// The data's `[west, south, east, north]`, degrees.
    pub fn data_box(&self) -> [f64; 4] {
        self.data_box
    }

    /// The deepest level.
    pub fn maxzoom(&self) -> u8 {
        self.maxzoom
    }

    /// The bound the blocks of a level-`z` tile are cut within: half Cesium's geometric
    /// error, and the exact blocks from the data's own level down.
    pub fn cut_bound(&self, z: u8) -> f64 {
        if z >= self.data_level {
            0.0
        } else {
            geodetic::geometric_error(z) / 2.0
        }
    }

    /// The TIN budget of a level-`z` tile against its grid: half Cesium's geometric error,
    /// no finer than at the data's own level (past it the grids are finer than the
    /// samples: only resampling shrinks), or the cap if smaller.
    pub fn budget(&self, z: u8) -> f64 {
        let half = geodetic::geometric_error(z.min(self.data_level)) / 2.0;
        self.max_error.map_or(half, |m| m.min(half))
    }

    /// The tiles of level `z` that exist, as `(x0, y0, x1, y1)` inclusive; `None` past the
    /// deepest level.
    pub fn available(&self, z: u8) -> Option<(u32, u32, u32, u32)> {
        if z > self.maxzoom {
            return None;
        }
        if z == 0 {
            return Some((0, 0, 1, 0));
        }
        let tiles = geodetic::tiles_meeting(z, self.data_box);
        let first = tiles.first()?;
        let last = tiles.last()?;
        Some((first.x, first.y, last.x, last.y))
    }

    /// Whether tile `t` exists.
    pub fn has(&self, t: GeodeticTile) -> bool {
        self.available(t.z)
            .is_some_and(|(x0, y0, x1, y1)| (x0..=x1).contains(&t.x) && (y0..=y1).contains(&t.y))
    }

    /// The `available` ranges of levels `from..=to`, as Cesium reads them.
    fn ranges(&self, from: u8, to: u8, within: Option<GeodeticTile>) -> Vec<Value> {
        (from..=to)
            .map(|z| {
                let Some((mut x0, mut y0, mut x1, mut y1)) = self.available(z) else {
                    return json!([]);
                };
                if let Some(r) = within {
                    // The root's part of the level: its half of the columns.
                    let shift = z - r.z;
                    let (rx0, rx1) = (r.x << shift, ((r.x + 1) << shift) - 1);
                    x0 = x0.max(rx0);
                    x1 = x1.min(rx1);
                    y0 = y0.max(r.y << shift);
                    y1 = y1.min(((r.y + 1) << shift) - 1);
                    if x0 > x1 || y0 > y1 {
                        return json!([]);
                    }
                }
                json!([{ "startX": x0, "startY": y0, "endX": x1, "endY": y1 }])
            })
            .collect()
    }

    /// The layer's TileJSON, as `CesiumTerrainProvider` reads it; `version` goes into the
    /// tiles' addresses (`?v=`), so that a new state of the data gets new addresses.
    pub fn layer_json(&self, name: &str, version: &str) -> Value {
        let [w, s, e, n] = self.data_box;
        json!({
            "tilejson": "2.1.0",
            "name": name,
            "description": "fmrh: Cesium's global-geodetic pyramid cut live from the store, \
                each tile an error-bounded TIN with its measured error in its metadata",
            "version": version,
            "format": "quantized-mesh-1.0",
            "scheme": "tms",
            "projection": "EPSG:4326",
            "bounds": [w, s, e, n],
            "tiles": ["{z}/{x}/{y}.terrain?v={version}"],
            "minzoom": 0,
            "maxzoom": self.maxzoom,
            "extensions": ["octvertexnormals", "metadata"],
            "available": self.ranges(0, self.maxzoom, None),
            "metadataAvailability": self.maxzoom.max(1),
            "fmrh": {
                "levels": (0..=self.maxzoom).map(|z| json!({
                    "level": z,
                    "cesium_geometric_error_m": geodetic::geometric_error(z),
                    "cut_bound_m": self.cut_bound(z),
                    "tin_budget_m": self.budget(z),
                })).collect::<Vec<_>>(),
                "data_level": self.data_level,
                "vertical_datum": self.datum.name(),
                "heights": match self.datum {
                    VerticalDatum::Egm96 => "above the WGS 84 ellipsoid: the data's heights above \
                        the EGM96 geoid plus its undulation N (NGA's 15' grid, bilinear)",
                    VerticalDatum::Ellipsoid => "above the WGS 84 ellipsoid, as stored",
                    // `new` refuses a datum it cannot lift.
                    VerticalDatum::Egm2008 => "above the EGM2008 geoid, as stored",
                    VerticalDatum::Unknown => "as stored: the data does not say what they are \
                        above (serve --vertical-datum says)",
                },
                "corner_quantum_m": self.quanta.corner,
                "error": "each tile's metadata: fmrh.error = max over the data samples inside \
                    it of |tile - surface| + the owning block's e*, so |tile - source| <= error",
            }
        })
    }

    /// The samples a tile and its four neighbours' grids (and a grid line beyond) may draw
    /// from: the tile's box widened by a tile each way, placed; `None` off the data.
    fn window(&self, t: GeodeticTile) -> Option<SampleRect> {
        let [w, s, e, n] = t.bounds();
        let (dw, dh) = (e - w, n - s);
        let pad = 1.0 + 2.0 / 64.0;
        let b = [w - dw * pad, s - dh * pad, e + dw * pad, n + dh * pad];
        window_in(&self.placement, self.data, self.data_box, b)
    }

    /// Cuts tile `t` from the blocks `cut(window, bound)` gives (`Terrain::cut`): the
    /// blocks within the level's bound over the tile and its neighbours, meshed within its
    /// budget, with its metadata (what it measured, and for a root the availability of
    /// every level below it).
    pub fn cut(
        &self,
        t: GeodeticTile,
        cut: impl FnOnce(SampleRect, f64) -> Result<Vec<CutBlock>>,
        edges: &EdgeCache,
    ) -> Result<TinTile> {
        if !self.has(t) {
            return Err(Error::InvalidArgument(format!(
                "tile {}/{}/{} is not in the tileset",
                t.z, t.x, t.y
            )));
        }
        let cut_bound = self.cut_bound(t.z);
        let budget = self.budget(t.z);
        let cut_blocks = match self.window(t) {
            Some(w) => cut(w, cut_bound)?,
            None => Vec::new(),
        };
        let blocks: Vec<GridBlock<'_>> = cut_blocks.iter().map(CutBlock::grid).collect();
        let levels: std::collections::BTreeSet<u8> = cut_blocks.iter().map(|b| b.level).collect();
        let surface = Surface::new(blocks);
        let (mut tin, learnt) = tin_tile::tin_tile(
            t,
            &surface,
            &self.placement,
            self.data_box,
            budget,
            self.quanta,
            &|n| edges.get(n),
        )?;
        edges.put(learnt);
        tin.data.metadata = json!({ "fmrh": {
            "tile": [t.z, t.x, t.y],
            "error": tin.error,
            "resampling": tin.resampling,
            "block_error": tin.block_error,
            "measured_samples": tin.measured,
            "cut_bound": cut_bound,
            "tin_budget": budget,
            "triangles": tin.data.triangles.len(),
            "levels": levels,
        }});
        if t.z == 0 {
            tin.data.metadata["available"] = Value::Array(self.ranges(1, self.maxzoom.max(1), Some(t)));
        }
        Ok(tin)
    }

    /// A cut tile's bytes, with the normals and metadata extensions when asked for.
    pub fn encode(tile: &TinTile, normals: bool, metadata: bool) -> Result<Vec<u8>> {
        let mut data = tile.data.clone();
        if !normals {
            data.normals = None;
        }
        if !metadata {
            data.metadata = Value::Null;
        }
        quantized_mesh::write(&data)
    }
}
