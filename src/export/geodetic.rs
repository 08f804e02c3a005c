//! The geographic (EPSG:4326) tile pyramid Cesium's terrain reads: addresses, bounds and
//! geometric errors. Pure arithmetic; no meshes, no files.
//!
//! Level 0 is two tiles, west and east of the prime meridian, each 180° a side; every tile
//! has four children, two each way. Tiles are addressed TMS-style, `z/x/y` with `x` counted
//! from 180° W and `y` from 90° S (the quantized-mesh spec's scheme). Cesium gives a level-0
//! tile the geometric error of a 65-sample heightmap stretched over a quarter of the
//! equator, and halves it each level ([`geometric_error`]).
//!
//! The tiles a georeferenced scene meets at each level are written from the root down
//! (Cesium only reaches a tile whose ancestors it has), by [`super::geodetic_mesh`].
//!
//! **The ellipsoid.** Tile headers are in Earth-centred, Earth-fixed coordinates (ECEF) on
//! WGS 84 ([`ecef`]), and carry a *horizon occlusion point* ([`horizon_occlusion_point`]):
//! a point in the ellipsoid-scaled frame (ECEF divided by the radii, where the ellipsoid is
//! the unit sphere) that is below the horizon only when the whole tile is, following
//! Cesium's "Horizon culling" (Ring, 2013) as its `EllipsoidalOccluder` computes it.

pub use crate::globe::{ecef, horizon_occlusion_point, up, WGS84_A};
#[cfg(any(test, feature = "testing"))]
pub use crate::globe::{scaled, scaled_point_visible, FAR_OCCLUSION_RADII, WGS84_B, WGS84_E2};

/// Samples along a side of the heightmap Cesium sizes its level-0 error by.
pub const HEIGHTMAP_WIDTH: f64 = 65.0;

/// One tile of the pyramid.
#[derive(Clone, Copy, Debug, PartialEq, Eq, PartialOrd, Ord, Hash)]
pub struct GeodeticTile {
    /// Level: 0 the two root tiles.
    pub z: u8,
    /// Column, from 180° W: `0..2^(z+1)`.
    pub x: u32,
    /// Row, from 90° S: `0..2^z`.
    pub y: u32,
}

/// Degrees along a side of a level-`z` tile.
pub fn tile_degrees(z: u8) -> f64 {
    180.0 / f64::from(1u32 << z.min(31))
}

/// The deepest level addressed (`x` must fit `u32`).
pub const MAX_LEVEL: u8 = 30;

impl GeodeticTile {
    /// `[west, south, east, north]` in degrees.
    pub fn bounds(&self) -> [f64; 4] {
        let d = tile_degrees(self.z);
        let west = -180.0 + f64::from(self.x) * d;
        let south = -90.0 + f64::from(self.y) * d;
        [west, south, west + d, south + d]
    }

    /// The tile one level up, or `None` at level 0.
    pub fn parent(&self) -> Option<GeodeticTile> {
        (self.z > 0).then(|| GeodeticTile {
            z: self.z - 1,
            x: self.x / 2,
            y: self.y / 2,
        })
    }

    /// The four tiles one level down (south-west, south-east, north-west, north-east).
    #[cfg(any(test, feature = "testing"))]
    pub fn children(&self) -> [GeodeticTile; 4] {
        let (z, x, y) = (self.z + 1, self.x * 2, self.y * 2);
        [
            GeodeticTile { z, x, y },
            GeodeticTile { z, x: x + 1, y },
            GeodeticTile { z, x, y: y + 1 },
            GeodeticTile {
                z,
                x: x + 1,
                y: y + 1,
            },
        ]
    }
}

/// Cesium's geometric error of a level-`z` tile, metres, as `CesiumTerrainProvider` sets
/// it (`TerrainProvider.getEstimatedLevelZeroGeometricErrorForAHeightmap`): the equator's
/// length times the heightmap quality 0.25, over 65 samples times the 2 tiles of level 0
/// (77,067 m), halved each level. (Before issue 41 fmrh left out the 2 tiles, and so
/// doubled every level's error: 37.6 m at level 12 where Cesium uses 18.8 m.)
pub fn geometric_error(z: u8) -> f64 {
    const HEIGHTMAP_QUALITY: f64 = 0.25;
    const LEVEL_ZERO_TILES: f64 = 2.0;
    let level_zero = WGS84_A * 2.0 * std::f64::consts::PI * HEIGHTMAP_QUALITY
        / (HEIGHTMAP_WIDTH * LEVEL_ZERO_TILES);
    level_zero / f64::from(1u32 << z.min(31))
}

/// The tiles of level `z` whose area meets the box `[west, south, east, north]` (degrees,
/// clamped to the globe), west to east, then south to north. A box edge lying on a tile
/// edge does not bring in the tile beyond it; an empty or invalid box meets none.
pub fn tiles_meeting(z: u8, bounds: [f64; 4]) -> Vec<GeodeticTile> {
    let z = z.min(MAX_LEVEL);
    let [w, s, e, n] = [
        bounds[0].clamp(-180.0, 180.0),
        bounds[1].clamp(-90.0, 90.0),
        bounds[2].clamp(-180.0, 180.0),
        bounds[3].clamp(-90.0, 90.0),
    ];
    if !(w < e && s < n) {
        return Vec::new();
    }
    let d = tile_degrees(z);
    let columns = 2u64 << z;
    let rows = 1u64 << z;
    // First index whose tile ends past `lo`; last index whose tile starts before `hi`.
    let span = |lo: f64, hi: f64, origin: f64, count: u64| {
        let first = (((lo - origin) / d).floor().max(0.0) as u64).min(count - 1);
        let last = ((((hi - origin) / d).ceil() as u64).max(1) - 1).min(count - 1);
        (first, last)
    };
    let (x0, x1) = span(w, e, -180.0, columns);
    let (y0, y1) = span(s, n, -90.0, rows);
    let mut out = Vec::new();
    for y in y0..=y1 {
        for x in x0..=x1 {
            out.push(GeodeticTile {
                z,
                x: x as u32,
                y: y as u32,
            });
        }
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;

    /// Regression (issue 41): CesiumJS's level-0 error for the global-geodetic pyramid is
    /// `6378137 · 2π · 0.25 / (65 · 2)` (computed here by hand, 77,067.34 m), 18.8 m at
    /// level 12; fmrh had twice that.
    #[test]
    fn geometric_errors_are_cesium_s() {
        assert!((geometric_error(0) - 77_067.34).abs() < 0.01, "{}", geometric_error(0));
        assert!((geometric_error(12) - 18.815).abs() < 0.001, "{}", geometric_error(12));
    }

    #[test]
    fn the_spec_s_first_tiles() {
        assert_eq!(
            GeodeticTile { z: 0, x: 1, y: 0 }.bounds(),
            [0.0, -90.0, 180.0, 90.0]
        );
        assert_eq!(
            GeodeticTile { z: 1, x: 2, y: 1 }.bounds(),
            [0.0, 0.0, 90.0, 90.0]
        );
        assert_eq!(tiles_meeting(0, [-180.0, -90.0, 180.0, 90.0]).len(), 2);
        assert_eq!(tiles_meeting(1, [-180.0, -90.0, 180.0, 90.0]).len(), 8);
        // A box on the prime meridian's east side only.
        assert_eq!(
            tiles_meeting(0, [0.0, 10.0, 1.0, 11.0]),
            vec![GeodeticTile { z: 0, x: 1, y: 0 }]
        );
        assert!(tiles_meeting(3, [5.0, 5.0, 5.0, 6.0]).is_empty());
        // Edges on tile edges bring in nothing beyond them, at the globe's edges too.
        assert_eq!(
            tiles_meeting(1, [0.0, 0.0, 90.0, 90.0]),
            vec![GeodeticTile { z: 1, x: 2, y: 1 }]
        );
        assert_eq!(
            tiles_meeting(0, [170.0, 80.0, 180.0, 90.0]),
            vec![GeodeticTile { z: 0, x: 1, y: 0 }]
        );
        assert_eq!(
            tiles_meeting(0, [-180.0, -90.0, -170.0, -80.0]),
            vec![GeodeticTile { z: 0, x: 0, y: 0 }]
        );
        // Cesium's level-0 error for the default ellipsoid: about 77 km (CesiumJS 1.x,
        // `CesiumTerrainProvider` with `getNumberOfXTilesAtLevel(0)` = 2; this pinned
        // 154 km, twice Cesium's, until issue 41).
        assert!(
            (geometric_error(0) - 77_067.34).abs() < 1.0,
            "{}",
            geometric_error(0)
        );
        assert_eq!(geometric_error(3), geometric_error(0) / 8.0);
    }

    /// The vertices of a tile, the occlusion point of `tile` with heights `lo..=hi`.
    fn tile_points(t: GeodeticTile, lo: f64, hi: f64) -> Vec<[f64; 3]> {
        let [w, s, e, n] = t.bounds();
        let mut out = Vec::new();
        for i in 0..=8 {
            for j in 0..=8 {
                let lon = w + (e - w) * f64::from(i) / 8.0;
                let lat = s + (n - s) * f64::from(j) / 8.0;
                let h = if (i + j) % 2 == 0 { lo } else { hi };
                out.push(ecef(lon, lat, h));
            }
        }
        out
    }

    proptest! {
        /// From any camera outside the ellipsoid, if any vertex of a tile is above the
        /// horizon, so is the tile's occlusion point: culling by it never hides a visible
        /// tile. (Tested on the vertices; a vertex above the horizon is what a tile shows.)
        #[test]
        fn the_occlusion_point_is_visible_whenever_a_vertex_is(
            z in 1u8..14, fx in 0.0f64..1.0, fy in 0.0f64..1.0,
            lo in -400.0f64..3000.0, dh in 0.0f64..5000.0,
            cam_lon in -180.0f64..180.0, cam_lat in -90.0f64..90.0, cam_h in 10.0f64..3.0e7,
        ) {
            let t = GeodeticTile {
                z,
                x: ((2u32 << z) as f64 * fx) as u32 % (2 << z),
                y: ((1u32 << z) as f64 * fy) as u32 % (1 << z),
            };
            let points = tile_points(t, lo, lo + dh);
            let [w, s, e, n] = t.bounds();
            let centre = ecef((w + e) / 2.0, (s + n) / 2.0, lo);
            let point = horizon_occlusion_point(centre, &points);
            let camera = scaled(ecef(cam_lon, cam_lat, cam_h));
            let any_visible = points.iter().any(|&p| scaled_point_visible(camera, scaled(p)));
            if any_visible {
                prop_assert!(scaled_point_visible(camera, point), "{t:?} from {cam_lon},{cam_lat},{cam_h}: {point:?}");
            }
        }

        /// The tiles a box meets cover it, and each of them meets it with positive area.
        #[test]
        fn tiles_meeting_cover_a_box_and_no_more(
            z in 0u8..12,
            w in -180.0f64..180.0, dw in 0.0001f64..40.0,
            s in -90.0f64..90.0, ds in 0.0001f64..40.0,
        ) {
            let b = [w, s, (w + dw).min(180.0), (s + ds).min(90.0)];
            prop_assume!(b[0] < b[2] && b[1] < b[3]);
            let tiles = tiles_meeting(z, b);
            let mut covered = 0.0;
            for t in &tiles {
                let [tw, ts, te, tn] = t.bounds();
                let ow = (te.min(b[2]) - tw.max(b[0])).max(0.0);
                let oh = (tn.min(b[3]) - ts.max(b[1])).max(0.0);
                prop_assert!(ow > 0.0 && oh > 0.0, "{t:?} does not meet {b:?}");
                covered += ow * oh;
            }
            let area = (b[2] - b[0]) * (b[3] - b[1]);
            prop_assert!((covered - area).abs() <= 1e-9 * area.max(1.0), "{covered} vs {area}");
        }

        /// Children partition their parent, and know it.
        #[test]
        fn children_partition_the_parent(z in 0u8..20, x in 0u32..1 << 20, y in 0u32..1 << 19) {
            let t = GeodeticTile { z, x: x % (2 << z), y: y % (1 << z) };
            let [w, s, e, n] = t.bounds();
            let mut area = 0.0;
            for c in t.children() {
                prop_assert_eq!(c.parent(), Some(t));
                let [cw, cs, ce, cn] = c.bounds();
                prop_assert!(cw >= w && cs >= s && ce <= e && cn <= n);
                area += (ce - cw) * (cn - cs);
            }
            prop_assert!((area - (e - w) * (n - s)).abs() <= 1e-9 * (e - w) * (n - s));
        }
    }
}
