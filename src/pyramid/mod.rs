//! A terrain's web tile pyramids, cut from its blocks: Cesium's quantized-mesh terrain
//! (`crate::export::tileset`) and web maps' terrain-RGB (`crate::export::terrain_rgb`),
//! tile by tile as `fmrh serve` answers them and whole as `fmrh export` writes them
//! ([`export`]). One cut serves both, so a static pyramid holds, tile for tile, the bytes
//! the server gives for the same state.
//!
//! This room joins a [`Terrain`] (which blocks, decoded) to the tile arithmetic of
//! `crate::export` (which tiles, and how a tile is drawn from blocks); it speaks no HTTP and
//! writes no files of its own (the writers are [`export`]'s sinks).

pub mod export;

use std::io::Write;

use crate::export::geodetic::GeodeticTile;
use crate::export::terrain_rgb::{self, Encoding, MercatorTile, NoData, RgbTiles};
use crate::export::tileset::{CutBlock, DataShape, EdgeCache, Tileset};
use crate::geoid::VerticalDatum;
use crate::model::SampleRect;
use crate::terrain::{Info, Terrain};
use crate::{Error, Result};

/// What a tileset needs of a terrain's [`Info`].
pub fn shape_of(info: &Info) -> DataShape {
    DataShape {
        georeference: info.georeference.clone(),
        width: info.width,
        height: info.height,
        height_range: info.height_range,
    }
}

/// The blocks of `terrain`'s cut over `window` within `bound`, as the tilesets take them.
pub fn cut_blocks(terrain: &Terrain, window: SampleRect, bound: f64) -> Result<Vec<CutBlock>> {
    Ok(terrain
        .cut(window, bound)?
        .blocks
        .into_iter()
        .map(|b| CutBlock {
            rect: b.rect,
            level: b.level,
            stride: b.stride,
            width: b.width,
            height: b.height,
            heights: b.heights,
            error: b.error,
        })
        .collect())
}

/// `bytes` gzipped as the server sends quantized-mesh tiles (level 5: a tile is cut once
/// and sent many times, but it is cut while a client waits).
pub fn gzip(bytes: &[u8]) -> Result<Vec<u8>> {
    let mut enc = flate2::write::GzEncoder::new(Vec::new(), flate2::Compression::new(5));
    enc.write_all(bytes)
        .and_then(|()| enc.finish())
        .map_err(|e| Error::InvalidArgument(format!("gzip: {e}")))
}

/// The terrain-RGB tile `t` of `terrain` (its tiles `tiles`), `size` pixels a side, as a
/// PNG in `encoding` with no data drawn as `nodata`: pixels drawn by the blocks of the
/// coarsest level within its smallest pixel. The caller checks that `tiles` has `t`
/// ([`RgbTiles::meets`]).
pub fn rgb_tile(
    terrain: &Terrain,
    tiles: &RgbTiles,
    t: MercatorTile,
    size: u32,
    encoding: Encoding,
    nodata: NoData,
) -> Result<Vec<u8>> {
    let blocks = match tiles.window(t) {
        Some(w) => cut_blocks(terrain, w, tiles.bound(t, size))?,
        None => Vec::new(),
    };
    let heights = tiles.heights(t, size, &blocks);
    terrain_rgb::png(&heights, size, encoding, nodata)
}

/// Which pyramid, and how its tiles are made.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum TileFormat {
    /// Cesium's quantized-mesh 1.0, global-geodetic TMS, with the `octvertexnormals` and
    /// `metadata` extensions; `max_error` caps every level's TIN budget (metres), `datum`
    /// overrides what the heights are above.
    QuantizedMesh {
        max_error: Option<f64>,
        datum: Option<VerticalDatum>,
    },
    /// Terrain-RGB PNGs, Web Mercator XYZ, with no data drawn as `nodata`.
    TerrainRgb {
        encoding: Encoding,
        size: u32,
        nodata: NoData,
    },
}

/// A tile's address in either pyramid.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum TileAddress {
    /// Cesium's: `x` from 180° W over `2^(z+1)` columns, `y` from the south.
    Geodetic(GeodeticTile),
    /// Web Mercator's: `y` from the north.
    Mercator(MercatorTile),
}

impl TileAddress {
    /// `(z, x, y)` as the address reads.
    pub fn zxy(&self) -> (u8, u32, u32) {
        match *self {
            TileAddress::Geodetic(t) => (t.z, t.x, t.y),
            TileAddress::Mercator(t) => (t.z, t.x, t.y),
        }
    }

    /// Where a PMTiles archive keeps the tile. PMTiles' zoom `z` is a square of `2^z ×
    /// 2^z` tiles; Cesium's geodetic level `z` is `2^(z+1) × 2^z`, so level `z` is kept at
    /// PMTiles zoom `z + 1`, with the same `x` and `y` (`y` from the south, as Cesium asks
    /// for it): the rows `0..2^z` of that zoom's square, the others empty.
    pub fn pmtiles_zxy(&self) -> (u8, u32, u32) {
        match *self {
            TileAddress::Geodetic(t) => (t.z + 1, t.x, t.y),
            TileAddress::Mercator(t) => (t.z, t.x, t.y),
        }
    }
}

/// A terrain's pyramid of one [`TileFormat`]: which tiles exist and each one's bytes.
pub struct Pyramid {
    terrain: Terrain,
    info: Info,
    kind: Kind,
}

enum Kind {
    Mesh { tileset: Tileset, edges: EdgeCache },
    Rgb {
        tiles: RgbTiles,
        encoding: Encoding,
        size: u32,
        nodata: NoData,
    },
}

impl Pyramid {
    /// The pyramid of `format` over `terrain`; an error when the terrain cannot be placed
    /// on the globe.
    pub fn new(terrain: Terrain, format: TileFormat) -> Result<Pyramid> {
        let info = terrain.info()?;
        let shape = shape_of(&info);
        let kind = match format {
            TileFormat::QuantizedMesh { max_error, datum } => Kind::Mesh {
                tileset: Tileset::new(&shape, max_error, datum.unwrap_or(info.vertical_datum))?,
                edges: EdgeCache::default(),
            },
            TileFormat::TerrainRgb {
                encoding,
                size,
                nodata,
            } => {
                if size != 256 && size != 512 {
                    return Err(Error::InvalidArgument(format!(
                        "terrain-RGB tiles are 256 or 512 pixels, not {size}"
                    )));
                }
                Kind::Rgb {
                    tiles: RgbTiles::new(&shape, size)?,
                    encoding,
                    size,
                    nodata,
                }
            }
        };
        Ok(Pyramid {
            terrain,
            info,
            kind,
        })
    }

    /// The terrain's description, as read when the pyramid was made.
    pub fn info(&self) -> &Info {
        &self.info
    }

    /// The deepest zoom.
    pub fn maxzoom(&self) -> u8 {
        match &self.kind {
            Kind::Mesh { tileset, .. } => tileset.maxzoom(),
            Kind::Rgb { tiles, .. } => tiles.maxzoom(),
        }
    }

    /// The tiles of zoom `z` the server answers (every tile meeting the data), those
    /// meeting `bbox` (`[west, south, east, north]`, degrees) when one is given, in no
    /// particular order.
    pub fn tiles(&self, z: u8, bbox: Option<[f64; 4]>) -> Vec<TileAddress> {
        if z > self.maxzoom() {
            return Vec::new();
        }
        let meets_box = |b: [f64; 4]| {
            bbox.is_none_or(|[w, s, e, n]| b[0] <= e && b[2] >= w && b[1] <= n && b[3] >= s)
        };
        match &self.kind {
            Kind::Mesh { tileset, .. } => {
                let Some((x0, y0, x1, y1)) = tileset.available(z) else {
                    return Vec::new();
                };
                (y0..=y1)
                    .flat_map(|y| (x0..=x1).map(move |x| GeodeticTile { z, x, y }))
                    .filter(|&t| tileset.has(t) && meets_box(t.bounds()))
                    .map(TileAddress::Geodetic)
                    .collect()
            }
            Kind::Rgb { tiles, .. } => {
                let [w, s, e, n] = tiles.data_box();
                let n_tiles = 1u64 << z;
                let column = |lon: f64| {
                    (((lon + 180.0) / 360.0 * n_tiles as f64).floor().max(0.0) as u64)
                        .min(n_tiles - 1) as u32
                };
                let row = |lat: f64| {
                    let lat = lat.clamp(-terrain_rgb::MAX_LAT, terrain_rgb::MAX_LAT).to_radians();
                    let m = (1.0 - (lat.tan() + 1.0 / lat.cos()).ln() / std::f64::consts::PI) / 2.0;
                    ((m * n_tiles as f64).floor().max(0.0) as u64).min(n_tiles - 1) as u32
                };
                // One tile of margin each way; `meets` decides.
                let (x0, x1) = (column(w).saturating_sub(1), column(e).saturating_add(1));
                let (y0, y1) = (row(n).saturating_sub(1), row(s).saturating_add(1));
                (y0..=y1.min((n_tiles - 1) as u32))
                    .flat_map(|y| (x0..=x1.min((n_tiles - 1) as u32)).map(move |x| MercatorTile { z, x, y }))
                    .filter(|&t| tiles.meets(t) && meets_box(t.bounds()))
                    .map(TileAddress::Mercator)
                    .collect()
            }
        }
    }

    /// The bytes of tile `t` as the server sends them without a content encoding:
    /// quantized-mesh with both extensions, or the PNG.
    pub fn tile(&self, t: TileAddress) -> Result<Vec<u8>> {
        match (&self.kind, t) {
            (Kind::Mesh { tileset, edges }, TileAddress::Geodetic(g)) => {
                let cut = tileset.cut(g, |w, bound| cut_blocks(&self.terrain, w, bound), edges)?;
                Tileset::encode(&cut, true, true)
            }
            (
                Kind::Rgb {
                    tiles,
                    encoding,
                    size,
                    nodata,
                },
                TileAddress::Mercator(m),
            ) => {
                if !tiles.meets(m) {
                    return Err(Error::InvalidArgument(format!(
                        "tile {}/{}/{} does not meet the data",
                        m.z, m.x, m.y
                    )));
                }
                rgb_tile(&self.terrain, tiles, m, *size, *encoding, *nodata)
            }
            _ => Err(Error::InvalidArgument(
                "a tile address of the other pyramid".into(),
            )),
        }
    }

    /// The pyramid's description for clients: Cesium's `layer.json` or the TileJSON, with
    /// tile addresses `template`-relative (`{z}/{x}/{y}.terrain` or `.png` when `None`).
    pub fn tilejson(&self, name: &str, version: &str, template: Option<&str>) -> serde_json::Value {
        match &self.kind {
            Kind::Mesh { tileset, .. } => {
                let mut json = tileset.layer_json(name, version);
                if let Some(t) = template {
                    json["tiles"] = serde_json::json!([t]);
                }
                json
            }
            Kind::Rgb {
                tiles,
                encoding,
                size,
                nodata,
            } => {
                let mut json = tiles.tilejson(
                    template.unwrap_or("{z}/{x}/{y}.png"),
                    *encoding,
                    *size,
                    *nodata,
                );
                json["name"] = name.into();
                json["version"] = version.into();
                json
            }
        }
    }

    /// The data's `[west, south, east, north]`, degrees.
    pub fn bounds(&self) -> [f64; 4] {
        match &self.kind {
            Kind::Mesh { tileset, .. } => tileset.data_box(),
            Kind::Rgb { tiles, .. } => {
                let [w, s, e, n] = tiles.data_box();
                [w, s.max(-terrain_rgb::MAX_LAT), e, n.min(terrain_rgb::MAX_LAT)]
            }
        }
    }

    /// The file extension of a tile.
    pub fn extension(&self) -> &'static str {
        match self.kind {
            Kind::Mesh { .. } => "terrain",
            Kind::Rgb { .. } => "png",
        }
    }
}
