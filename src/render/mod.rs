//! Pictures of a scene without a GPU: the surface its blocks draw, hillshaded and tinted by
//! each block's level with the blocks' outlines, seen through the scene's camera
//! ([`perspective`]) or from overhead with the camera's view drawn on the ground ([`top`]).
//!
//! A picture is made from a [`Surface`]: the heights a scene's blocks draw over a window
//! (a reconstruction) and the blocks themselves. Nothing here reads a file or chooses
//! blocks; the caller schedules the scene and reconstructs it.
//!
//! The overhead map (`top.rs`) is drawn in metres on the ground, north up, with a legend in
//! its north-west corner (each level's hue with its number, and the frustum's red), a north
//! arrow in its north-east corner and a scale bar in its south-west corner.
//!
//! **Shading.** Each sample's normal comes from central differences of its neighbours in
//! metres; the light comes from the north-west, 45° up (the cartographic convention), with a
//! quarter of ambient light so that slopes facing away stay readable. Each level has a hue
//! ([`level_colour`]), so the picture shows where the scene is fine and where coarse; a
//! block's edge is drawn dark in its hue.
//!
//! **Perspective.** The surface becomes a mesh of at most [`MESH_SIDE`] vertices a side
//! (every `s`-th sample), projected through the pinhole camera, and rasterized with a depth
//! buffer (depth as `1 / z`, which interpolates linearly on the screen). A triangle with a
//! vertex behind the near plane is left out: cameras look at terrain in front of them.

use std::io::Write;

use glam::DVec3;

use crate::error::{Error, Result};
use crate::model::SampleRect;
use crate::scene::{Camera, SceneBlock, WorldFrame};

mod text;
pub mod top;

pub use top::{top, MapGround};

/// Vertices along the longer side of the mesh a perspective picture rasterizes.
pub const MESH_SIDE: usize = 768;

/// The largest picture side accepted, in pixels.
pub const MAX_SIDE: u32 = 8192;

/// The hue of each level, coarsest first (the list repeats past its end).
const PALETTE: [[u8; 3]; 10] = [
    [68, 1, 84],
    [72, 40, 120],
    [62, 74, 137],
    [49, 104, 142],
    [38, 130, 142],
    [31, 158, 137],
    [53, 183, 121],
    [109, 205, 89],
    [180, 222, 44],
    [253, 231, 37],
];

/// The hue of level `level` in a picture: ten hues from purple (coarse) to yellow (fine),
/// repeating past the tenth level.
pub fn level_colour(level: u8) -> [u8; 3] {
    PALETTE[usize::from(level) % PALETTE.len()]
}

/// What the frustum and the eye are drawn in on an overhead picture.
pub const FRUSTUM_COLOUR: [u8; 3] = [230, 30, 30];

/// The heights a scene draws over a window, and its blocks.
pub struct Surface<'a> {
    /// The window, inclusive samples.
    pub window: SampleRect,
    /// Row-major heights of the window's samples; NaN where no block draws.
    pub heights: &'a [f64],
    /// The scene's blocks (their levels and rectangles).
    pub blocks: &'a [SceneBlock],
    /// Where samples lie in metres.
    pub frame: WorldFrame,
}

/// An RGB picture, row-major from the top-left.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct Image {
    /// Pixels across.
    pub width: u32,
    /// Pixels down.
    pub height: u32,
    /// Three bytes a pixel.
    pub rgb: Vec<u8>,
}

impl Image {
    fn new(width: u32, height: u32) -> Image {
        Image {
            width,
            height,
            rgb: vec![0; width as usize * height as usize * 3],
        }
    }

    /// Pixel `(x, y)`.
    #[cfg(any(test, feature = "testing"))]
    pub fn pixel(&self, x: u32, y: u32) -> [u8; 3] {
        let i = (y as usize * self.width as usize + x as usize) * 3;
        [self.rgb[i], self.rgb[i + 1], self.rgb[i + 2]]
    }

    fn set(&mut self, x: i64, y: i64, c: [u8; 3]) {
        if x >= 0 && y >= 0 && x < i64::from(self.width) && y < i64::from(self.height) {
            let i = (y as usize * self.width as usize + x as usize) * 3;
            self.rgb[i..i + 3].copy_from_slice(&c);
        }
    }

    /// Writes the picture as an 8-bit RGB PNG.
    pub fn write_png<W: Write>(&self, out: W) -> Result<()> {
        let png_error = |e: png::EncodingError| Error::InvalidArgument(format!("PNG: {e}"));
        let mut encoder = png::Encoder::new(out, self.width, self.height);
        encoder.set_color(png::ColorType::Rgb);
        encoder.set_depth(png::BitDepth::Eight);
        let mut writer = encoder.write_header().map_err(png_error)?;
        writer.write_image_data(&self.rgb).map_err(png_error)?;
        writer.finish().map_err(png_error)
    }
}

/// Per window sample: the light it gets (0 to 1, NaN where no height) and the index of the
/// block that draws it (`u32::MAX` where none).
struct Shaded {
    w: usize,
    h: usize,
    light: Vec<f32>,
    owner: Vec<u32>,
}

impl Surface<'_> {
    fn size(&self) -> Result<(usize, usize)> {
        let w = self
            .window
            .col1
            .checked_sub(self.window.col0)
            .map(|d| d + 1);
        let h = self
            .window
            .row1
            .checked_sub(self.window.row0)
            .map(|d| d + 1);
        match (w, h) {
            (Some(w), Some(h)) if (w * h) as usize == self.heights.len() => {
                Ok((w as usize, h as usize))
            }
            _ => Err(Error::InvalidArgument(format!(
                "a surface of {} heights does not fill its window",
                self.heights.len()
            ))),
        }
    }

    fn shade(&self) -> Result<Shaded> {
        let (w, h) = self.size()?;
        let (dx, dy) = (self.frame.dx, self.frame.dy);
        let light_dir = DVec3::new(-0.5, -0.5, std::f64::consts::FRAC_1_SQRT_2);
        let at = |x: usize, y: usize| self.heights[y * w + x];
        let mut light = vec![f32::NAN; w * h];
        for y in 0..h {
            for x in 0..w {
                let z = at(x, y);
                if !z.is_finite() {
                    continue;
                }
                // One-sided at the edges and next to holes.
                let slope = |a: f64, b: f64, span: f64| -> f64 {
                    match (a.is_finite(), b.is_finite()) {
                        (true, true) => (b - a) / (2.0 * span),
                        (true, false) => (z - a) / span,
                        (false, true) => (b - z) / span,
                        (false, false) => 0.0,
                    }
                };
                let west = if x > 0 { at(x - 1, y) } else { f64::NAN };
                let east = if x + 1 < w { at(x + 1, y) } else { f64::NAN };
                let north = if y > 0 { at(x, y - 1) } else { f64::NAN };
                let south = if y + 1 < h { at(x, y + 1) } else { f64::NAN };
                // The world's y grows southwards.
                let n = DVec3::new(-slope(west, east, dx), -slope(north, south, dy), 1.0)
                    .normalize_or_zero();
                light[y * w + x] = (0.25 + 0.75 * n.dot(light_dir).max(0.0)) as f32;
            }
        }
        let mut owner = vec![u32::MAX; w * h];
        for (i, b) in self.blocks.iter().enumerate() {
            let Some(r) = b.rect().intersect(&self.window) else {
                continue;
            };
            for row in r.row0..=r.row1 {
                let y = (row - self.window.row0) as usize;
                let from = (r.col0 - self.window.col0) as usize;
                let to = (r.col1 - self.window.col0) as usize;
                owner[y * w + from..=y * w + to].fill(i as u32);
            }
        }
        Ok(Shaded { w, h, light, owner })
    }

    fn level_of(&self, owner: u32) -> Option<u8> {
        self.blocks.get(owner as usize).map(|b| b.level)
    }
}

fn scaled(c: [u8; 3], k: f32) -> [u8; 3] {
    c.map(|v| (f32::from(v) * k).round().clamp(0.0, 255.0) as u8)
}

/// A lit sample of a block of `level`: its hue, lightened toward grey and shaded.
fn lit(level: Option<u8>, light: f32) -> [u8; 3] {
    let hue = level.map_or([160, 160, 160], level_colour);
    let mixed = hue.map(|v| (0.7 * f32::from(v) + 0.3 * 210.0) as u8);
    scaled(mixed, light)
}

/// The surface seen through `camera`, at its viewport's size.
pub fn perspective(surface: &Surface<'_>, camera: &Camera) -> Result<Image> {
    let view = camera.view()?;
    let [width, height] = camera.viewport;
    if width > MAX_SIDE || height > MAX_SIDE {
        return Err(Error::InvalidArgument(format!(
            "a picture of {width}x{height}: each side must be at most {MAX_SIDE} pixels"
        )));
    }
    let shaded = surface.shade()?;
    let (w, h) = (shaded.w, shaded.h);
    let mut image = Image::new(width, height);
    for y in 0..height {
        let t = y as f32 / height.max(1) as f32;
        let sky = [(150.0 + 70.0 * t) as u8, (190.0 + 45.0 * t) as u8, 240];
        for x in 0..width {
            image.set(i64::from(x), i64::from(y), sky);
        }
    }
    let step = w.max(h).div_ceil(MESH_SIDE).max(1);
    let cols: Vec<usize> = (0..w)
        .step_by(step)
        .chain(((w - 1) % step != 0).then_some(w - 1))
        .collect();
    let rows: Vec<usize> = (0..h)
        .step_by(step)
        .chain(((h - 1) % step != 0).then_some(h - 1))
        .collect();
    let near = 1e-6 * (f64::from(width) + f64::from(height));
    // Each mesh vertex on the screen (the camera's own projection, `View::project`):
    // (x, y, 1/z), or None behind the near plane or without a height.
    let project = |col: usize, row: usize| -> Option<[f64; 3]> {
        let z = surface.heights[row * w + col];
        if !z.is_finite() {
            return None;
        }
        let p = surface.frame.point(
            (surface.window.col0 + col as u64) as f64,
            (surface.window.row0 + row as u64) as f64,
            z,
        );
        let [x, y, depth] = view.project(p)?;
        (depth > near).then_some([x, y, 1.0 / depth])
    };
    let screen: Vec<Vec<Option<[f64; 3]>>> = rows
        .iter()
        .map(|&r| cols.iter().map(|&c| project(c, r)).collect())
        .collect();
    let mut depth = vec![0.0f32; width as usize * height as usize];
    let mut owner = vec![u32::MAX; width as usize * height as usize];
    for j in 0..rows.len().saturating_sub(1) {
        for i in 0..cols.len().saturating_sub(1) {
            let (c, r) = (cols[i], rows[j]);
            let light = shaded.light[r * w + c];
            let o = shaded.owner[r * w + c];
            let colour = lit(
                surface.level_of(o),
                if light.is_nan() { 0.5 } else { light },
            );
            let (a, b, d, e) = (
                screen[j][i],
                screen[j][i + 1],
                screen[j + 1][i],
                screen[j + 1][i + 1],
            );
            for tri in [[a, b, d], [b, e, d]] {
                if let [Some(p0), Some(p1), Some(p2)] = tri {
                    fill_triangle(&mut image, &mut depth, &mut owner, [p0, p1, p2], colour, o);
                }
            }
        }
    }
    // Block edges: where the block drawn changes between neighbouring pixels.
    let (iw, ih) = (width as usize, height as usize);
    for y in 0..ih {
        for x in 0..iw {
            let o = owner[y * iw + x];
            if o == u32::MAX {
                continue;
            }
            let differs = |x2: usize, y2: usize| {
                let n = owner[y2 * iw + x2];
                n != u32::MAX && n != o && depth[y2 * iw + x2] <= depth[y * iw + x] * 1.02
            };
            if (x + 1 < iw && differs(x + 1, y)) || (y + 1 < ih && differs(x, y + 1)) {
                let hue = surface.level_of(o).map_or([60, 60, 60], level_colour);
                image.set(x as i64, y as i64, scaled(hue, 0.45));
            }
        }
    }
    Ok(image)
}

/// Fills a screen triangle (vertices `x, y, 1/z`) where it is nearer than what is drawn.
fn fill_triangle(
    image: &mut Image,
    depth: &mut [f32],
    owner: &mut [u32],
    [a, b, c]: [[f64; 3]; 3],
    colour: [u8; 3],
    block: u32,
) {
    let area = (b[0] - a[0]) * (c[1] - a[1]) - (b[1] - a[1]) * (c[0] - a[0]);
    if area.abs() < 1e-12 || !area.is_finite() {
        return;
    }
    let (w, h) = (f64::from(image.width), f64::from(image.height));
    let x0 = a[0].min(b[0]).min(c[0]).floor().max(0.0);
    let x1 = a[0].max(b[0]).max(c[0]).ceil().min(w - 1.0);
    let y0 = a[1].min(b[1]).min(c[1]).floor().max(0.0);
    let y1 = a[1].max(b[1]).max(c[1]).ceil().min(h - 1.0);
    if x0 > x1 || y0 > y1 {
        return;
    }
    let width = image.width as usize;
    for py in y0 as usize..=y1 as usize {
        for px in x0 as usize..=x1 as usize {
            let (sx, sy) = (px as f64 + 0.5, py as f64 + 0.5);
            let w0 = ((b[0] - sx) * (c[1] - sy) - (b[1] - sy) * (c[0] - sx)) / area;
            let w1 = ((c[0] - sx) * (a[1] - sy) - (c[1] - sy) * (a[0] - sx)) / area;
            let w2 = 1.0 - w0 - w1;
            if w0 < 0.0 || w1 < 0.0 || w2 < 0.0 {
                continue;
            }
            let inv_z = (w0 * a[2] + w1 * b[2] + w2 * c[2]) as f32;
            let i = py * width + px;
            if inv_z > depth[i] {
                depth[i] = inv_z;
                owner[i] = block;
                image.set(px as i64, py as i64, colour);
            }
        }
    }
}

/// Pixels from the picture's corner to the legend's, and between its rows.
pub const LEGEND_MARGIN: i64 = 4;
/// A legend swatch's side, in pixels; rows are this plus 4 apart.
pub const LEGEND_SWATCH: i64 = 12;

/// The overhead map's legend, in its north-west corner on a white panel: a swatch of each
/// level's hue with the level's number, then the frustum's colour. Left out of pictures too
/// small to hold it.
fn legend(image: &mut Image, levels: &[u8]) {
    let row = LEGEND_SWATCH + 4;
    let (w, h) = (LEGEND_SWATCH + 30, row * (levels.len() as i64 + 1) + 4);
    if levels.is_empty()
        || w + 2 * LEGEND_MARGIN > i64::from(image.width)
        || h + 2 * LEGEND_MARGIN > i64::from(image.height)
    {
        return;
    }
    let (x0, y0) = (LEGEND_MARGIN, LEGEND_MARGIN);
    fill(image, x0, y0, w, h, [255, 255, 255]);
    for (i, &l) in levels.iter().enumerate() {
        let y = y0 + 4 + row * i as i64;
        fill(
            image,
            x0 + 4,
            y,
            LEGEND_SWATCH,
            LEGEND_SWATCH,
            level_colour(l),
        );
        text::draw(image, x0 + LEGEND_SWATCH + 10, y + 1, &l.to_string(), [40, 40, 40]);
    }
    // The frustum: a red line, with the eye's dot.
    let y = y0 + 4 + row * levels.len() as i64 + LEGEND_SWATCH / 2;
    fill(image, x0 + 4, y - 1, LEGEND_SWATCH + 20, 2, FRUSTUM_COLOUR);
    fill(image, x0 + 4, y - 3, 6, 6, FRUSTUM_COLOUR);
}

/// A `dx` × `dy` rectangle from `(x0, y0)`, clipped to the picture.
fn fill(image: &mut Image, x0: i64, y0: i64, dx: i64, dy: i64, c: [u8; 3]) {
    for y in y0..y0 + dy {
        for x in x0..x0 + dx {
            image.set(x, y, c);
        }
    }
}

/// A line from `a` to `b` (pixels), clipped to the picture.
fn line(image: &mut Image, a: (f64, f64), b: (f64, f64), c: [u8; 3]) {
    if !(a.0.is_finite() && a.1.is_finite() && b.0.is_finite() && b.1.is_finite()) {
        return;
    }
    let steps = (b.0 - a.0).abs().max((b.1 - a.1).abs()).ceil().min(1e6) as usize;
    for i in 0..=steps {
        let t = if steps == 0 {
            0.0
        } else {
            i as f64 / steps as f64
        };
        let (x, y) = (a.0 + (b.0 - a.0) * t, a.1 + (b.1 - a.1) * t);
        image.set(x.floor() as i64, y.floor() as i64, c);
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Ground sloping up to the south-east faces the light (north-west): lit; sloping up to
    /// the north-west faces away: ambient only; flat ground in between.
    #[test]
    fn slopes_facing_the_light_are_lit_and_those_facing_away_are_not() {
        let light_of = |k: f64| {
            let heights: Vec<f64> = (0..25).map(|i| k * f64::from(i % 5 + i / 5)).collect();
            let surface = Surface {
                window: SampleRect {
                    col0: 0,
                    row0: 0,
                    col1: 4,
                    row1: 4,
                },
                heights: &heights,
                blocks: &[],
                frame: WorldFrame::new(Some([1.0, 1.0])),
            };
            surface.shade().unwrap().light[12]
        };
        let (facing, flat, away) = (light_of(1.0), light_of(0.0), light_of(-1.0));
        // Flat: 0.25 + 0.75 cos 45°.
        assert!((flat - (0.25 + 0.75 * std::f32::consts::FRAC_1_SQRT_2)).abs() < 1e-6);
        assert!(facing > flat && flat > away, "{facing} {flat} {away}");
        assert!((away - 0.25).abs() < 1e-6, "facing away: ambient only");
    }
}
