//! The camera, and the little geometry a scene needs from it: the view frustum, how many
//! pixels a metre covers at a distance, and distances to boxes.
//!
//! **World frame.** `x = col · dx` (east), `y = row · dy` (south), `z = height`, all in metres;
//! `dx`, `dy` are the dataset's ground spacing (1 when the source did not say). Sample `(0, 0)`
//! is the origin; the georeference is not applied, so coordinates stay small and exact. With
//! `y` growing south and `z` up the frame is **left-handed**: `x × y = z` does not hold, and the
//! screen's right is `up × forward`, not the `forward × up` of a right-handed frame (ECEF,
//! glTF, OpenGL). A camera carries its frame's [`Handedness`], and [`View`] is the one place
//! that turns a camera into a screen basis and a pixel: the pictures, the
//! meshes' refinement and the selection all take it from there. (Before issue 40 the
//! right was taken as `forward × up` in the flat frame too, which mirrored every perspective
//! picture east-west; culling is symmetric, so the selection never depended on it.)
//!
//! **Screen-space error** (seed 004 eq. 2). A vertical error `e` seen at distance `d` covers
//! `e · λ / d` pixels, with `λ = S / (2 · tan(fov_y / 2))` and `S` the viewport's height in
//! pixels. Seed 000's eq. 2 is the same relation solved for the error: `ε = τ / λ · P_min`.
//!
//! **On the globe** ([`TerrainFrame::Globe`]) a geographic grid's samples are placed on the
//! WGS 84 ellipsoid instead, in Earth-centred, Earth-fixed metres, and the camera is given in
//! the same frame: every box below is then the ECEF box of a cell's shell, and distances are
//! true 3D distances.
//!
//! **Frustum.** The four side planes through the eye (no near or far plane: a terrain viewer
//! wants everything in front of it). A point is visible when it is on the inner side of all
//! four, which also puts it in front of the eye because the field of view is below 180°.

use glam::DVec3;

use crate::error::{Error, Result};

/// Vertical field of view used when none is given, in degrees.
pub const DEFAULT_FOV_DEG: f64 = 60.0;
/// Viewport used when none is given, in pixels.
pub const DEFAULT_VIEWPORT: [u32; 2] = [1024, 768];
/// The largest viewport side accepted, in pixels.
pub const MAX_VIEWPORT: u32 = 1 << 16;

/// The largest camera coordinate accepted, in metres: a thousand times the Earth's orbit,
/// far past any terrain, and small enough that differences of coordinates stay finite
/// and keep millimetres near the terrain.
pub const MAX_COORDINATE: f64 = 1e12;

/// Which way round a world frame's axes turn: it decides which side of the screen is right.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Handedness {
    /// `x` east, `y` south, `z` up: the flat terrain frame (`WorldFrame`). The screen's
    /// right is `up × forward`.
    Left,
    /// Earth-centred, Earth-fixed metres (`GlobeFrame`), like glTF's and OpenGL's frames.
    /// The screen's right is `forward × up`.
    Right,
}

/// A pinhole camera in the world frame.
///
/// ```
/// use fmrh::glam::DVec3;
/// use fmrh::Camera;
///
/// // 2 km south-west of the data's north-west corner, 900 m up, looking at a point 5 km in.
/// let camera = Camera {
///     viewport: [1920, 1080],
///     fov_y_deg: 45.0,
///     ..Camera::looking_at(DVec3::new(-2000.0, -2000.0, 900.0), DVec3::new(5000.0, 5000.0, 0.0))
/// };
/// assert!(camera.view().is_ok());
/// // On the globe: 45° N, 7° E, 3 km above the ellipsoid, looking east and 20° down.
/// let on_globe = Camera::on_globe(45.0, 7.0, 3000.0, 90.0, -20.0);
/// assert!(on_globe.eye.length() > 6.3e6);
/// ```
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Camera {
    /// Where the eye is.
    pub eye: DVec3,
    /// A point the camera looks at.
    pub target: DVec3,
    /// Which way is up on the screen. When it is parallel to the view direction (looking
    /// straight down with `up = +z`), the world axis least aligned with the view is used
    /// instead: north (`-y`), then east (`+x`).
    pub up: DVec3,
    /// Vertical field of view in degrees, strictly between 0 and 180.
    pub fov_y_deg: f64,
    /// Viewport `[width, height]` in pixels.
    pub viewport: [u32; 2],
    /// The handedness of the frame `eye`, `target` and `up` are given in: [`Handedness::Left`]
    /// in a flat terrain frame ([`Camera::looking_at`]), [`Handedness::Right`] on the globe
    /// ([`Camera::on_globe`]). Only pictures depend on it: the frustum is symmetric.
    pub handedness: Handedness,
}

impl Camera {
    /// A camera at `eye` looking at `target` in a flat terrain frame (x east, y south, z
    /// up), `+z` up, 60° vertical field of view, 1024 × 768.
    pub fn looking_at(eye: DVec3, target: DVec3) -> Camera {
        Camera {
            eye,
            target,
            up: DVec3::Z,
            fov_y_deg: DEFAULT_FOV_DEG,
            viewport: DEFAULT_VIEWPORT,
            handedness: Handedness::Left,
        }
    }

    /// A camera on the globe: the eye at latitude `lat` and
    /// longitude `lon` (degrees), `h` metres above the WGS 84 ellipsoid, looking along
    /// `heading` (degrees clockwise from north) and `pitch` (degrees above the horizontal), in
    /// ECEF metres; 60° vertical field of view, 1024 × 768.
    pub fn on_globe(lat: f64, lon: f64, h: f64, heading: f64, pitch: f64) -> Camera {
        let (eye, target, up) = crate::globe::look(lat, lon, h, heading, pitch);
        Camera {
            up,
            handedness: Handedness::Right,
            ..Camera::looking_at(eye, target)
        }
    }

    /// Checks the camera and derives its view geometry. Non-finite input, a target equal to
    /// the eye, a zero up vector, a field of view outside (0°, 180°) or an empty viewport is an
    /// [`Error::InvalidArgument`].
    pub fn view(&self) -> Result<View> {
        let bad = |what: String| Err(Error::InvalidArgument(format!("camera: {what}")));
        for (name, v) in [("eye", self.eye), ("target", self.target), ("up", self.up)] {
            if !v.is_finite() {
                return bad(format!("{name} {v} is not finite"));
            }
        }
        if !self.fov_y_deg.is_finite() || self.fov_y_deg <= 0.0 || self.fov_y_deg >= 180.0 {
            return bad(format!(
                "field of view {}° must lie strictly between 0 and 180",
                self.fov_y_deg
            ));
        }
        let [w, h] = self.viewport;
        if w == 0 || h == 0 || w > MAX_VIEWPORT || h > MAX_VIEWPORT {
            return bad(format!(
                "viewport {w}x{h}: each side must be 1 to {MAX_VIEWPORT} pixels"
            ));
        }
        for (name, p) in [("eye", self.eye), ("target", self.target)] {
            if p.abs().max_element() > MAX_COORDINATE {
                return bad(format!(
                    "camera coordinates out of range: the {name} is at ({}, {}, {}); each \
                     coordinate must be within ±{MAX_COORDINATE:e} m",
                    p.x, p.y, p.z
                ));
            }
        }
        let forward = (self.target - self.eye).normalize_or_zero();
        if forward == DVec3::ZERO || !forward.is_finite() {
            return bad("the target must differ from the eye".into());
        }
        if self.up.length_squared() == 0.0 {
            return bad("the up vector is zero".into());
        }
        // The screen's up is `up` made perpendicular to the view; where `up` is along it
        // (looking straight down with `+z` up), north, then east.
        let screen_up = [self.up, -DVec3::Y, DVec3::X]
            .into_iter()
            .map(|up| {
                let up = up.normalize();
                up - forward * up.dot(forward)
            })
            .find(|u| u.length() > 1e-9)
            .map(DVec3::normalize)
            .unwrap_or(DVec3::Z);
        let right = match self.handedness {
            Handedness::Left => screen_up.cross(forward),
            Handedness::Right => forward.cross(screen_up),
        }
        .normalize();
        let tan_y = (self.fov_y_deg.to_radians() / 2.0).tan();
        let tan_x = tan_y * f64::from(w) / f64::from(h);
        if !(tan_y.is_finite() && tan_x.is_finite() && tan_y > 0.0) {
            return bad(format!("field of view {}° is degenerate", self.fov_y_deg));
        }
        // Corner rays, as the screen shows them: top-left, bottom-left, bottom-right,
        // top-right.
        let rays = [
            forward - right * tan_x + screen_up * tan_y,
            forward - right * tan_x - screen_up * tan_y,
            forward + right * tan_x - screen_up * tan_y,
            forward + right * tan_x + screen_up * tan_y,
        ];
        let mut planes = [Plane::default(); 4];
        for (i, plane) in planes.iter_mut().enumerate() {
            let n = rays[i].cross(rays[(i + 1) % 4]).normalize_or_zero();
            let n = if n.dot(forward) < 0.0 { -n } else { n };
            *plane = Plane {
                normal: n,
                offset: -n.dot(self.eye),
            };
        }
        // Separating-axis candidates besides the box's own normals: each box edge direction
        // crossed with each corner ray. Where the cone projects onto a half-line, record which.
        let mut axes = Vec::with_capacity(12);
        for e in [DVec3::X, DVec3::Y, DVec3::Z] {
            for r in &rays {
                let axis = e.cross(*r);
                if axis.length_squared() > 0.0 {
                    axes.push(ConeAxis::new(axis, self.eye, &rays));
                }
            }
        }
        for e in [DVec3::X, DVec3::Y, DVec3::Z] {
            axes.push(ConeAxis::new(e, self.eye, &rays));
        }
        Ok(View {
            eye: self.eye,
            forward,
            right,
            up: screen_up,
            centre: [f64::from(w) / 2.0, f64::from(h) / 2.0],
            lambda: f64::from(h) / (2.0 * tan_y),
            planes,
            rays,
            axes,
        })
    }
}

/// A plane `normal · p + offset = 0`; the inner side is where the expression is `>= 0`.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct Plane {
    /// Unit normal, pointing inside.
    pub normal: DVec3,
    /// `-normal · (a point of the plane)`.
    pub offset: f64,
}

/// An axis-aligned box in the world frame.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Aabb {
    /// Least corner.
    pub min: DVec3,
    /// Greatest corner.
    pub max: DVec3,
}

impl Aabb {
    /// The distance from `p` to the nearest point of the box (0 inside).
    pub fn distance(&self, p: DVec3) -> f64 {
        (p - p.clamp(self.min, self.max)).length()
    }

    /// The distance from `p` to the farthest point of the box.
    pub fn max_distance(&self, p: DVec3) -> f64 {
        let far = DVec3::select(
            (p - self.min).abs().cmpge((p - self.max).abs()),
            self.min,
            self.max,
        );
        (p - far).length()
    }
}

/// How a box lies against the frustum.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Coverage {
    /// Entirely outside.
    Outside,
    /// Partly inside, or possibly so.
    Partial,
    /// Entirely inside.
    Inside,
}

/// A separating-axis candidate and the frustum's projection onto it.
#[derive(Clone, Copy, Debug, PartialEq)]
struct ConeAxis {
    axis: DVec3,
    /// The eye's projection: the cone's end point on this axis.
    apex: f64,
    /// +1: the cone projects onto `[apex, +inf)`; -1: onto `(-inf, apex]`; 0: the whole line
    /// (this axis never separates).
    side: i8,
}

impl ConeAxis {
    fn new(axis: DVec3, eye: DVec3, rays: &[DVec3; 4]) -> ConeAxis {
        let dirs = rays.map(|r| axis.dot(r));
        let side = if dirs.iter().all(|&d| d >= 0.0) {
            1
        } else if dirs.iter().all(|&d| d <= 0.0) {
            -1
        } else {
            0
        };
        ConeAxis {
            axis,
            apex: axis.dot(eye),
            side,
        }
    }
}

/// A checked camera's view geometry.
#[derive(Clone, Debug, PartialEq)]
pub struct View {
    /// The eye.
    pub eye: DVec3,
    /// Unit view direction.
    pub forward: DVec3,
    /// Unit direction of the screen's right, perpendicular to `forward`.
    pub right: DVec3,
    /// Unit direction of the screen's up, perpendicular to `forward` and `right`.
    pub up: DVec3,
    /// The viewport's centre in pixels from its top-left corner: where `forward` lands.
    pub centre: [f64; 2],
    /// Pixels covered by one metre at one metre: `S / (2 · tan(fov_y / 2))`.
    pub lambda: f64,
    /// The four side planes.
    pub planes: [Plane; 4],
    /// The four corner rays (not unit length).
    pub rays: [DVec3; 4],
    axes: Vec<ConeAxis>,
}

impl View {
    /// Where world point `p` lands on the screen: `[x, y, depth]`, `x` pixels from the
    /// viewport's left edge, `y` down from its top, `depth` metres along the view. `None`
    /// for a point not in front of the eye (depth ≤ 0). Every picture projects with this.
    pub fn project(&self, p: DVec3) -> Option<[f64; 3]> {
        let d = p - self.eye;
        let depth = d.dot(self.forward);
        (depth > 0.0).then(|| {
            [
                self.centre[0] + self.lambda * d.dot(self.right) / depth,
                self.centre[1] - self.lambda * d.dot(self.up) / depth,
                depth,
            ]
        })
    }

    /// Screen-space error in pixels of a static error `error` whose box is at `distance`.
    /// Zero error is zero pixels at any distance; a positive error at distance 0 is infinite.
    pub fn screen_error(&self, error: f64, distance: f64) -> f64 {
        if error == 0.0 {
            0.0
        } else {
            error * self.lambda / distance
        }
    }

    /// The largest static error whose screen-space error stays within `tau` pixels at
    /// `distance` (seed 000 eq. 2: `ε = τ / λ · P_min`).
    pub fn allowed_error(&self, tau: f64, distance: f64) -> f64 {
        tau / self.lambda * distance
    }

    /// A conservative classification of `b` by the plane test: `Outside` is certain,
    /// `Partial` may be a box that misses the frustum near its edges.
    pub fn classify(&self, b: &Aabb) -> Coverage {
        let (centre, half) = ((b.min + b.max) * 0.5, (b.max - b.min) * 0.5);
        let mut inside_all = true;
        for p in &self.planes {
            let s = p.normal.dot(centre) + p.offset;
            let r = p.normal.abs().dot(half);
            if s + r < 0.0 {
                return Coverage::Outside;
            }
            inside_all &= s - r >= 0.0;
        }
        if inside_all {
            Coverage::Inside
        } else {
            Coverage::Partial
        }
    }

    /// Whether `b` meets the frustum, exactly: the separating-axis test between the box and
    /// the frustum's cone (face normals of both, and every box edge crossed with every corner
    /// ray). A closed box touching the frustum's boundary meets it.
    pub fn intersects(&self, b: &Aabb) -> bool {
        match self.classify(b) {
            Coverage::Outside => return false,
            Coverage::Inside => return true,
            Coverage::Partial => {}
        }
        if b.distance(self.eye) == 0.0 {
            return true;
        }
        let (centre, half) = ((b.min + b.max) * 0.5, (b.max - b.min) * 0.5);
        !self.axes.iter().any(|a| {
            let c = a.axis.dot(centre);
            let r = a.axis.abs().dot(half);
            match a.side {
                1 => c + r < a.apex,
                -1 => c - r > a.apex,
                _ => false,
            }
        })
    }
}

/// Ground spacing of the world frame, in metres per sample step.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct WorldFrame {
    /// Metres from one column to the next (east).
    pub dx: f64,
    /// Metres from one row to the next (south).
    pub dy: f64,
}

impl WorldFrame {
    /// The frame of a dataset whose spacing is `spacing_m` (1 m when unknown or unusable).
    pub fn new(spacing_m: Option<[f64; 2]>) -> WorldFrame {
        let ok = |v: f64| v.is_finite() && v > 0.0;
        match spacing_m {
            Some([dx, dy]) if ok(dx.abs()) && ok(dy.abs()) => WorldFrame {
                dx: dx.abs(),
                dy: dy.abs(),
            },
            _ => WorldFrame { dx: 1.0, dy: 1.0 },
        }
    }

    /// The world point of sample `(col, row)` at height `z`.
    pub fn point(&self, col: f64, row: f64, z: f64) -> DVec3 {
        DVec3::new(col * self.dx, row * self.dy, z)
    }
}

/// A geographic grid on the WGS 84 ellipsoid: sample `(col, row)` at longitude `lon0 + col ·
/// dlon` and latitude `lat0 + row · dlat` (degrees), the world frame being ECEF metres
/// ([`crate::globe`]).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct GlobeFrame {
    /// Longitude of sample column 0, degrees.
    pub lon0: f64,
    /// Latitude of sample row 0, degrees.
    pub lat0: f64,
    /// Degrees of longitude from one column to the next (east).
    pub dlon: f64,
    /// Degrees of latitude from one row to the next (negative for a north-up grid).
    pub dlat: f64,
    /// Heights are above the EGM96 geoid: each is placed `N` higher, on the ellipsoid.
    pub geoid: bool,
}

impl GlobeFrame {
    /// The frame of a georeference whose CRS is geographic (longitude and latitude in
    /// degrees); an error otherwise: a projected grid is not placed on the globe yet.
    pub fn of(g: &crate::heightfield::Georeference) -> Result<GlobeFrame> {
        let name = g.crs.as_deref().unwrap_or("");
        let geographic =
            crate::crs::Crs::parse(name).is_some_and(|c| c.kind == crate::crs::CrsKind::Geographic);
        let finite = g.origin.iter().chain(&g.step).all(|v| v.is_finite())
            && g.step[0] != 0.0
            && g.step[1] != 0.0;
        if !geographic || !finite {
            return Err(Error::InvalidArgument(format!(
                "the globe frame needs a geographic grid (longitude and latitude, e.g. \
                 EPSG:4326); this one is `{name}` with origin {:?} and step {:?}",
                g.origin, g.step
            )));
        }
        Ok(GlobeFrame {
            lon0: g.origin[0],
            lat0: g.origin[1],
            dlon: g.step[0],
            dlat: g.step[1],
            geoid: false,
        })
    }

    /// This frame with heights above `datum` placed on the ellipsoid: EGM96 heights `N`
    /// higher. An error for a datum fmrh cannot place (EGM2008: no grid of it is bundled).
    pub fn with_datum(self, datum: crate::geoid::VerticalDatum) -> Result<GlobeFrame> {
        let lift = datum.lift().map_err(|why| {
            Error::InvalidArgument(format!("the terrain cannot be placed on the globe: {why}"))
        })?;
        Ok(GlobeFrame {
            geoid: lift == crate::geoid::Lift::Egm96,
            ..self
        })
    }

    /// The least and greatest amount heights over the box between `(lon_a, lat_a)` and
    /// `(lon_b, lat_b)` are raised by to place them on the ellipsoid.
    fn lift_range(&self, lon_a: f64, lon_b: f64, lat_a: f64, lat_b: f64) -> (f64, f64) {
        if self.geoid {
            crate::geoid::egm96_range(lon_a, lon_b, lat_a, lat_b)
        } else {
            (0.0, 0.0)
        }
    }

    /// The same grid counted from sample `(col, row)`: where a tile starting there lies.
    pub fn at_sample(&self, col: u64, row: u64) -> GlobeFrame {
        let (lon0, lat0) = self.lon_lat(col as f64, row as f64);
        GlobeFrame {
            lon0,
            lat0,
            ..*self
        }
    }

    /// Longitude and latitude of sample position `(col, row)`, degrees.
    pub fn lon_lat(&self, col: f64, row: f64) -> (f64, f64) {
        (self.lon0 + col * self.dlon, self.lat0 + row * self.dlat)
    }

    /// The ECEF point of sample position `(col, row)` at height `z`.
    pub fn point(&self, col: f64, row: f64, z: f64) -> DVec3 {
        let (lon, lat) = self.lon_lat(col, row);
        let lat = lat.clamp(-90.0, 90.0);
        let lift = if self.geoid {
            crate::geoid::egm96_undulation(lat, lon)
        } else {
            0.0
        };
        crate::globe::ecef_point(lon, lat, z + lift)
    }

    /// The ECEF box holding samples `rect` (closed, between its grid lines) between heights
    /// `zmin` and `zmax`.
    pub fn rect_box(&self, rect: &crate::model::SampleRect, zmin: f64, zmax: f64) -> Aabb {
        let (lon_a, lat_a) = self.lon_lat(rect.col0 as f64, rect.row0 as f64);
        let (lon_b, lat_b) = self.lon_lat(rect.col1 as f64, rect.row1 as f64);
        let (lo, hi) = self.lift_range(lon_a, lon_b, lat_a, lat_b);
        let (min, max) =
            crate::globe::shell_box(lon_a, lon_b, lat_a, lat_b, zmin + lo, zmax + hi);
        Aabb { min, max }
    }

    /// Whether everything over samples `rect` up to height `zmax` is below the horizon seen
    /// from `eye` ([`crate::globe::shell_hidden`]).
    pub fn hidden(&self, eye: DVec3, rect: &crate::model::SampleRect, zmax: f64) -> bool {
        let (lon_a, lat_a) = self.lon_lat(rect.col0 as f64, rect.row0 as f64);
        let (lon_b, lat_b) = self.lon_lat(rect.col1 as f64, rect.row1 as f64);
        let (_, hi) = self.lift_range(lon_a, lon_b, lat_a, lat_b);
        crate::globe::shell_hidden(eye, lon_a, lon_b, lat_a, lat_b, zmax + hi)
    }
}

/// Where a terrain's samples are in the world: a flat frame, or on the globe.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum TerrainFrame {
    /// `x = col · dx` east, `y = row · dy` south, `z` up: right for a tile, not a continent.
    Flat(WorldFrame),
    /// ECEF on WGS 84, from a geographic grid: distances are true 3D distances over the
    /// curved Earth, and what is below the horizon is culled.
    Globe(GlobeFrame),
}

impl TerrainFrame {
    /// The world point of sample `(col, row)` at height `z`.
    pub fn point(&self, col: f64, row: f64, z: f64) -> DVec3 {
        match self {
            TerrainFrame::Flat(f) => f.point(col, row, z),
            TerrainFrame::Globe(g) => g.point(col, row, z),
        }
    }

    /// The box of samples `rect` between heights `zmin` and `zmax`.
    pub fn rect_box(&self, rect: &crate::model::SampleRect, zmin: f64, zmax: f64) -> Aabb {
        match self {
            TerrainFrame::Flat(f) => Aabb {
                min: f.point(rect.col0 as f64, rect.row0 as f64, zmin),
                max: f.point(rect.col1 as f64, rect.row1 as f64, zmax),
            },
            TerrainFrame::Globe(g) => g.rect_box(rect, zmin, zmax),
        }
    }

    /// Whether all of samples `rect` up to height `zmax` is below the horizon from `eye`
    /// (never, in a flat frame).
    pub fn hidden(&self, eye: DVec3, rect: &crate::model::SampleRect, zmax: f64) -> bool {
        match self {
            TerrainFrame::Flat(_) => false,
            TerrainFrame::Globe(g) => g.hidden(eye, rect, zmax),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn cam(eye: [f64; 3], target: [f64; 3]) -> Camera {
        Camera::looking_at(DVec3::from(eye), DVec3::from(target))
    }

    #[test]
    fn bad_cameras_are_refused() {
        let ok = cam([0.0, 0.0, 10.0], [1.0, 1.0, 0.0]);
        assert!(ok.view().is_ok());
        let mut c = ok;
        c.eye.x = f64::NAN;
        assert!(c.view().is_err());
        c = ok;
        c.target.z = f64::INFINITY;
        assert!(c.view().is_err());
        c = ok;
        c.target = c.eye;
        assert!(c.view().is_err());
        for fov in [0.0, -1.0, 180.0, 200.0, f64::NAN] {
            c = ok;
            c.fov_y_deg = fov;
            assert!(c.view().is_err(), "{fov}");
        }
        c = ok;
        c.viewport = [0, 10];
        assert!(c.view().is_err());
        c = ok;
        c.up = DVec3::ZERO;
        assert!(c.view().is_err());
    }

    #[test]
    fn straight_down_uses_north_up() {
        let v = cam([5.0, 5.0, 10.0], [5.0, 5.0, 0.0]).view().unwrap();
        assert!(v.planes.iter().all(|p| p.normal.is_finite()));
        // The point below the eye is inside, one far to the side is not.
        let below = Aabb {
            min: DVec3::new(4.9, 4.9, 0.0),
            max: DVec3::new(5.1, 5.1, 0.0),
        };
        assert_eq!(v.classify(&below), Coverage::Inside);
        let aside = Aabb {
            min: DVec3::new(100.0, 100.0, 0.0),
            max: DVec3::new(101.0, 101.0, 0.0),
        };
        assert!(!v.intersects(&aside));
    }

    #[test]
    fn screen_error_matches_seed_004() {
        let v = cam([0.0, 0.0, 0.0], [1.0, 0.0, 0.0]).view().unwrap();
        // 768 px, 60°: λ = 384 / tan 30° = 665.1
        assert!((v.lambda - 384.0 / (30f64.to_radians()).tan()).abs() < 1e-9);
        let e = v.allowed_error(1.0, 100.0);
        assert!((v.screen_error(e, 100.0) - 1.0).abs() < 1e-12);
        assert_eq!(v.screen_error(0.0, 0.0), 0.0);
        assert_eq!(v.screen_error(1.0, 0.0), f64::INFINITY);
    }

    #[test]
    fn box_distances() {
        let b = Aabb {
            min: DVec3::new(0.0, 0.0, 0.0),
            max: DVec3::new(2.0, 2.0, 2.0),
        };
        assert_eq!(b.distance(DVec3::new(1.0, 1.0, 1.0)), 0.0);
        assert_eq!(b.distance(DVec3::new(5.0, 1.0, 1.0)), 3.0);
        assert_eq!(b.max_distance(DVec3::new(1.0, 1.0, 1.0)), 3f64.sqrt());
        assert_eq!(
            b.max_distance(DVec3::new(-1.0, 0.0, 0.0)),
            (9.0f64 + 4.0 + 4.0).sqrt()
        );
    }

    #[test]
    fn exact_test_rejects_what_planes_cannot() {
        // A narrow frustum looking along +x; a box beside it near the eye but across the
        // diagonal of two side planes' extensions.
        let mut c = cam([0.0, 0.0, 0.0], [1.0, 0.0, 0.0]);
        c.fov_y_deg = 10.0;
        c.viewport = [100, 100];
        let v = c.view().unwrap();
        let far_corner = Aabb {
            min: DVec3::new(-3.0, 2.0, 2.0),
            max: DVec3::new(-1.0, 3.0, 3.0),
        };
        assert!(!v.intersects(&far_corner));
        let ahead = Aabb {
            min: DVec3::new(10.0, -0.1, -0.1),
            max: DVec3::new(11.0, 0.1, 0.1),
        };
        assert!(v.intersects(&ahead));
    }
}
