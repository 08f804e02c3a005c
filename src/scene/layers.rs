//! Layers on the globe: a coarse whole-Earth grid with finer geographic grids above it (SRTM
//! tiles over ETOPO1), seen as one terrain by one camera.
//!
//! **Priority.** Layer 0 is the base; each later layer lies above those before it. Where a
//! layer has data (its *footprint*, the longitude-latitude rectangle of its samples) it hides
//! every layer below. A scene runs each layer's own scene on the globe (each a cover of what
//! that layer shows, within `tau`: `Terrain::on_globe`), then **cuts** every block by the
//! footprints of the layers above it: a block wholly under them is dropped, and a block they
//! cover in part keeps the covered rectangles as *cut-outs*, which a renderer leaves out.
//! Every visible point of the globe is then drawn by exactly one block: by the highest layer
//! whose footprint holds it (that layer's own cover), and by no block of a lower layer, which
//! has it in a cut-out. (Footprint edges are shared lines, drawn by both sides.)
//!
//! **Alignment.** Each footprint edge of a layer must lie on a sample line of every layer
//! below whose footprint it crosses: an SRTM tile's whole degrees on ETOPO1's half degrees.
//! Cut-outs are then whole cells of the lower grid, and along a seam the lower surface is
//! linear between its samples, which is what makes the seam's skirts exact (below).
//! [`Layers::new`] refuses layers that break it.
//!
//! **Seams and skirts.** Where two layers meet, the two surfaces are the two layers' own, at
//! their own levels of detail, from different sources: they need not meet. Each block on a
//! seam gets a skirt ([`Layers::skirts`]), a curtain below its seam edges, as deep as its
//! edge lies above the other side's surface at the most. Both surfaces are linear along the
//! seam between the points where either may bend: the grid lines of every block along it (a
//! physical block's are its whole samples), and where the seam crosses a grid cell's
//! diagonal (a block coarser than its data has grid lines that the seam runs between). The gap is measured at every such point of both sides (`grid_breaks`),
//! against every other layer drawing there (several meet at a footprint's corner), so the
//! maximum bounds the gap everywhere on the seam: with the skirts hung, the side that is
//! higher at any point of the seam reaches below the other, and no crack is seen (the mesh
//! module's skirt argument, across layers). `tests/globe_layers.rs` found the corner case: a
//! skirt measured against the highest other layer only missed the base's gap just beside the
//! corner where two SRTM tiles and ETOPO1 meet (2,503 m against 2,499 m measured).
//!
//! The scene asks each layer's terrain for its scene and never parses a page.

use serde::Serialize;

use super::camera::{Camera, GlobeFrame, TerrainFrame};
use super::load::{load_blocks, PAYLOAD_GAP};
use super::result::{SceneBlock, SceneOptions, SceneStats};
use super::surface::{GridBlock, Surface};
use super::terrain::Terrain;
use crate::error::{Error, Result};
use crate::model::SampleRect;
use crate::store::Source;

/// Slivers thinner than this (degrees) are no area: rounding, not data.
const SLIVER: f64 = 1e-9;

/// A rectangle of longitudes and latitudes, degrees, `lon0 < lon1`, `lat0 < lat1`. Longitudes
/// may run past ±180° (a grid across the antimeridian); rectangles are compared a whole turn
/// apart too.
#[derive(Clone, Copy, Debug, PartialEq, Serialize)]
pub struct LonLatRect {
    /// West edge.
    pub lon0: f64,
    /// East edge.
    pub lon1: f64,
    /// South edge.
    pub lat0: f64,
    /// North edge.
    pub lat1: f64,
}

impl LonLatRect {
    /// The rectangle of samples `rect` (between their grid lines) of a grid on `frame`.
    pub fn of_samples(frame: &GlobeFrame, rect: &SampleRect) -> LonLatRect {
        let (a, b) = (
            frame.lon_lat(rect.col0 as f64, rect.row0 as f64),
            frame.lon_lat(rect.col1 as f64, rect.row1 as f64),
        );
        LonLatRect {
            lon0: a.0.min(b.0),
            lon1: a.0.max(b.0),
            lat0: a.1.min(b.1).max(-90.0),
            lat1: a.1.max(b.1).min(90.0),
        }
    }

    fn shifted(&self, turns: f64) -> LonLatRect {
        LonLatRect {
            lon0: self.lon0 + 360.0 * turns,
            lon1: self.lon1 + 360.0 * turns,
            ..*self
        }
    }

    fn intersect_plain(&self, o: &LonLatRect) -> Option<LonLatRect> {
        let r = LonLatRect {
            lon0: self.lon0.max(o.lon0),
            lon1: self.lon1.min(o.lon1),
            lat0: self.lat0.max(o.lat0),
            lat1: self.lat1.min(o.lat1),
        };
        (r.lon1 - r.lon0 > SLIVER && r.lat1 - r.lat0 > SLIVER).then_some(r)
    }

    /// The parts of `other` inside this rectangle with area, `other` taken as it is and a
    /// whole turn east and west, in this rectangle's longitudes.
    pub fn clips(&self, other: &LonLatRect) -> Vec<LonLatRect> {
        [-1.0, 0.0, 1.0]
            .iter()
            .filter_map(|&t| self.intersect_plain(&other.shifted(t)))
            .collect()
    }

    /// Whether the point is in the rectangle (edges included), a whole turn either way too.
    pub fn contains(&self, lon: f64, lat: f64) -> bool {
        (lat >= self.lat0 && lat <= self.lat1)
            && [-360.0, 0.0, 360.0]
                .iter()
                .any(|t| lon + t >= self.lon0 && lon + t <= self.lon1)
    }

    /// This rectangle less `cut` (in the same longitudes): at most four pieces with area.
    fn minus(&self, cut: &LonLatRect) -> Vec<LonLatRect> {
        let Some(c) = self.intersect_plain(cut) else {
            return vec![*self];
        };
        let pieces = [
            // West and east strips, full height; then south and north within the cut's span.
            LonLatRect {
                lon1: c.lon0,
                ..*self
            },
            LonLatRect {
                lon0: c.lon1,
                ..*self
            },
            LonLatRect {
                lon0: c.lon0,
                lon1: c.lon1,
                lat1: c.lat0,
                ..*self
            },
            LonLatRect {
                lon0: c.lon0,
                lon1: c.lon1,
                lat0: c.lat1,
                ..*self
            },
        ];
        pieces
            .into_iter()
            .filter(|p| p.lon1 - p.lon0 > SLIVER && p.lat1 - p.lat0 > SLIVER)
            .collect()
    }

    /// Whether `cuts` (in this rectangle's longitudes) cover all of it.
    pub fn covered_by(&self, cuts: &[LonLatRect]) -> bool {
        let mut left = vec![*self];
        for c in cuts {
            left = left.iter().flat_map(|p| p.minus(c)).collect();
            if left.is_empty() {
                return true;
            }
        }
        left.is_empty()
    }
}

/// One layer: a terrain on the globe and where its data lies.
pub struct Layer<'s, S: Source> {
    /// Its terrain, on the globe.
    pub terrain: Terrain<'s, S>,
    /// Where its samples lie.
    pub frame: GlobeFrame,
    /// Its footprint: the rectangle of all its samples.
    pub footprint: LonLatRect,
}

/// Terrains on the globe, each above those before it (the module doc).
pub struct Layers<'s, S: Source> {
    layers: Vec<Layer<'s, S>>,
}

/// A block of a layered scene.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct LayerBlock {
    /// The layer it comes from (0 the base).
    pub layer: usize,
    /// The block, in its layer's samples.
    #[serde(flatten)]
    pub block: SceneBlock,
    /// The parts of it the layers above draw instead (clipped to it): not drawn.
    pub cutouts: Vec<LonLatRect>,
}

/// A scene over layers.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct LayeredScene {
    /// The tolerance in pixels.
    pub tau: f64,
    /// The blocks, by layer, then as each layer's scene orders them.
    pub blocks: Vec<LayerBlock>,
    /// Each layer's scene statistics (its blocks before the cut).
    pub layers: Vec<SceneStats>,
    /// Blocks dropped because the layers above cover them.
    pub hidden_by_layers: u64,
    /// The layers' statistics summed (blocks, samples, triangles and bytes after the cut;
    /// errors maximised).
    pub stats: SceneStats,
}

impl<'s, S: Source> Layers<'s, S> {
    /// `terrains` as layers, the first the base: each must be on the globe, and each footprint
    /// edge must lie on a sample line of every lower layer it crosses.
    pub fn new(terrains: Vec<Terrain<'s, S>>) -> Result<Layers<'s, S>> {
        let mut layers: Vec<Layer<'s, S>> = Vec::with_capacity(terrains.len());
        for (i, terrain) in terrains.into_iter().enumerate() {
            let TerrainFrame::Globe(frame) = terrain.world() else {
                return Err(Error::InvalidArgument(format!(
                    "layer {i} is not on the globe (give each layer as Terrain::on_globe)"
                )));
            };
            let footprint = LonLatRect::of_samples(&frame, &terrain.domain().data_rect());
            for (k, below) in layers.iter().enumerate() {
                if below.footprint.clips(&footprint).is_empty() {
                    continue;
                }
                check_aligned(&footprint, &below.frame, &below.footprint).map_err(|e| {
                    Error::InvalidArgument(format!("layer {i} over layer {k}: {e}"))
                })?;
            }
            layers.push(Layer {
                terrain,
                frame,
                footprint,
            });
        }
        if layers.is_empty() {
            return Err(Error::InvalidArgument("no layers".into()));
        }
        Ok(Layers { layers })
    }

    /// The layers, the base first.
    #[cfg(any(test, feature = "testing"))]
    pub fn layers(&self) -> &[Layer<'s, S>] {
        &self.layers
    }

    /// The blocks `camera` (ECEF) needs at `options.tau`: each layer's scene, cut by the
    /// footprints above it.
    pub fn scene(&self, camera: &Camera, options: &SceneOptions) -> Result<LayeredScene> {
        if options.window.is_some() {
            return Err(Error::InvalidArgument(
                "a window names samples of one grid; layers have several: no --window".into(),
            ));
        }
        let started = std::time::Instant::now();
        let mut blocks = Vec::new();
        let mut per_layer = Vec::with_capacity(self.layers.len());
        let mut stats = SceneStats::default();
        let mut hidden = 0;
        for (i, layer) in self.layers.iter().enumerate() {
            let scene = layer.terrain.scene(camera, options)?;
            let above: Vec<LonLatRect> = self.layers[i + 1..].iter().map(|l| l.footprint).collect();
            let side = u64::from(layer.terrain.domain().block_size());
            for b in scene.blocks {
                let r = LonLatRect::of_samples(&layer.frame, &b.rect());
                let cutouts: Vec<LonLatRect> = above.iter().flat_map(|f| r.clips(f)).collect();
                if !cutouts.is_empty() && r.covered_by(&cutouts) {
                    hidden += 1;
                    continue;
                }
                stats.add_block(&b, side);
                blocks.push(LayerBlock {
                    layer: i,
                    block: b,
                    cutouts,
                });
            }
            stats.add_search(&scene.stats);
            per_layer.push(scene.stats);
        }
        stats.schedule_ns = started.elapsed().as_nanos() as u64;
        Ok(LayeredScene {
            tau: options.tau,
            blocks,
            layers: per_layer,
            hidden_by_layers: hidden,
            stats,
        })
    }

    /// Reads and decodes every block of `scene`, layer by layer (each layer's payloads in
    /// coalesced runs), in the scene's order.
    pub fn load(&self, scene: &LayeredScene) -> Result<Vec<super::LoadedBlock>> {
        let mut out: Vec<Option<super::LoadedBlock>> = vec![None; scene.blocks.len()];
        for (i, layer) in self.layers.iter().enumerate() {
            let at: Vec<usize> = (0..scene.blocks.len())
                .filter(|&k| scene.blocks[k].layer == i)
                .collect();
            let mine: Vec<SceneBlock> = at.iter().map(|&k| scene.blocks[k].block).collect();
            let loaded = load_blocks(layer.terrain.store(), &mine, PAYLOAD_GAP)?;
            for (k, l) in at.into_iter().zip(loaded) {
                out[k] = Some(l);
            }
        }
        out.into_iter()
            .map(|l| l.ok_or_else(|| Error::Internal("a layered block was not loaded".into())))
            .collect()
    }

    /// Block `k` of `scene` as the mesh and the surface take it, given the scene's blocks
    /// loaded in order ([`Layers::load`]).
    pub fn grid<'a>(
        &self,
        scene: &LayeredScene,
        loaded: &'a [super::LoadedBlock],
        k: usize,
    ) -> GridBlock<'a> {
        let b = &scene.blocks[k];
        let stride = self.layers[b.layer].terrain.domain().stride(b.block.level);
        GridBlock::of(&b.block, &loaded[k], stride)
    }

    /// The edges of samples `rect` of layer `j` that lie on its footprint's border.
    fn border_seams(&self, j: usize, rect: &SampleRect) -> Vec<Seam> {
        let layer = &self.layers[j];
        let data = layer.terrain.domain().data_rect();
        let (lon_a, lat_a) = layer.frame.lon_lat(rect.col0 as f64, rect.row0 as f64);
        let (lon_b, lat_b) = layer.frame.lon_lat(rect.col1 as f64, rect.row1 as f64);
        let parallel = |at| Seam {
            along_lon: true,
            at,
            from: lon_a,
            to: lon_b,
        };
        let meridian = |at| Seam {
            along_lon: false,
            at,
            from: lat_a,
            to: lat_b,
        };
        let mut out = Vec::new();
        if rect.row0 == data.row0 {
            out.push(parallel(lat_a));
        }
        if rect.row1 == data.row1 {
            out.push(parallel(lat_b));
        }
        if rect.col0 == data.col0 {
            out.push(meridian(lon_a));
        }
        if rect.col1 == data.col1 {
            out.push(meridian(lon_b));
        }
        out
    }

    /// The skirt depth of each block of `scene` (metres; 0 off the seams), given its blocks
    /// loaded in order ([`Layers::load`]): see the module doc.
    pub fn skirts(&self, scene: &LayeredScene, loaded: &[super::LoadedBlock]) -> Result<Vec<f64>> {
        if loaded.len() != scene.blocks.len() {
            return Err(Error::InvalidArgument(format!(
                "{} loaded blocks for a scene of {}",
                loaded.len(),
                scene.blocks.len()
            )));
        }
        let n = self.layers.len();
        let grids: Vec<GridBlock<'_>> = (0..scene.blocks.len())
            .map(|k| self.grid(scene, loaded, k))
            .collect();
        // Each layer's blocks (their indices in the scene) and surface.
        let mut index: Vec<Vec<usize>> = vec![Vec::new(); n];
        for (k, b) in scene.blocks.iter().enumerate() {
            index[b.layer].push(k);
        }
        let surfaces: Vec<Surface<'_>> = index
            .iter()
            .map(|ks| Surface::new(ks.iter().map(|&k| grids[k]).collect()))
            .collect();
        let mut depth = vec![0.0f64; scene.blocks.len()];
        for (k, block) in scene.blocks.iter().enumerate() {
            let j = block.layer;
            for seam in self.border_seams(j, &block.block.rect()) {
                // Every point where any block's surface may bend along the seam.
                let mut ts = Vec::new();
                for (i, layer) in self.layers.iter().enumerate() {
                    for &ko in &index[i] {
                        ts.extend(layer.seam_breaks(&grids[ko], &seam));
                    }
                }
                for t in ts {
                    let (lon, lat) = seam.point(t);
                    let (c, w) = self.layers[j].sample_of(lon, lat);
                    let own = super::surface::height_at(&grids[k], c, w);
                    // Across the seam: every other layer drawing there (at a footprint's
                    // corner several meet; where a layer is cut out on both sides this only
                    // deepens a skirt, which never opens a crack).
                    for i in (0..n).filter(|&i| i != j) {
                        let other = &self.layers[i];
                        if !other.footprint.contains(lon, lat) {
                            continue;
                        }
                        let (oc, or) = other.sample_of(lon, lat);
                        let Some(s) = surfaces[i].at(oc, or) else {
                            continue;
                        };
                        let ko = index[i][s.block];
                        depth[k] = depth[k].max(own - s.height);
                        depth[ko] = depth[ko].max(s.height - own);
                    }
                }
            }
        }
        Ok(depth)
    }
}

/// A piece of a layer's footprint border, degrees: along a parallel (longitudes `from` to
/// `to` at latitude `at`) or a meridian (latitudes `from` to `to` at longitude `at`).
struct Seam {
    along_lon: bool,
    at: f64,
    from: f64,
    to: f64,
}

impl Seam {
    /// Longitude and latitude of the point at parameter `t` (a longitude or a latitude).
    fn point(&self, t: f64) -> (f64, f64) {
        if self.along_lon {
            (t, self.at)
        } else {
            (self.at, t)
        }
    }
}

impl<S: Source> Layer<'_, S> {
    /// The fractional sample position of `lon`, `lat` on this layer's grid, the longitude
    /// taken a whole turn either way when that puts it in the footprint.
    fn sample_of(&self, lon: f64, lat: f64) -> (f64, f64) {
        let f = &self.footprint;
        let lon = [0.0, -360.0, 360.0]
            .iter()
            .map(|t| lon + t)
            .find(|l| *l >= f.lon0 && *l <= f.lon1)
            .unwrap_or(lon);
        (
            (lon - self.frame.lon0) / self.frame.dlon,
            (lat - self.frame.lat0) / self.frame.dlat,
        )
    }

    /// Where block `g` of this layer may bend along `seam`, as seam parameters: the seam
    /// brought into the grid's samples, [`grid_breaks`] there, and back.
    fn seam_breaks(&self, g: &GridBlock<'_>, seam: &Seam) -> Vec<f64> {
        let (a, b) = (
            self.sample_of(seam.point(seam.from).0, seam.point(seam.from).1),
            self.sample_of(seam.point(seam.to).0, seam.point(seam.to).1),
        );
        // In the grid, a parallel is a row (the column varies) and a meridian a column.
        let (line, ta, tb) = if seam.along_lon {
            (a.1, a.0, b.0)
        } else {
            (a.0, a.1, b.1)
        };
        let r = &g.rect;
        let (line_lo, line_hi, lo, hi) = if seam.along_lon {
            (r.row0, r.row1, r.col0, r.col1)
        } else {
            (r.col0, r.col1, r.row0, r.row1)
        };
        let (from, to) = (ta.min(tb).max(lo as f64), ta.max(tb).min(hi as f64));
        if ta == tb || line < line_lo as f64 || line > line_hi as f64 || from > to {
            return Vec::new();
        }
        grid_breaks(g, seam.along_lon, line, from, to)
            .into_iter()
            .map(|x| seam.from + (x - ta) / (tb - ta) * (seam.to - seam.from))
            .collect()
    }
}

/// Where block `g`'s surface may bend along the line `line` (a row when `along_row`, else a
/// column) between `from` and `to` (samples): its grid lines across, and where the line
/// crosses a grid cell's north-west to south-east diagonal when it runs between grid lines
/// (`format-spec/model.md` §4); the ends too.
fn grid_breaks(g: &GridBlock<'_>, along_row: bool, line: f64, from: f64, to: f64) -> Vec<f64> {
    let s = g.stride as f64;
    let (origin_line, origin_t) = if along_row {
        (g.rect.row0 as f64, g.rect.col0 as f64)
    } else {
        (g.rect.col0 as f64, g.rect.row0 as f64)
    };
    let mut out = vec![from, to];
    // Its grid lines across (every whole sample for a physical block): between two of them
    // and off the diagonals below, the surface is one plane.
    let mut k = ((from - origin_t) / s).ceil();
    loop {
        let t = origin_t + k * s;
        if t > to {
            break;
        }
        out.push(t);
        k += 1.0;
    }
    // Offset of the line inside its row (column) of cells: the diagonal meets it that far
    // past each grid line across.
    let off = (line - origin_line).rem_euclid(s);
    if off > 0.0 {
        let first = ((from - origin_t - off) / s).floor();
        let mut k = first;
        loop {
            let x = origin_t + k * s + off;
            if x > to {
                break;
            }
            if x >= from {
                out.push(x);
            }
            k += 1.0;
        }
    }
    out
}

/// Whether every edge of `fp` inside `below` lies on a sample line of the grid `frame`.
fn check_aligned(
    fp: &LonLatRect,
    frame: &GlobeFrame,
    below: &LonLatRect,
) -> std::result::Result<(), String> {
    let on_line = |v: f64, origin: f64, step: f64| {
        let k = (v - origin) / step;
        (k - k.round()).abs() < 1e-6
    };
    for lon in [fp.lon0, fp.lon1] {
        let inside = [-360.0, 0.0, 360.0]
            .iter()
            .any(|t| lon + t > below.lon0 && lon + t < below.lon1);
        let ok = [-360.0, 0.0, 360.0]
            .iter()
            .any(|t| on_line(lon + t, frame.lon0, frame.dlon));
        if inside && !ok {
            return Err(format!(
                "its edge at longitude {lon} is not on a sample line of the grid below (step {}°): \
                 cut-outs must follow the lower grid",
                frame.dlon.abs()
            ));
        }
    }
    for lat in [fp.lat0, fp.lat1] {
        if lat > below.lat0 && lat < below.lat1 && !on_line(lat, frame.lat0, frame.dlat) {
            return Err(format!(
                "its edge at latitude {lat} is not on a sample line of the grid below (step {}°): \
                 cut-outs must follow the lower grid",
                frame.dlat.abs()
            ));
        }
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    fn r(lon0: f64, lon1: f64, lat0: f64, lat1: f64) -> LonLatRect {
        LonLatRect {
            lon0,
            lon1,
            lat0,
            lat1,
        }
    }

    /// Between consecutive breaks the surface along a line is linear (so a gap's maximum is
    /// at a break): rows and columns on and between grid lines, of a coarse random block.
    #[test]
    fn surfaces_are_linear_between_breaks() {
        let (stride, w) = (4u64, 6u32);
        let heights: Vec<f32> = (0..w * w)
            .map(|i| ((i * 7919) % 113) as f32 * 3.5 - 100.0)
            .collect();
        let g = GridBlock {
            rect: SampleRect {
                col0: 8,
                row0: 4,
                col1: 28,
                row1: 24,
            },
            stride,
            grid_width: w,
            grid_height: w,
            heights: &heights,
            error: 0.0,
        };
        for along_row in [true, false] {
            for line in [8.0, 9.0, 10.5, 12.0, 15.0, 23.75] {
                let (from, to) = if along_row { (8.0, 28.0) } else { (4.0, 24.0) };
                let mut ts = grid_breaks(&g, along_row, line, from, to);
                ts.sort_by(f64::total_cmp);
                ts.dedup();
                let at = |t: f64| {
                    let (c, r) = if along_row { (t, line) } else { (line, t) };
                    crate::scene::surface::height_at(&g, c, r)
                };
                for p in ts.windows(2) {
                    for f in [0.25, 0.5, 0.75] {
                        let t = p[0] + f * (p[1] - p[0]);
                        let linear = at(p[0]) + f * (at(p[1]) - at(p[0]));
                        assert!(
                            (at(t) - linear).abs() < 1e-9,
                            "{along_row} line {line}: bends between {} and {}",
                            p[0],
                            p[1]
                        );
                    }
                }
            }
        }
    }

    #[test]
    fn cover_by_pieces_and_across_the_antimeridian() {
        let block = r(0.0, 2.0, 40.0, 42.0);
        assert!(block.covered_by(&[r(0.0, 1.0, 40.0, 42.0), r(1.0, 2.0, 40.0, 42.0)]));
        assert!(!block.covered_by(&[r(0.0, 1.0, 40.0, 42.0), r(1.0, 2.0, 40.0, 41.5)]));
        // A tile given at 179..181 meets a block at -180..-178.
        let west = r(-180.0, -178.0, 0.0, 1.0);
        let clips = west.clips(&r(179.0, 181.0, 0.0, 1.0));
        assert_eq!(clips, vec![r(-180.0, -179.0, 0.0, 1.0)]);
        assert!(r(179.0, 181.0, 0.0, 1.0).contains(-179.5, 0.5));
        // Edges only: no cut.
        assert!(block.clips(&r(2.0, 3.0, 40.0, 42.0)).is_empty());
    }
}
