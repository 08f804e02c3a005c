//! The WGS 84 ellipsoid as a world frame: geodetic coordinates and Earth-centred,
//! Earth-fixed (ECEF) metres, local east-north-up axes, cameras given as latitude,
//! longitude and height with a heading and pitch, the box that holds a cell of a geographic
//! grid between two heights, and horizon culling.
//!
//! **Why.** A flat frame (`x = col · dx`, `y = row · dy`) is right for a 100 km tile and
//! wrong for a continent: the Earth's curvature drops the ground `d² / 2R` below the tangent
//! plane at distance `d` (785 m at 100 km, 78 km at 1,000 km), and a geographic grid's
//! columns narrow towards the poles. On the globe, a sample `(col, row)` of a geographic grid
//! lies at longitude `lon0 + col · dlon` and latitude `lat0 + row · dlat`, and a height `h`
//! above the ellipsoid puts it at [`ecef`]; distances, and so screen errors, are then true 3D
//! distances.
//!
//! **Boxes.** [`shell_box`] is the exact axis-aligned ECEF box of the shell between heights
//! `h0` and `h1` over a longitude-latitude cell: `z` grows with latitude and height; the
//! distance from the axis, `(N + h) cos φ`, shrinks away from the equator; so each axis's
//! extremes lie at the cell's corners or where it crosses a meridian of 0°, 90°, 180° or
//! 270°. Scenes take these boxes where the flat frame takes its boxes: frustum tests and
//! distances stay conservative.
//!
//! **Horizon culling** (Cesium's ellipsoidal occluder; Ring, "Horizon culling", 2013). In the
//! ellipsoid-scaled frame (ECEF divided by the radii) the ellipsoid is the unit sphere, and a
//! point is hidden from a camera outside it exactly when it lies in the sphere's *shadow*:
//! inside the cone from the camera tangent to the sphere and beyond the plane of the
//! tangency circle ([`scaled_point_hidden`]). The shadow is convex, and moving a hidden point
//! towards the centre keeps it hidden. So a cell's shell is hidden when a lattice over its top
//! (at `max(h1, 0)`), each point lifted by the most the surface can bulge between lattice
//! points, is all in the shadow ([`shell_hidden`]): the lattice and its lifted copy bound the
//! top surface, whose convex hull then lies in the shadow, and everything below it too.
//! Points below the ellipsoid count as on it, as in Cesium. The test never hides a shell with
//! a visible point; it may keep one that is hidden by less than its margin.

use glam::DVec3;

/// The WGS 84 ellipsoid's semi-major axis, metres (Cesium's `maximumRadius`).
pub const WGS84_A: f64 = 6_378_137.0;

/// The WGS 84 ellipsoid's semi-minor (polar) axis, metres (Cesium's `minimumRadius`).
pub const WGS84_B: f64 = 6_356_752.314_245_179;

/// WGS 84's first eccentricity squared, `1 - b²/a²`.
pub const WGS84_E2: f64 = 1.0 - (WGS84_B * WGS84_B) / (WGS84_A * WGS84_A);

/// The least radius of curvature on WGS 84 (the meridian's at the equator, `a (1 - e²)`).
const MIN_CURVATURE_RADIUS: f64 = WGS84_A * (1.0 - WGS84_E2);

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

/// [`ecef`] as a vector.
pub fn ecef_point(lon: f64, lat: f64, h: f64) -> DVec3 {
    DVec3::from(ecef(lon, lat, h))
}

/// The ellipsoid's outward normal (geodetic up) at `lon`, `lat` (degrees), in ECEF.
pub fn up(lon: f64, lat: f64) -> [f64; 3] {
    let (lam, phi) = (lon.to_radians(), lat.to_radians());
    [phi.cos() * lam.cos(), phi.cos() * lam.sin(), phi.sin()]
}

/// Unit east, north and up at `lon`, `lat` (degrees), in ECEF.
pub fn enu(lon: f64, lat: f64) -> [DVec3; 3] {
    let (lam, phi) = (lon.to_radians(), lat.to_radians());
    let east = DVec3::new(-lam.sin(), lam.cos(), 0.0);
    let north = DVec3::new(-phi.sin() * lam.cos(), -phi.sin() * lam.sin(), phi.cos());
    [east, north, DVec3::from(up(lon, lat))]
}

/// Longitude, latitude (degrees) and height of the ECEF point `p` (Bowring's method, then
/// three Newton steps on the latitude: sub-millimetre from the centre's neighbourhood to far
/// beyond orbit). The poles' longitude is 0.
pub fn geodetic(p: DVec3) -> (f64, f64, f64) {
    let r = (p.x * p.x + p.y * p.y).sqrt();
    let lon = if r == 0.0 {
        0.0
    } else {
        p.y.atan2(p.x).to_degrees()
    };
    if r < 1e-9 {
        let h = p.z.abs() - WGS84_B;
        return (lon, if p.z >= 0.0 { 90.0 } else { -90.0 }, h);
    }
    let ep2 = (WGS84_A * WGS84_A - WGS84_B * WGS84_B) / (WGS84_B * WGS84_B);
    let theta = (p.z * WGS84_A).atan2(r * WGS84_B);
    let mut phi = (p.z + ep2 * WGS84_B * theta.sin().powi(3))
        .atan2(r - WGS84_E2 * WGS84_A * theta.cos().powi(3));
    for _ in 0..3 {
        let n = WGS84_A / (1.0 - WGS84_E2 * phi.sin().powi(2)).sqrt();
        phi = (p.z + WGS84_E2 * n * phi.sin()).atan2(r);
    }
    let n = WGS84_A / (1.0 - WGS84_E2 * phi.sin().powi(2)).sqrt();
    let h = if phi.cos().abs() > 1e-3 {
        r / phi.cos() - n
    } else {
        p.z / phi.sin() - n * (1.0 - WGS84_E2)
    };
    (lon, phi.to_degrees(), h)
}

/// An eye at latitude `lat`, longitude `lon` (degrees), height `h` (metres), looking along
/// `heading` (degrees clockwise from north) and `pitch` (degrees above the horizontal, so
/// -90 looks straight down): the eye, a point one kilometre along the view, and the screen's
/// up (ECEF).
pub fn look(lat: f64, lon: f64, h: f64, heading: f64, pitch: f64) -> (DVec3, DVec3, DVec3) {
    let [east, north, upv] = enu(lon, lat);
    let (hd, pt) = (heading.to_radians(), pitch.to_radians());
    let level = north * hd.cos() + east * hd.sin();
    let forward = level * pt.cos() + upv * pt.sin();
    // The screen's up: the local up tilted with the pitch (level looking straight down).
    let screen_up = upv * pt.cos() - level * pt.sin();
    let eye = ecef_point(lon, lat, h);
    (eye, eye + forward * 1000.0, screen_up)
}

/// The radius from the polar axis and the height along it of latitude `lat` at height `h`.
fn radial(lat: f64, h: f64) -> (f64, f64) {
    let phi = lat.to_radians();
    let n = WGS84_A / (1.0 - WGS84_E2 * phi.sin().powi(2)).sqrt();
    ((n + h) * phi.cos(), (n * (1.0 - WGS84_E2) + h) * phi.sin())
}

/// The range of `f(λ)` for `λ` in `[a, b]` degrees, `f` being cos or sin shifted by `shift`
/// (cos: 0, sin: 90): the ends, and every multiple of 180° past the peak inside.
fn trig_range(a: f64, b: f64, shift: f64) -> (f64, f64) {
    if b - a >= 360.0 {
        return (-1.0, 1.0);
    }
    let f = |x: f64| (x - shift).to_radians().cos();
    let (mut lo, mut hi) = (f(a).min(f(b)), f(a).max(f(b)));
    // Peaks (cos = 1) at shift + 360k, troughs (cos = -1) at shift + 180 + 360k.
    let first = ((a - shift) / 180.0).ceil() as i64;
    let last = ((b - shift) / 180.0).floor() as i64;
    for k in first..=last {
        if k.rem_euclid(2) == 0 {
            hi = 1.0;
        } else {
            lo = -1.0;
        }
    }
    (lo, hi)
}

/// The least and greatest corners of the axis-aligned ECEF box that holds every point at
/// longitude `lon_a..=lon_b`, latitude `lat_a..=lat_b` (degrees, any order) and height
/// `h0..=h1` (`h0 <= h1`), padded by a millimetre per thousand kilometres.
pub fn shell_box(
    lon_a: f64,
    lon_b: f64,
    lat_a: f64,
    lat_b: f64,
    h0: f64,
    h1: f64,
) -> (DVec3, DVec3) {
    let (lon0, lon1) = (lon_a.min(lon_b), lon_a.max(lon_b));
    let (lat0, lat1) = (
        lat_a.min(lat_b).clamp(-90.0, 90.0),
        lat_a.max(lat_b).clamp(-90.0, 90.0),
    );
    let (h0, h1) = (h0.min(h1), h0.max(h1));
    // z: increasing in latitude and, at a fixed sign of sin φ, monotone in height.
    let zs = [
        radial(lat0, h0).1,
        radial(lat0, h1).1,
        radial(lat1, h0).1,
        radial(lat1, h1).1,
    ];
    let zmin = zs.iter().copied().fold(f64::INFINITY, f64::min);
    let zmax = zs.iter().copied().fold(f64::NEG_INFINITY, f64::max);
    // Distance from the axis: greatest at the latitude nearest the equator and the top,
    // least at the one farthest from it and the bottom.
    let nearest = 0.0f64.clamp(lat0, lat1);
    let farthest = if lat0.abs() > lat1.abs() { lat0 } else { lat1 };
    let r_max = radial(nearest, h1).0.max(0.0);
    let r_min = radial(farthest, h0).0.max(0.0);
    let axis = |(lo, hi): (f64, f64)| {
        let max = if hi >= 0.0 { r_max * hi } else { r_min * hi };
        let min = if lo >= 0.0 { r_min * lo } else { r_max * lo };
        (min, max)
    };
    let (xmin, xmax) = axis(trig_range(lon0, lon1, 0.0));
    let (ymin, ymax) = axis(trig_range(lon0, lon1, 90.0));
    let pad = 1e-9 * (WGS84_A + h1.abs());
    (
        DVec3::new(xmin - pad, ymin - pad, zmin - pad),
        DVec3::new(xmax + pad, ymax + pad, zmax + pad),
    )
}

/// `p` (ECEF) in the ellipsoid-scaled frame, where WGS 84 is the unit sphere.
pub fn scaled(p: [f64; 3]) -> [f64; 3] {
    [p[0] / WGS84_A, p[1] / WGS84_A, p[2] / WGS84_B]
}

/// Whether the scaled point `point` lies in the unit sphere's shadow seen from the scaled
/// camera `camera`: beyond the horizon plane and inside the tangent cone. A camera inside
/// the sphere hides nothing.
pub fn scaled_point_hidden(camera: DVec3, point: DVec3) -> bool {
    let vh2 = camera.length_squared() - 1.0;
    if vh2 <= 0.0 {
        return false;
    }
    let vt = point - camera;
    let vt_dot_vc = -vt.dot(camera);
    vt_dot_vc > vh2 && vt_dot_vc * vt_dot_vc / vt.length_squared() > vh2
}

/// Lattice points a side of the top of a shell in [`shell_hidden`]: at least this many...
const MIN_LATTICE: usize = 5;
/// ...and at most this many, so that lattice cells stay under [`LATTICE_CELL_DEG`] where
/// they can.
const MAX_LATTICE: usize = 17;
/// The widest lattice cell wanted, in degrees of arc across its diagonal.
const LATTICE_CELL_DEG: f64 = 0.25;

/// The lattice over a shell's top that [`shell_hidden`] looks at, and how far each of its
/// points is lifted: `(points a side, margin in metres)`, or `None` for a cell too large
/// for the construction (never hidden). The margin is twice the most the surface can rise
/// above a chord across one lattice cell (its diagonal, where the cell is widest, over the
/// ellipsoid's least radius of curvature), plus a millimetre.
pub fn horizon_lattice(
    lon_a: f64,
    lon_b: f64,
    lat_a: f64,
    lat_b: f64,
    h1: f64,
) -> Option<(usize, f64)> {
    let (lon0, lon1) = (lon_a.min(lon_b), lon_a.max(lon_b));
    let (lat0, lat1) = (
        lat_a.min(lat_b).clamp(-90.0, 90.0),
        lat_a.max(lat_b).clamp(-90.0, 90.0),
    );
    let widest = 0.0f64.clamp(lat0, lat1).to_radians().cos();
    let across = ((lon1 - lon0) * widest).hypot(lat1 - lat0);
    let k = ((across / LATTICE_CELL_DEG).ceil() as usize + 1).clamp(MIN_LATTICE, MAX_LATTICE);
    let delta = (across / (k - 1) as f64).to_radians();
    if delta > 0.5 {
        return None;
    }
    let top = h1.max(0.0);
    let chord = (WGS84_A + top) * delta;
    Some((
        k,
        2.0 * chord * chord / (8.0 * MIN_CURVATURE_RADIUS) + 1e-3 + 1e-9 * top,
    ))
}

/// Whether every point of the shell over longitude `lon_a..=lon_b`, latitude
/// `lat_a..=lat_b` (degrees) up to height `h1` is below the horizon seen from `eye` (ECEF):
/// every point of [`horizon_lattice`]'s lattice over its top, lifted by its margin, is; see
/// the module's notes. A cell too large for the construction is never hidden.
pub fn shell_hidden(eye: DVec3, lon_a: f64, lon_b: f64, lat_a: f64, lat_b: f64, h1: f64) -> bool {
    let camera = DVec3::from(scaled(eye.to_array()));
    if camera.length_squared() <= 1.0 {
        return false;
    }
    let Some((k, margin)) = horizon_lattice(lon_a, lon_b, lat_a, lat_b, h1) else {
        return false;
    };
    let (lon0, lon1) = (lon_a.min(lon_b), lon_a.max(lon_b));
    let (lat0, lat1) = (
        lat_a.min(lat_b).clamp(-90.0, 90.0),
        lat_a.max(lat_b).clamp(-90.0, 90.0),
    );
    let n = (k - 1) as f64;
    let (dlon, dlat) = ((lon1 - lon0) / n, (lat1 - lat0) / n);
    let top = h1.max(0.0) + margin;
    for i in 0..k {
        for j in 0..k {
            let lon = lon0 + dlon * i as f64;
            let lat = lat0 + dlat * j as f64;
            let p = DVec3::from(scaled(ecef(lon, lat, top)));
            if !scaled_point_hidden(camera, p) {
                return false;
            }
        }
    }
    true
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
    let d = DVec3::from(scaled(direction)).normalize_or(DVec3::Z);
    let mut magnitude: f64 = 0.0;
    for &p in points {
        let sp = DVec3::from(scaled(p));
        let len2 = sp.length_squared();
        let len = len2.sqrt();
        if len == 0.0 {
            continue;
        }
        let dir = sp / len;
        let (len2, len) = (len2.max(1.0), len.max(1.0));
        let cos_alpha = dir.dot(d);
        let sin_alpha = dir.cross(d).length();
        let cos_beta = 1.0 / len;
        let sin_beta = (len2 - 1.0).sqrt() * cos_beta;
        let denominator = cos_alpha * cos_beta - sin_alpha * sin_beta;
        if denominator <= 1.0 / FAR_OCCLUSION_RADII {
            magnitude = FAR_OCCLUSION_RADII;
            break;
        }
        magnitude = magnitude.max(1.0 / denominator);
    }
    (d * magnitude.max(1.0)).to_array()
}

/// Whether the ellipsoid-scaled point `point` is above the horizon seen from the camera at
/// `camera` (scaled frame): Cesium's `EllipsoidalOccluder.isScaledSpacePointVisible`.
#[cfg(any(test, feature = "testing"))]
pub fn scaled_point_visible(camera: [f64; 3], point: [f64; 3]) -> bool {
    let (c, p) = (DVec3::from(camera), DVec3::from(point));
    let vh2 = c.length_squared() - 1.0;
    let vt = p - c;
    let vt_dot_vc = -vt.dot(c);
    let occluded = if vh2 < 0.0 {
        vt_dot_vc > 0.0
    } else {
        vt_dot_vc > vh2 && vt_dot_vc * vt_dot_vc / vt.length_squared() > vh2
    };
    !occluded
}

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;

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

    #[test]
    fn looking_north_level_and_straight_down() {
        // On the equator at 0°: east is +y, north +z, up +x.
        let (eye, target, screen_up) = look(0.0, 0.0, 100.0, 0.0, 0.0);
        let f = (target - eye).normalize();
        assert!((f - DVec3::Z).length() < 1e-12 && (screen_up - DVec3::X).length() < 1e-12);
        let (eye, target, screen_up) = look(0.0, 0.0, 100.0, 90.0, -90.0);
        let f = (target - eye).normalize();
        assert!((f + DVec3::X).length() < 1e-12, "{f}");
        // Looking down with heading east, the screen's up points east.
        assert!((screen_up - DVec3::Y).length() < 1e-12, "{screen_up}");
    }

    #[test]
    fn shell_boxes_reach_past_the_cell_where_meridians_cross() {
        // A cell across the prime meridian on the equator: x peaks inside it.
        let (lo, hi) = shell_box(-1.0, 1.0, -1.0, 1.0, 0.0, 100.0);
        assert!((hi.x - (WGS84_A + 100.0)).abs() < 1.0, "{hi}");
        assert!(lo.y < 0.0 && hi.y > 0.0 && lo.z < 0.0 && hi.z > 0.0);
        // Across the antimeridian as 179..181: x is least at 180°.
        let (lo, _) = shell_box(179.0, 181.0, 10.0, 11.0, 0.0, 0.0);
        let r10 = radial(10.0, 0.0).0;
        assert!((lo.x + r10).abs() < 1.0, "{lo}");
        // A polar cap: the axis passes through it.
        let (lo, hi) = shell_box(-180.0, 180.0, 89.0, 90.0, 0.0, 0.0);
        assert!(lo.x < 0.0 && hi.x > 0.0 && (hi.z - WGS84_B).abs() < 1.0);
    }

    proptest! {
        /// ECEF and back gives the point again, pole to pole, far below and far above.
        #[test]
        fn geodetic_inverts_ecef(lon in -179.999f64..179.999, lat in -90.0f64..90.0, h in -10_000.0f64..4.0e7) {
            let (lo, la, hh) = geodetic(ecef_point(lon, lat, h));
            prop_assert!((la - lat).abs() < 1e-9, "{lat} -> {la}");
            prop_assert!((hh - h).abs() < 1e-4 * (1.0 + h.abs() / 1e7), "{h} -> {hh}");
            if lat.abs() < 89.999 {
                prop_assert!((lo - lon).abs() < 1e-9, "{lon} -> {lo}");
            }
        }

        /// Every point of a shell lies in its box, and the box is tight: each face is
        /// within a fraction of the cell of some point of it.
        #[test]
        fn shell_boxes_hold_their_shells(
            lon in -200.0f64..200.0, dlon in 0.0f64..120.0,
            lat in -90.0f64..90.0, dlat in 0.0f64..60.0,
            h0 in -500.0f64..9000.0, dh in 0.0f64..5000.0,
        ) {
            let lat1 = (lat + dlat).min(90.0);
            let (lo, hi) = shell_box(lon, lon + dlon, lat, lat1, h0, h0 + dh);
            let n = 24;
            let (mut plo, mut phi) = (DVec3::splat(f64::INFINITY), DVec3::splat(f64::NEG_INFINITY));
            for i in 0..=n {
                for j in 0..=n {
                    for h in [h0, h0 + dh] {
                        let p = ecef_point(lon + dlon * i as f64 / n as f64, lat + (lat1 - lat) * j as f64 / n as f64, h);
                        prop_assert!(p.cmpge(lo).all() && p.cmple(hi).all(), "{p} outside {lo}..{hi}");
                        plo = plo.min(p);
                        phi = phi.max(p);
                    }
                }
            }
            // The lattice misses the box's faces by at most the bulge between its points.
            let step = (dlon.max(lat1 - lat) / n as f64).to_radians();
            let slack = 2.0 * WGS84_A * (1.0 - (step / 2.0).cos()) + WGS84_A * step * step + 1.0;
            prop_assert!((plo - lo).max_element() <= slack && (hi - phi).max_element() <= slack,
                "{lo}..{hi} against the lattice's {plo}..{phi} (slack {slack})");
        }

        /// A hidden shell has no visible point: not at its top, not below it, not between
        /// the lattice points the test looks at; from any camera outside the ellipsoid.
        #[test]
        fn hidden_shells_have_no_visible_point(
            lon in -180.0f64..180.0, dlon in 0.0f64..20.0,
            lat in -89.0f64..89.0, dlat in 0.0f64..10.0,
            h1 in -300.0f64..8000.0,
            cam_lon in -180.0f64..180.0, cam_lat in -90.0f64..90.0, cam_h in 1.0f64..4.0e7,
        ) {
            let lat1 = (lat + dlat).min(90.0);
            let eye = ecef_point(cam_lon, cam_lat, cam_h);
            if shell_hidden(eye, lon, lon + dlon, lat, lat1, h1) {
                let camera = DVec3::from(scaled(eye.to_array()));
                let n = 32;
                for i in 0..=n {
                    for j in 0..=n {
                        for h in [h1, h1 * 0.5, 0.0] {
                            let p = ecef(lon + dlon * i as f64 / n as f64, lat + (lat1 - lat) * j as f64 / n as f64, h.max(0.0));
                            prop_assert!(scaled_point_hidden(camera, DVec3::from(scaled(p))),
                                "a visible point of a hidden shell from {cam_lon},{cam_lat},{cam_h}");
                        }
                    }
                }
            }
        }
    }

    proptest! {
        /// The same, with the camera set so that the horizon passes near the cell: due
        /// south of it along its middle meridian, at about the horizon's distance for its
        /// height, where a test of the corners alone would hide the cell's bulging middle.
        #[test]
        fn hidden_shells_near_the_limb_have_no_visible_point(
            lon in -180.0f64..180.0, dlon in 0.5f64..40.0,
            lat in -60.0f64..60.0, dlat in 0.5f64..20.0,
            h1 in 0.0f64..8000.0, cam_h in 1000.0f64..4.0e7, off in -3.0f64..3.0,
        ) {
            let lat1 = (lat + dlat).min(89.0);
            let horizon = (WGS84_A / (WGS84_A + cam_h)).acos().to_degrees();
            let cam_lat = lat - horizon - off;
            prop_assume!(cam_lat > -89.0);
            let eye = ecef_point(lon + dlon / 2.0, cam_lat, cam_h);
            if shell_hidden(eye, lon, lon + dlon, lat, lat1, h1) {
                let camera = DVec3::from(scaled(eye.to_array()));
                let n = 48;
                for i in 0..=n {
                    for j in 0..=n {
                        let p = ecef(lon + dlon * i as f64 / n as f64, lat + (lat1 - lat) * j as f64 / n as f64, h1);
                        prop_assert!(scaled_point_hidden(camera, DVec3::from(scaled(p))),
                            "a visible point of a hidden shell at {i},{j}");
                    }
                }
            }
        }
    }

    /// The shell test does hide things: the far side of the Earth from low orbit.
    #[test]
    fn the_far_side_is_hidden() {
        let eye = ecef_point(0.0, 0.0, 400_000.0);
        assert!(shell_hidden(eye, 179.0, 180.0, -1.0, 0.0, 8000.0));
        assert!(shell_hidden(eye, 30.0, 31.0, 0.0, 1.0, 8000.0));
        assert!(!shell_hidden(eye, 10.0, 11.0, 0.0, 1.0, 0.0));
        // From inside the ellipsoid nothing is hidden.
        assert!(!shell_hidden(
            ecef_point(0.0, 0.0, -10.0),
            179.0,
            180.0,
            0.0,
            1.0,
            0.0
        ));
    }
}
