//! Web maps' terrain: heights as the colours of Web Mercator XYZ tiles, as MapLibre GL's
//! (and Mapbox GL's) `raster-dem` sources read them, cut from a terrain's blocks.
//!
//! **Tiles.** Tile `z/x/y` is Web Mercator's (EPSG:3857), `y` counted from the north; its
//! `size × size` pixels (256 or 512) are sampled at their centres. **Encodings**: Mapbox
//! terrain-RGB, `h = −10000 + (R·65536 + G·256 + B)·0.1` (0.1 m steps), and Terrarium,
//! `h = R·256 + G + B/256 − 32768` (1/256 m steps); each height is rounded to the nearest
//! step its encoding holds. A pixel with no data under it (off the data, or a void) is
//! opaque sea level by default, or another height, or transparent ([`NoData`]: readers of
//! `raster-dem` tiles ignore alpha, so a transparent pixel would read as −10 km). Heights are the stored ones (orthometric for SRTM: what
//! MapLibre expects), never lifted by a geoid.
//!
//! **Which blocks.** A tile is cut from the coarsest error level of the FMRH whose every
//! block's **measured** error is within the tile's pixel size on the ground, taken at its
//! edge nearest a pole (the smallest pixel in the tile): `40 075 016.686 m · cos(lat) /
//! (2^z · size)`. **Resampling**: each pixel is the height the blocks' surface draws at its
//! centre (linear over each cell's two triangles, as the meshes draw it; at a sample, the
//! sample), so a pixel is within its block's error of the source there.
//!
//! **Levels.** `maxzoom` is the first zoom whose pixels at the data's centre latitude are
//! at most the data's own sample spacing: deeper tiles would only interpolate. Its tiles are
//! cut from the exact blocks (`e* = 0`), not the coarsest within a pixel: a user zoomed in
//! all the way sees the data itself, as a tiler reading the raster gives it (the pixel
//! rule alone left 38 m errors in N43E006's deepest tiles; `benches/terrain_rgb_export.rs`).

use serde_json::{json, Value};

use crate::error::{Error, Result};
use crate::export::geodetic_mesh::Placement;
use crate::export::tileset::{window_in, CutBlock, DataShape};
use crate::model::SampleRect;
use crate::scene::surface::{GridBlock, Surface};

/// The equator's length on the WGS 84 ellipsoid, metres: Web Mercator's width at zoom 0.
pub const EQUATOR_M: f64 = 40_075_016.686;

/// Web Mercator's latitude limit, degrees (the square's top and bottom).
pub const MAX_LAT: f64 = 85.051_128_779_806_59;

/// The deepest zoom served (pixels of a few centimetres at 512 px).
pub const MAX_ZOOM: u8 = 24;

/// What a pixel with no data under it (off the data, or a void) holds.
///
/// Web maps' `raster-dem` readers ignore alpha: MapLibre draws a tile through a canvas,
/// whose premultiplied alpha turns a transparent pixel's colour into `(0, 0, 0)`, which it
/// decodes as −10,000 m (Mapbox) or −32,768 m (Terrarium), a cliff at every edge of the
/// data (seen in `tests/maplibre_terrain.rs`). So the default is an opaque height.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum NoData {
    /// Opaque, encoding this height (metres); the default is 0 (sea level).
    Height(f64),
    /// Transparent `(0, 0, 0, 0)`, for readers that honour alpha.
    Transparent,
}

impl Default for NoData {
    fn default() -> NoData {
        NoData::Height(0.0)
    }
}

impl NoData {
    /// `transparent`, or a height in metres (finite).
    pub fn parse(text: &str) -> Option<NoData> {
        if text == "transparent" {
            return Some(NoData::Transparent);
        }
        text.parse::<f64>()
            .ok()
            .filter(|h| h.is_finite())
            .map(NoData::Height)
    }

    /// What it is, for a TileJSON.
    pub fn describe(self) -> String {
        match self {
            NoData::Height(h) => format!("opaque, encoding {h} m"),
            NoData::Transparent => "transparent (0, 0, 0, 0)".into(),
        }
    }
}

/// How heights become colours.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum Encoding {
    /// Mapbox terrain-RGB: `−10000 + (R·65536 + G·256 + B)·0.1`.
    Mapbox,
    /// Terrarium: `R·256 + G + B/256 − 32768`.
    Terrarium,
}

impl Encoding {
    /// The encoding a name says (`mapbox` or `terrarium`).
    pub fn parse(name: &str) -> Option<Encoding> {
        match name {
            "mapbox" => Some(Encoding::Mapbox),
            "terrarium" => Some(Encoding::Terrarium),
            _ => None,
        }
    }

    /// Its name, as TileJSON's `encoding` says it.
    pub fn name(self) -> &'static str {
        match self {
            Encoding::Mapbox => "mapbox",
            Encoding::Terrarium => "terrarium",
        }
    }

    /// The smallest step of height it holds, metres.
    #[cfg(test)]
    fn step(self) -> f64 {
        match self {
            Encoding::Mapbox => 0.1,
            Encoding::Terrarium => 1.0 / 256.0,
        }
    }

    /// The pixel for height `h` (metres), rounded to the nearest step it holds and clamped
    /// to its range; NaN (no data): transparent.
    pub fn encode(self, h: f64) -> [u8; 4] {
        if h.is_nan() {
            return [0, 0, 0, 0];
        }
        let v = match self {
            Encoding::Mapbox => ((h + 10_000.0) * 10.0).round().clamp(0.0, 16_777_215.0),
            Encoding::Terrarium => ((h + 32_768.0) * 256.0).round().clamp(0.0, 16_777_215.0),
        } as u32;
        [(v >> 16) as u8, (v >> 8) as u8, v as u8, 255]
    }

    /// The height a pixel encodes; `None` for a transparent one.
    #[cfg(test)]
    fn decode(self, px: [u8; 4]) -> Option<f64> {
        if px[3] == 0 {
            return None;
        }
        let v = f64::from(u32::from(px[0]) << 16 | u32::from(px[1]) << 8 | u32::from(px[2]));
        Some(match self {
            Encoding::Mapbox => v / 10.0 - 10_000.0,
            Encoding::Terrarium => v / 256.0 - 32_768.0,
        })
    }
}

/// A Web Mercator XYZ tile (`y` from the north).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub struct MercatorTile {
    pub z: u8,
    pub x: u32,
    pub y: u32,
}

impl MercatorTile {
    /// Whether `x` and `y` lie within zoom `z`'s `2^z × 2^z` tiles.
    pub fn is_valid(&self) -> bool {
        self.z <= MAX_ZOOM && u64::from(self.x) < 1u64 << self.z && u64::from(self.y) < 1u64 << self.z
    }

    /// Longitude and latitude (degrees) of the point `(fx, fy)` tiles from the tile's
    /// north-west corner (0 to 1 across it).
    pub fn lon_lat(&self, fx: f64, fy: f64) -> [f64; 2] {
        let n = (1u64 << self.z) as f64;
        let lon = (f64::from(self.x) + fx) / n * 360.0 - 180.0;
        let m = std::f64::consts::PI * (1.0 - 2.0 * (f64::from(self.y) + fy) / n);
        [lon, m.sinh().atan().to_degrees()]
    }

    /// `[west, south, east, north]`, degrees.
    pub fn bounds(&self) -> [f64; 4] {
        let [w, n] = self.lon_lat(0.0, 0.0);
        let [e, s] = self.lon_lat(1.0, 1.0);
        [w, s, e, n]
    }

    /// A pixel's size on the ground at latitude `lat` (degrees), metres, with `size`
    /// pixels a tile.
    pub fn pixel_m(z: u8, size: u32, lat: f64) -> f64 {
        EQUATOR_M * lat.to_radians().cos() / ((1u64 << z) as f64 * f64::from(size))
    }
}

/// The terrain-RGB tiles of one terrain: where its data lies and how to place it.
pub struct RgbTiles {
    placement: Placement,
    data: SampleRect,
    data_box: [f64; 4],
    maxzoom: u8,
}

impl RgbTiles {
    /// The tiles of a terrain shaped as `data`, with `size` pixels a tile; an error when
    /// it cannot be placed on the globe.
    pub fn new(data: &DataShape, size: u32) -> Result<RgbTiles> {
        let georeference = data.georeference.as_ref().ok_or_else(|| {
            Error::InvalidArgument(
                "no georeference: the data cannot be placed on a map, so it has no \
                 terrain-RGB tiles"
                    .into(),
            )
        })?;
        if data.width == 0 || data.height == 0 {
            return Err(Error::InvalidArgument("the terrain has no samples".into()));
        }
        let placement = Placement::new(georeference, 1.0)?;
        let rect = SampleRect {
            col0: 0,
            row0: 0,
            col1: data.width - 1,
            row1: data.height - 1,
        };
        let data_box = placement.box_of(&rect).ok_or_else(|| {
            Error::InvalidArgument("the data's corners cannot be placed on the globe".into())
        })?;
        let [w, s, e, n] = data_box;
        // The data's finer spacing on the ground, metres, at its centre latitude.
        let lat = (s + n) / 2.0;
        let spacing = ((e - w) / data.width.max(2).saturating_sub(1) as f64
            * lat.to_radians().cos())
        .min((n - s) / data.height.max(2).saturating_sub(1) as f64)
            * EQUATOR_M
            / 360.0;
        let mut maxzoom = 0;
        while maxzoom < MAX_ZOOM && MercatorTile::pixel_m(maxzoom, size, lat) > spacing {
            maxzoom += 1;
        }
        Ok(RgbTiles {
            placement,
            data: rect,
            data_box,
            maxzoom,
        })
    }

    /// The deepest zoom.
    pub fn maxzoom(&self) -> u8 {
        self.maxzoom
    }

    /// The data's `[west, south, east, north]`, degrees.
    pub fn data_box(&self) -> [f64; 4] {
        self.data_box
    }

    /// Whether tile `t` meets the data.
    pub fn meets(&self, t: MercatorTile) -> bool {
        let [w, s, e, n] = t.bounds();
        let [dw, ds, de, dn] = self.data_box;
        t.is_valid() && t.z <= self.maxzoom && w <= de && e >= dw && s <= dn && n >= ds
    }

    /// The bound on the blocks' measured error a tile of `size` pixels is cut within: its
    /// smallest pixel on the ground (at its edge nearest a pole); at `maxzoom`, where the
    /// pixels are as fine as the samples, 0: the deepest tiles hold the data itself.
    pub fn bound(&self, t: MercatorTile, size: u32) -> f64 {
        if t.z >= self.maxzoom {
            return 0.0;
        }
        let [_, s, _, n] = t.bounds();
        let poleward = if s.abs() > n.abs() { s } else { n };
        MercatorTile::pixel_m(t.z, size, poleward.clamp(-MAX_LAT, MAX_LAT))
    }

    /// The samples tile `t` draws from (its box placed, with two samples of margin);
    /// `None` off the data.
    pub fn window(&self, t: MercatorTile) -> Option<SampleRect> {
        window_in(&self.placement, self.data, self.data_box, t.bounds())
    }

    /// The height at each pixel centre of tile `t` (`size × size`, rows from the north),
    /// drawn by `blocks`; NaN where none holds the point.
    pub fn heights(&self, t: MercatorTile, size: u32, blocks: &[CutBlock]) -> Vec<f64> {
        let grids: Vec<GridBlock<'_>> = blocks.iter().map(CutBlock::grid).collect();
        let surface = Surface::new(grids);
        let k = f64::from(size);
        let centres: Vec<[f64; 2]> = (0..size)
            .flat_map(|j| (0..size).map(move |i| (i, j)))
            .map(|(i, j)| t.lon_lat((f64::from(i) + 0.5) / k, (f64::from(j) + 0.5) / k))
            .collect();
        self.placement
            .positions(&centres)
            .into_iter()
            .map(|p| {
                p.and_then(|[c, r]| surface.at(c, r))
                    .map_or(f64::NAN, |s| s.height)
            })
            .collect()
    }

    /// TileJSON for tiles at `template` (its `{z}/{x}/{y}` filled in by the client).
    pub fn tilejson(&self, template: &str, encoding: Encoding, size: u32, nodata: NoData) -> Value {
        let [w, s, e, n] = self.data_box;
        json!({
            "tilejson": "3.0.0",
            "tiles": [template],
            "scheme": "xyz",
            "minzoom": 0,
            "maxzoom": self.maxzoom,
            "bounds": [w, s.max(-MAX_LAT), e, n.min(MAX_LAT)],
            "encoding": encoding.name(),
            "tileSize": size,
            "fmrh": {
                "heights": "as stored (orthometric for SRTM and DTED), rounded to the encoding's step",
                "resampling": "the blocks' surface at each pixel centre (linear over each cell's two triangles)",
                "blocks": "the coarsest error level whose every block's measured error is within the tile's smallest pixel",
                "no_data": nodata.describe(),
            }
        })
    }
}

/// A `size × size` tile of `heights` (rows from the north; NaN: no data, drawn as
/// `nodata` says) as a PNG in `encoding`: RGB, or RGBA when a pixel is transparent.
pub fn png(heights: &[f64], size: u32, encoding: Encoding, nodata: NoData) -> Result<Vec<u8>> {
    if heights.len() != (size as usize) * (size as usize) {
        return Err(Error::InvalidArgument(format!(
            "{} heights for a {size} × {size} tile",
            heights.len()
        )));
    }
    let fill = match nodata {
        NoData::Height(h) => h,
        NoData::Transparent => f64::NAN,
    };
    // RGB when every pixel is opaque (a quarter fewer bytes to compress), else RGBA.
    let alpha = fill.is_nan() && heights.iter().any(|h| h.is_nan());
    let channels = if alpha { 4 } else { 3 };
    let pixels: Vec<u8> = heights
        .iter()
        .flat_map(|&h| encoding.encode(if h.is_nan() { fill } else { h }))
        .enumerate()
        .filter(|(k, _)| alpha || k % 4 != 3)
        .map(|(_, v)| v)
        .collect();
    debug_assert_eq!(pixels.len(), heights.len() * channels);
    let mut out = Vec::new();
    {
        let mut encoder = png::Encoder::new(&mut out, size, size);
        encoder.set_color(if alpha {
            png::ColorType::Rgba
        } else {
            png::ColorType::Rgb
        });
        encoder.set_depth(png::BitDepth::Eight);
        let fail = |e: png::EncodingError| Error::InvalidArgument(format!("png: {e}"));
        let mut writer = encoder.write_header().map_err(fail)?;
        writer.write_image_data(&pixels).map_err(fail)?;
        writer.finish().map_err(fail)?;
    }
    Ok(out)
}

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;

    proptest! {
        /// Each encoding gives back every height in its range to half its step, and an
        /// exact step value exactly; NaN is transparent and decodes to nothing.
        #[test]
        fn encodings_round_trip_to_half_a_step(h in -10_000.0f64..8_000.0) {
            for e in [Encoding::Mapbox, Encoding::Terrarium] {
                let back = e.decode(e.encode(h)).unwrap();
                prop_assert!((back - h).abs() <= e.step() / 2.0 + 1e-9, "{:?}: {} -> {}", e, h, back);
                let exact = (h / e.step()).round() * e.step();
                prop_assert!((e.decode(e.encode(exact)).unwrap() - exact).abs() < 1e-9);
            }
        }

        /// A tile's corners are its neighbours' corners, and its pixels' centres lie
        /// inside its bounds, north to south.
        #[test]
        fn tiles_share_their_corners(z in 1u8..20, fx in 0.0f64..1.0, fy in 0.0f64..1.0) {
            let n = 1u32 << z;
            let (x, y) = (((fx * f64::from(n)) as u32).min(n - 2), ((fy * f64::from(n)) as u32).min(n - 2));
            let t = MercatorTile { z, x, y };
            let right = MercatorTile { z, x: x + 1, y };
            let below = MercatorTile { z, x, y: y + 1 };
            prop_assert_eq!(t.lon_lat(1.0, 0.0), right.lon_lat(0.0, 0.0));
            prop_assert_eq!(t.lon_lat(0.0, 1.0), below.lon_lat(0.0, 0.0));
            let [w, s, e, nn] = t.bounds();
            let [lon, lat] = t.lon_lat(0.5, 0.5);
            prop_assert!(w < lon && lon < e && s < lat && lat < nn);
        }
    }

    #[test]
    fn known_values() {
        // 0 m is 100,000 steps of 0.1 m above −10,000 m: 0x0186A0.
        assert_eq!(Encoding::Mapbox.encode(0.0), [1, 134, 160, 255]);
        assert_eq!(Encoding::Terrarium.encode(0.0), [128, 0, 0, 255]);
        assert_eq!(Encoding::Terrarium.encode(1.5), [128, 1, 128, 255]);
        assert_eq!(Encoding::Mapbox.encode(f64::NAN), [0, 0, 0, 0]);
        let t = MercatorTile { z: 0, x: 0, y: 0 };
        let [w, s, e, n] = t.bounds();
        assert!((w + 180.0).abs() < 1e-12 && (e - 180.0).abs() < 1e-12);
        assert!((n - MAX_LAT).abs() < 1e-9 && (s + MAX_LAT).abs() < 1e-9);
        assert!((MercatorTile::pixel_m(0, 256, 0.0) - 156_543.033_93).abs() < 1e-3);
        assert!(!MercatorTile { z: 2, x: 4, y: 0 }.is_valid());
    }
}
