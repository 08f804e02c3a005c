//! The overhead map (`fmrh render --top`): the surface from above in metres on the ground,
//! each block tinted by its level and outlined, the camera's view drawn on the ground, a
//! legend of the levels, a scale bar and a north arrow.
//!
//! **Ground.** A map is drawn in metres, one scale for the whole picture, so that it keeps
//! the terrain's true shape ([`MapGround`]). A projected grid (or one known only by its
//! spacing) puts sample `(col, row)` at `col · dx` east and `row · dy` south: a grid whose
//! samples are not square on the ground is not drawn square. A geographic grid (longitude
//! and latitude) puts each row at its own latitude's width: `east = (lon − lon_c) · a(φ)`,
//! `north = (φ − φ_c) · b(φ_c)`, with `a(φ)` and `b(φ)` the metres of a degree of longitude
//! and latitude on the WGS 84 ellipsoid ([`crate::crs::geographic_spacing`]) and `lon_c`,
//! `φ_c` the window's middle: a sinusoidal projection about the window's middle meridian.
//! Parallels keep their true length (a one-degree tile at 43° N is 0.73 times as wide as it
//! is high, and narrower at its north edge than at its south) and so does the middle
//! meridian; away from it the meridians lean by `Δlon · sin φ` (0.3° at the edge of that
//! tile). Drawing such a grid in samples, as fmrh did before issue 40, made it 1.37 times too
//! wide at 43° N.
//!
//! **North.** The picture's up is grid north (the direction rows count down). The arrow in
//! the north-east corner points to true north at the window's middle: on a geographic grid
//! that is up; on a projected grid whose CRS fmrh can invert it is turned by the meridian
//! convergence, measured with the CRS's own inverse projection (2.9° anticlockwise from up
//! at 119° W, 46° N in UTM zone 10 N); where nothing says where north is, the arrow shows
//! grid north with a hollow head.
//!
//! **Scale.** The bar in the south-west corner is the longest round length (1, 2 or 5 ·
//! 10^k m) at most a quarter of the picture's width, labelled in m or km. On a geographic grid it is
//! true along parallels and the middle meridian.

use glam::DVec3;

use super::{level_colour, line, lit, scaled, Image, Surface, FRUSTUM_COLOUR, MAX_SIDE};
use crate::error::{Error, Result};
use crate::heightfield::Georeference;
use crate::scene::{Camera, GlobeFrame};

/// How the overhead map lays samples on the ground.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum MapGround {
    /// The surface's own frame: `dx`, `dy` metres a sample, grid north up. `north_deg` is
    /// true north's bearing from grid north, clockwise in degrees, when the grid's CRS says
    /// it (a projected grid's meridian convergence, negated); `None` when nothing says
    /// where north is (the frame's rows are taken to run south).
    Grid {
        /// True north, clockwise from the picture's up, degrees.
        north_deg: Option<f64>,
    },
    /// A geographic grid: each row at its latitude's true width, north up.
    Geographic(GlobeFrame),
}

impl MapGround {
    /// The ground of a grid with georeference `georef`, true north taken at sample
    /// `(col, row)` (the window's middle): geographic when its CRS is; a grid with the
    /// convergence when the CRS is projected and fmrh can invert it; else a plain grid.
    pub fn of(georef: Option<&Georeference>, col: f64, row: f64) -> MapGround {
        let Some(g) = georef else {
            return MapGround::Grid { north_deg: None };
        };
        if let Ok(globe) = GlobeFrame::of(g) {
            return MapGround::Geographic(globe);
        }
        MapGround::Grid {
            north_deg: convergence_deg(g, col, row).map(|gamma| -gamma),
        }
    }
}

/// The meridian convergence of a projected grid at sample `(col, row)`: grid north's bearing
/// from true north, clockwise, degrees. `None` when the CRS cannot be inverted there.
fn convergence_deg(g: &Georeference, col: f64, row: f64) -> Option<f64> {
    let crs = crate::crs::Crs::parse(g.crs.as_deref()?)?;
    if !matches!(crs.kind, crate::crs::CrsKind::Projected { .. }) {
        return None;
    }
    let x = g.origin[0] + col * g.step[0];
    let y = g.origin[1] + row * g.step[1];
    // A step up the grid's columns (towards smaller rows: grid north), in CRS units.
    let d = g.step[1].abs().max(1e-9) * 10.0;
    let north = if g.step[1] < 0.0 { d } else { -d };
    let [p, q] = <[[f64; 2]; 2]>::try_from(crs.to_lon_lat_all(&[[x, y], [x, y + north]])?).ok()?;
    let [sx, sy] = crate::crs::geographic_spacing([1.0, 1.0], p[1]);
    let east = (q[0] - p[0]) * sx;
    let northward = (q[1] - p[1]) * sy;
    let gamma = east.atan2(northward).to_degrees();
    gamma.is_finite().then_some(gamma)
}

/// Where samples of a window lie on the ground: metres east and north of the window's
/// middle.
struct Ground {
    kind: MapGround,
    dx: f64,
    dy: f64,
    /// The middle's sample position (whole-grid samples).
    col_c: f64,
    row_c: f64,
    /// On a geographic grid, metres a degree of latitude at the middle.
    north_m_per_deg: f64,
}

impl Ground {
    fn new(kind: MapGround, surface: &Surface<'_>) -> Ground {
        let w = &surface.window;
        let col_c = (w.col0 + w.col1) as f64 / 2.0;
        let row_c = (w.row0 + w.row1) as f64 / 2.0;
        let north_m_per_deg = match kind {
            MapGround::Geographic(g) => {
                crate::crs::geographic_spacing([1.0, 1.0], g.lon_lat(col_c, row_c).1)[1]
            }
            MapGround::Grid { .. } => 0.0,
        };
        Ground {
            kind,
            dx: surface.frame.dx,
            dy: surface.frame.dy,
            col_c,
            row_c,
            north_m_per_deg,
        }
    }

    /// Metres east of the middle a degree of longitude is, at latitude `lat`.
    fn east_m_per_deg(lat: f64) -> f64 {
        crate::crs::geographic_spacing([1.0, 1.0], lat)[0]
    }

    /// `(east, north)` metres of sample position `(col, row)`.
    fn at(&self, col: f64, row: f64) -> (f64, f64) {
        match self.kind {
            MapGround::Grid { .. } => ((col - self.col_c) * self.dx, (self.row_c - row) * self.dy),
            MapGround::Geographic(g) => {
                let (lon, lat) = g.lon_lat(col, row);
                let (lon_c, lat_c) = g.lon_lat(self.col_c, self.row_c);
                (
                    (lon - lon_c) * Ground::east_m_per_deg(lat),
                    (lat - lat_c) * self.north_m_per_deg,
                )
            }
        }
    }

    /// The sample position at `(east, north)` metres: the inverse of [`Ground::at`].
    fn sample(&self, east: f64, north: f64) -> (f64, f64) {
        match self.kind {
            MapGround::Grid { .. } => (self.col_c + east / self.dx, self.row_c - north / self.dy),
            MapGround::Geographic(g) => {
                let (lon_c, lat_c) = g.lon_lat(self.col_c, self.row_c);
                let lat = lat_c + north / self.north_m_per_deg;
                let lon = lon_c + east / Ground::east_m_per_deg(lat);
                ((lon - g.lon0) / g.dlon, (lat - g.lat0) / g.dlat)
            }
        }
    }

    /// True north on the picture, clockwise from up in radians, and whether it is known.
    fn north(&self) -> (f64, bool) {
        match self.kind {
            MapGround::Geographic(_) => (0.0, true),
            MapGround::Grid { north_deg: Some(d) } => (d.to_radians(), true),
            MapGround::Grid { north_deg: None } => (0.0, false),
        }
    }
}

/// What an overhead map shows besides its pixels: for readers that check it (the tests,
/// and anyone measuring on the picture).
#[derive(Clone, Debug, PartialEq)]
pub struct TopMap {
    /// The picture.
    pub image: Image,
    /// Metres on the ground a pixel spans, across and down.
    pub metres_per_pixel: f64,
    /// The scale bar's length in metres (0 when the picture is too small to hold it).
    pub scale_bar_m: f64,
    /// The bar's left end `(x, y)` and length in pixels: [`SCALE_COLOUR`] from `x` on row
    /// `y`.
    pub scale_bar_px: (i64, i64, i64),
    /// True north, clockwise from the picture's up, degrees; `None` when unknown (the
    /// arrow then shows grid north, hollow).
    pub north_deg: Option<f64>,
}

/// The scale bar's and the north arrow's colour.
pub const SCALE_COLOUR: [u8; 3] = [20, 20, 20];

/// The surface from overhead, north up, its longer side `side` pixels, in metres on the
/// ground as `ground` lays it: each block tinted by its level and outlined, and the camera's
/// view drawn on the ground (the eye, and its four corner rays to where they meet the ground
/// at the surface's mean height, or the picture's edge). The picture spans the window and
/// the eye.
pub fn top(
    surface: &Surface<'_>,
    camera: &Camera,
    side: u32,
    ground: MapGround,
) -> Result<TopMap> {
    let view = camera.view()?;
    if side == 0 || side > MAX_SIDE {
        return Err(Error::InvalidArgument(format!(
            "a picture side of {side}: it must be 1 to {MAX_SIDE} pixels"
        )));
    }
    let shaded = surface.shade()?;
    let (w, h) = (shaded.w, shaded.h);
    let win = surface.window;
    let g = Ground::new(ground, surface);
    // The picture spans the window's corners and the eye (with a margin around it), in
    // metres: `[e0, e1] × [n0, n1]`. Samples are cells a sample wide around their centres.
    let (c0, c1) = (win.col0 as f64 - 0.5, win.col1 as f64 + 0.5);
    let (r0, r1) = (win.row0 as f64 - 0.5, win.row1 as f64 + 0.5);
    let corners = [(c0, r0), (c1, r0), (c0, r1), (c1, r1), (c0, (r0 + r1) / 2.0), (c1, (r0 + r1) / 2.0)];
    let mut bounds = Bounds::default();
    for (c, r) in corners {
        bounds.take(g.at(c, r));
    }
    if bounds.e0 > bounds.e1 || bounds.n0 > bounds.n1 {
        return Err(Error::InvalidArgument(
            "the window does not lie on the ground (a georeference out of range)".into(),
        ));
    }
    let extent = (bounds.e1 - bounds.e0).max(bounds.n1 - bounds.n0);
    let (ce, cn) = ((bounds.e0 + bounds.e1) / 2.0, (bounds.n0 + bounds.n1) / 2.0);
    let eye = g.at(view.eye.x / surface.frame.dx, view.eye.y / surface.frame.dy);
    // The eye, and a margin around it, as far as four times the window's extent.
    let (margin, limit) = (0.03 * extent, 4.0 * extent);
    bounds.take((
        (eye.0 - margin).max(ce - limit),
        (eye.1 - margin).max(cn - limit),
    ));
    bounds.take((
        (eye.0 + margin).min(ce + limit),
        (eye.1 + margin).min(cn + limit),
    ));
    let Bounds { e0, e1, n0, n1 } = bounds;
    let scale = f64::from(side) / (e1 - e0).max(n1 - n0); // pixels a metre
    let iw = (((e1 - e0) * scale).round() as u32).clamp(1, side);
    let ih = (((n1 - n0) * scale).round() as u32).clamp(1, side);
    let mut image = Image::new(iw, ih);
    // The window sample under pixel `(px, py)`, if it lies inside the window.
    let sample = |px: u32, py: u32| -> Option<usize> {
        let e = e0 + (f64::from(px) + 0.5) / scale;
        let n = n1 - (f64::from(py) + 0.5) / scale;
        let (col, row) = g.sample(e, n);
        let x = (col - win.col0 as f64 + 0.5).floor();
        let y = (row - win.row0 as f64 + 0.5).floor();
        (x >= 0.0 && y >= 0.0 && x < w as f64 && y < h as f64).then(|| y as usize * w + x as usize)
    };
    let owner_at = |px: u32, py: u32| sample(px, py).map_or(u32::MAX, |s| shaded.owner[s]);
    for py in 0..ih {
        for px in 0..iw {
            let Some(s) = sample(px, py) else {
                image.set(i64::from(px), i64::from(py), [250, 250, 250]);
                continue;
            };
            let o = shaded.owner[s];
            let light = shaded.light[s];
            let c = if light.is_nan() {
                [235, 235, 235]
            } else {
                lit(surface.level_of(o), light)
            };
            let edge = (px + 1 < iw && owner_at(px + 1, py) != o)
                || (py + 1 < ih && owner_at(px, py + 1) != o);
            let c = match (edge, surface.level_of(o)) {
                (true, Some(l)) => scaled(level_colour(l), 0.45),
                _ => c,
            };
            image.set(i64::from(px), i64::from(py), c);
        }
    }
    // The view on the ground.
    let finite: Vec<f64> = surface
        .heights
        .iter()
        .copied()
        .filter(|z| z.is_finite())
        .collect();
    let mean = if finite.is_empty() {
        0.0
    } else {
        finite.iter().sum::<f64>() / finite.len() as f64
    };
    let to_pixel = |p: DVec3| -> (f64, f64) {
        let (e, n) = g.at(p.x / surface.frame.dx, p.y / surface.frame.dy);
        ((e - e0) * scale, (n1 - n) * scale)
    };
    let reach = (w.max(h) as f64) * surface.frame.dx.max(surface.frame.dy) * 4.0;
    let rays: Vec<(f64, f64)> = view
        .rays
        .iter()
        .map(|r| {
            let t = if r.z < 0.0 && view.eye.z > mean {
                ((mean - view.eye.z) / r.z).min(reach / r.length())
            } else {
                reach / r.length()
            };
            to_pixel(view.eye + *r * t)
        })
        .collect();
    let eye_px = to_pixel(view.eye);
    for (i, c) in rays.iter().enumerate() {
        line(&mut image, eye_px, *c, FRUSTUM_COLOUR);
        line(&mut image, *c, rays[(i + 1) % 4], FRUSTUM_COLOUR);
    }
    disc(&mut image, eye_px, 3, FRUSTUM_COLOUR);
    let mut levels: Vec<u8> = surface.blocks.iter().map(|b| b.level).collect();
    levels.sort_unstable();
    levels.dedup();
    super::legend(&mut image, &levels);
    let (scale_bar_m, scale_bar_px) = scale_bar(&mut image, 1.0 / scale);
    let (north, known) = g.north();
    north_arrow(&mut image, north, known);
    Ok(TopMap {
        image,
        metres_per_pixel: 1.0 / scale,
        scale_bar_m,
        scale_bar_px,
        north_deg: known.then(|| north.to_degrees()),
    })
}

/// A box on the ground, metres east and north.
struct Bounds {
    e0: f64,
    e1: f64,
    n0: f64,
    n1: f64,
}

impl Default for Bounds {
    /// Empty: anything taken grows it.
    fn default() -> Bounds {
        Bounds {
            e0: f64::MAX,
            e1: f64::MIN,
            n0: f64::MAX,
            n1: f64::MIN,
        }
    }
}

impl Bounds {
    /// Grows the box to hold `(east, north)`, if finite.
    fn take(&mut self, (e, n): (f64, f64)) {
        if e.is_finite() && n.is_finite() {
            self.e0 = self.e0.min(e);
            self.e1 = self.e1.max(e);
            self.n0 = self.n0.min(n);
            self.n1 = self.n1.max(n);
        }
    }
}

/// A filled disc of radius `r` pixels at `at`.
fn disc(image: &mut Image, at: (f64, f64), r: i64, c: [u8; 3]) {
    if !(at.0.is_finite() && at.1.is_finite()) {
        return;
    }
    for dy in -r..=r {
        for dx in -r..=r {
            if dx * dx + dy * dy <= r * r {
                image.set(at.0.floor() as i64 + dx, at.1.floor() as i64 + dy, c);
            }
        }
    }
}

/// The longest round length (1, 2 or 5 · 10^k) at most `target`: more than `target / 2.5`.
pub fn round_length(target: f64) -> f64 {
    let mut unit = 10f64.powf(target.log10().floor());
    // `log10` may fall a hair short of a power of ten.
    if unit * 10.0 <= target {
        unit *= 10.0;
    }
    [5.0, 2.0, 1.0]
        .into_iter()
        .map(|m| m * unit)
        .find(|&l| l <= target)
        .unwrap_or(unit)
}

/// Pixels from the picture's edges to the scale bar and the north arrow.
const CORNER_MARGIN: i64 = 8;

/// Draws the scale bar in the south-west corner on a white panel: the longest round length
/// at most a quarter of the picture's width, with ticks at its ends and its label above. Returns
/// the length in metres and the bar's `(x, y, length)` in pixels; left out (length 0) of a
/// picture too small to hold it.
fn scale_bar(image: &mut Image, metres_per_pixel: f64) -> (f64, (i64, i64, i64)) {
    let width = i64::from(image.width);
    let height = i64::from(image.height);
    let metres = round_length(width as f64 / 4.0 * metres_per_pixel);
    let length = (metres / metres_per_pixel).round() as i64;
    let label = if metres >= 1000.0 {
        format!("{}km", metres / 1000.0)
    } else {
        format!("{metres}m")
    };
    let text_w = super::text::width(&label);
    let panel_w = length.max(text_w) + 8;
    let panel_h = 2 * super::text::HEIGHT + 16;
    if !metres.is_finite() || length < 8 || panel_w + 2 * CORNER_MARGIN > width
        || panel_h + 2 * CORNER_MARGIN > height
    {
        return (0.0, (0, 0, 0));
    }
    let (x0, y0) = (CORNER_MARGIN, height - CORNER_MARGIN - panel_h);
    super::fill(image, x0, y0, panel_w, panel_h, [255, 255, 255]);
    super::text::draw(image, x0 + 4, y0 + 4, &label, SCALE_COLOUR);
    let bar_y = y0 + panel_h - 6;
    let bar_x = x0 + 4;
    super::fill(image, bar_x, bar_y, length, 2, SCALE_COLOUR);
    super::fill(image, bar_x, bar_y - 4, 2, 6, SCALE_COLOUR);
    super::fill(image, bar_x + length - 2, bar_y - 4, 2, 6, SCALE_COLOUR);
    (metres, (bar_x, bar_y, length))
}

/// The north arrow's length in pixels.
pub const ARROW_LENGTH: f64 = 28.0;

/// Draws the north arrow in the north-east corner on a white panel: a shaft and a head
/// pointing `north` (clockwise from up, radians) and an `N` at its foot; the head hollow
/// when north is not known (grid north).
fn north_arrow(image: &mut Image, north: f64, known: bool) {
    let size = ARROW_LENGTH as i64 + 12;
    let panel_h = size + super::text::HEIGHT + 6;
    if size + 2 * CORNER_MARGIN > i64::from(image.width)
        || panel_h + 2 * CORNER_MARGIN > i64::from(image.height)
    {
        return;
    }
    let x0 = i64::from(image.width) - CORNER_MARGIN - size;
    let y0 = CORNER_MARGIN;
    super::fill(image, x0, y0, size, panel_h, [255, 255, 255]);
    let centre = (x0 as f64 + size as f64 / 2.0, y0 as f64 + size as f64 / 2.0);
    let (s, c) = north.sin_cos();
    let half = ARROW_LENGTH / 2.0;
    let tip = (centre.0 + s * half, centre.1 - c * half);
    let tail = (centre.0 - s * half, centre.1 + c * half);
    line(image, tail, tip, SCALE_COLOUR);
    // The head: two sides back from the tip, 25° off the shaft, filled when north is known.
    let back = 9.0;
    let side = |turn: f64| {
        let a = north + std::f64::consts::PI + turn;
        (tip.0 + a.sin() * back, tip.1 - a.cos() * back)
    };
    let (l, r) = (side(-0.44), side(0.44));
    line(image, tip, l, SCALE_COLOUR);
    line(image, tip, r, SCALE_COLOUR);
    line(image, l, r, SCALE_COLOUR);
    if known {
        for k in 0..=16 {
            let t = f64::from(k) / 16.0;
            line(image, tip, (l.0 + (r.0 - l.0) * t, l.1 + (r.1 - l.1) * t), SCALE_COLOUR);
        }
    }
    let n_w = super::text::width("N");
    super::text::draw(image, x0 + (size - n_w) / 2, y0 + size + 2, "N", SCALE_COLOUR);
}
