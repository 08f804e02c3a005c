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

/// The WGS84 ellipsoid's semi-major axis, metres (Cesium's `maximumRadius`).
pub const WGS84_A: f64 = 6_378_137.0;

/// The WGS84 ellipsoid's semi-minor (polar) axis, metres (Cesium's `minimumRadius`).
pub const WGS84_B: f64 = 6_356_752.314_245_179;

/// WGS84's first eccentricity squared, `1 - b²/a²`.
pub const WGS84_E2: f64 = 1.0 - (WGS84_B * WGS84_B) / (WGS84_A * WGS84_A);

/// Earth-centred, Earth-fixed coordinates (metres) of longitude `lon` and latitude `lat`
/// (degrees) at height `h` above the WGS 84 ellipsoid.
pub fn ecef(lon: f64, lat: f64, h: f64) -> [f64; 3] {
    let (lam, phi) = (lon.to_radians(), lat.to_radians());
    let n = WGS84_A / (1.0 - WGS84_E2 * phi.sin().powi(2)).sqrt();
    [
        (n + h) * phi.cos() * lam.cos(),
        (n + h) * phi.cos() * lam.sin(),
        (n * (1.0 - WGS84_E2) + h) * phi.sin(),
    ]
}

/// The ellipsoid's outward normal (geodetic up) at `lon`, `lat` (degrees), in ECEF.
pub fn up(lon: f64, lat: f64) -> [f64; 3] {
    let (lam, phi) = (lon.to_radians(), lat.to_radians());
    [phi.cos() * lam.cos(), phi.cos() * lam.sin(), phi.sin()]
}

/// `p` (ECEF) in the ellipsoid-scaled frame, where WGS 84 is the unit sphere.
pub fn scaled(p: [f64; 3]) -> [f64; 3] {
    [p[0] / WGS84_A, p[1] / WGS84_A, p[2] / WGS84_B]
}

/// How far out along the scaled direction the occlusion point of a tile too large for the
/// construction is put (radii): it is then hidden only from a camera in the narrow shadow
/// right behind the Earth.
pub const FAR_OCCLUSION_RADII: f64 = 1000.0;

/// The horizon occlusion point of a tile whose vertices are `points` (ECEF), on the ray
/// from the Earth's centre towards `direction` (ECEF, usually the tile's bounding-sphere
/// centre), in the ellipsoid-scaled frame: the nearest point on the ray that every vertex's
/// horizon plane (the plane tangent to the unit sphere's cone through the vertex) keeps
/// behind, so that whenever a vertex is above the horizon, so is the point. Vertices below
/// the ellipsoid count as on it. A tile that reaches a quarter of the way round the globe
/// from `direction` has no such point; it gets one [`FAR_OCCLUSION_RADII`] out instead.
pub fn horizon_occlusion_point(direction: [f64; 3], points: &[[f64; 3]]) -> [f64; 3] {
    let d = normalize(scaled(direction));
    let mut magnitude: f64 = 0.0;
    for &p in points {
        let sp = scaled(p);
        let len2 = dot(sp, sp);
        let len = len2.sqrt();
        if len == 0.0 {
            continue;
        }
        let dir = [sp[0] / len, sp[1] / len, sp[2] / len];
        let (len2, len) = (len2.max(1.0), len.max(1.0));
        let cos_alpha = dot(dir, d);
        let sin_alpha = norm(cross(dir, d));
        let cos_beta = 1.0 / len;
        let sin_beta = (len2 - 1.0).sqrt() * cos_beta;
        let denominator = cos_alpha * cos_beta - sin_alpha * sin_beta;
        if denominator <= 1.0 / FAR_OCCLUSION_RADII {
            magnitude = FAR_OCCLUSION_RADII;
            break;
        }
        magnitude = magnitude.max(1.0 / denominator);
    }
    let m = magnitude.max(1.0);
    [d[0] * m, d[1] * m, d[2] * m]
}

/// Whether the ellipsoid-scaled point `point` is above the horizon seen from the camera at
/// `camera` (scaled frame, outside the unit sphere): Cesium's
/// `EllipsoidalOccluder.isScaledSpacePointVisible`.
pub fn scaled_point_visible(camera: [f64; 3], point: [f64; 3]) -> bool {
    let vh2 = dot(camera, camera) - 1.0;
    let vt = [
        point[0] - camera[0],
        point[1] - camera[1],
        point[2] - camera[2],
    ];
    let vt_dot_vc = -dot(vt, camera);
    let occluded = if vh2 < 0.0 {
        vt_dot_vc > 0.0
    } else {
        vt_dot_vc > vh2 && vt_dot_vc * vt_dot_vc / dot(vt, vt) > vh2
    };
    !occluded
}

fn dot(a: [f64; 3], b: [f64; 3]) -> f64 {
    a[0] * b[0] + a[1] * b[1] + a[2] * b[2]
}

fn cross(a: [f64; 3], b: [f64; 3]) -> [f64; 3] {
    [
        a[1] * b[2] - a[2] * b[1],
        a[2] * b[0] - a[0] * b[2],
        a[0] * b[1] - a[1] * b[0],
    ]
}

fn norm(a: [f64; 3]) -> f64 {
    dot(a, a).sqrt()
}

fn normalize(a: [f64; 3]) -> [f64; 3] {
    let l = norm(a);
    if l > 0.0 {
        [a[0] / l, a[1] / l, a[2] / l]
    } else {
        [0.0, 0.0, 1.0]
    }
}

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

/// Cesium's geometric error of a level-`z` tile, metres: a 65-sample heightmap over a
/// quarter of the equator at level 0, halved each level.
pub fn geometric_error(z: u8) -> f64 {
    let level_zero = WGS84_A * 2.0 * std::f64::consts::PI * 0.25 / HEIGHTMAP_WIDTH;
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
        // Cesium's level-0 error for the default ellipsoid: about 154 km.
        assert!(
            (geometric_error(0) - 154_134.67).abs() < 1.0,
            "{}",
            geometric_error(0)
        );
        assert_eq!(geometric_error(3), geometric_error(0) / 8.0);
    }

    #[test]
    fn ecef_of_known_points() {
        let close = |a: [f64; 3], b: [f64; 3]| (0..3).all(|k| (a[k] - b[k]).abs() < 1e-6);
        assert!(close(ecef(0.0, 0.0, 0.0), [WGS84_A, 0.0, 0.0]));
        assert!(close(ecef(90.0, 0.0, 100.0), [0.0, WGS84_A + 100.0, 0.0]));
        assert!(close(ecef(0.0, 90.0, 0.0), [0.0, 0.0, WGS84_B]));
        assert!(close(
            ecef(-180.0, -90.0, 10.0),
            [0.0, 0.0, -WGS84_B - 10.0]
        ));
        // 45° N 45° E on the ellipsoid lies on it: (x² + y²)/a² + z²/b² = 1.
        let [x, y, z] = scaled(ecef(45.0, 45.0, 0.0));
        assert!((x * x + y * y + z * z - 1.0).abs() < 1e-12);
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
