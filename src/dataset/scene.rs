//! Scenes across tiles (`docs/datasets-design.md` §4). A dataset scene is the single-file
//! scene run on each tile the view meets, in the dataset's one world frame: tile `t`'s
//! terrain lies `(col0·dx, row0·dy)` from the dataset's origin, so its scene sees the camera
//! moved back by as much. Tiles meet only along shared edge lines, so the tiles' covers
//! together cover the view once: no hole (but the dataset's own holes), no overlap.
//!
//! On the globe ([`Dataset::scene_on_globe`], `docs/globe-design.md` §2) the world frame is
//! ECEF: each tile's grid is placed at the longitudes and latitudes the dataset's
//! georeference gives its samples, the camera is the same for every tile, and tiles wholly
//! below the horizon are not opened.
//!
//! Only the tiles whose box (their rectangle by their height range, both in the manifest)
//! meets the frustum or the window are opened, and only the manifest's tile pages whose
//! boxes meet it are read. Neighbour levels across a tile border are filled in from the
//! blocks on the other side, in the block's own tile's level scale (the level whose blocks
//! have the same sample stride), so a renderer stitches there as inside a tile.

use glam::DVec3;
use serde::Serialize;

use super::reader::{Dataset, Tile};
use crate::error::{Error, Result};
use crate::model::SampleRect;
use crate::scene::{DEFAULT_GAP, 
    Aabb, Camera, GlobeFrame, Mode, NeighbourLevels, SceneBlock, SceneOptions, SceneStats, Terrain,
    TerrainFrame, View, WorldFrame,
};
use crate::store::ReadStats;

/// A block of a dataset scene: a tile's scene block, its rectangle moved into dataset
/// samples (its level, `x`, `y`, key and payload stay the tile's own).
#[derive(Clone, Copy, Debug, PartialEq, Serialize)]
pub struct DatasetBlock {
    /// The tile's index in the manifest.
    pub tile: u64,
    /// The block.
    #[serde(flatten)]
    pub block: SceneBlock,
}

/// What one tile contributed.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct TilePart {
    /// The tile's index.
    pub tile: u64,
    /// Its file.
    pub name: String,
    /// The samples of it the scene covers, in dataset coordinates.
    pub window: Option<SampleRect>,
    /// Its blocks.
    pub blocks: u64,
    /// Uniform mode: the cluster its blocks come from (`None`: physical blocks).
    pub cluster: Option<usize>,
    /// What scheduling read from its file.
    pub reads: ReadStats,
}

/// A scene over a dataset.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct DatasetScene {
    /// The mode.
    pub mode: Mode,
    /// The tolerance in pixels.
    pub tau: f64,
    /// The window, or the samples the tiles' frustum footprints span, in dataset samples.
    pub window: Option<SampleRect>,
    /// The blocks, by tile, then by key.
    pub blocks: Vec<DatasetBlock>,
    /// The tiles' statistics summed (blocks, bytes, scans, reads) or maximised (errors); in
    /// uniform mode `p_min` and `allowed_error` are the dataset's, and `threshold` the
    /// largest any tile used.
    pub stats: SceneStats,
    /// Each tile the scene met.
    pub tiles: Vec<TilePart>,
}

/// The box of `rect` (dataset samples) between `lo` and `hi` in `world`; an empty range (an
/// all-void tile) is taken as height 0.
fn rect_box(world: &TerrainFrame, rect: &SampleRect, lo: f32, hi: f32) -> Aabb {
    let (lo, hi) = if lo <= hi { (lo, hi) } else { (0.0, 0.0) };
    world.rect_box(rect, f64::from(lo), f64::from(hi))
}

/// Whether `view` may see anything of `rect` between `lo` and `hi`: its box meets the
/// frustum and, on the globe, it is not wholly below the horizon.
fn may_see(world: &TerrainFrame, view: &View, rect: &SampleRect, lo: f32, hi: f32) -> bool {
    let top = if lo <= hi { hi } else { 0.0 };
    view.intersects(&rect_box(world, rect, lo, hi)) && !world.hidden(view.eye, rect, f64::from(top))
}

impl Dataset {
    /// The world frame of the dataset: its spacing, or `spacing_m` when given.
    pub fn frame(&self, spacing_m: Option<[f64; 2]>) -> Result<WorldFrame> {
        match spacing_m.or(self.spacing_m()) {
            Some(s) => Ok(WorldFrame::new(Some(s))),
            None => Err(Error::InvalidArgument(format!(
                "{}: the distance between samples is unknown, so a camera in metres cannot be \
                 placed; give --spacing DX[,DY] in metres",
                self.dir().display()
            ))),
        }
    }

    /// The dataset's grid on the WGS 84 ellipsoid: sample `(col, row)` of the dataset at the
    /// longitude and latitude its georeference gives. An error unless the dataset has a
    /// geographic georeference (its tiles were placed by SRTM names or geographic
    /// GeoTIFFs). Heights above the EGM96 geoid are placed on the ellipsoid.
    pub fn globe_frame(&self) -> Result<GlobeFrame> {
        let g = self.georeference().ok_or_else(|| {
            Error::InvalidArgument(format!(
                "{}: the globe frame needs a georeferenced dataset; this one has no \
                 georeference (its tiles were placed by a layout)",
                self.dir().display()
            ))
        })?;
        GlobeFrame::of(&g)?.with_datum(self.vertical_datum()?)
    }

    /// The tiles a scene may need: those whose boxes meet `window` (dataset samples), or the
    /// frustum when there is no window. Reads only the tile pages whose boxes meet it.
    pub fn scene_tiles(
        &self,
        camera: &Camera,
        window: Option<SampleRect>,
        frame: &WorldFrame,
    ) -> Result<Vec<Tile>> {
        self.tiles_seen(camera, window, &TerrainFrame::Flat(*frame))
    }

    /// [`Dataset::scene_tiles`] on the globe: the tiles whose ECEF boxes meet the frustum
    /// (or `window`), less those wholly below the horizon.
    pub fn scene_tiles_on_globe(
        &self,
        camera: &Camera,
        window: Option<SampleRect>,
    ) -> Result<Vec<Tile>> {
        self.tiles_seen(camera, window, &TerrainFrame::Globe(self.globe_frame()?))
    }

    fn tiles_seen(
        &self,
        camera: &Camera,
        window: Option<SampleRect>,
        world: &TerrainFrame,
    ) -> Result<Vec<Tile>> {
        let view = camera.view()?;
        match window {
            Some(w) => self.tiles_meeting(&w),
            None => {
                let head = &self.state().head;
                let mut out = Vec::new();
                let seen: Vec<usize> = (0..head.pages.len())
                    .filter(|&p| {
                        let e = &head.pages[p];
                        may_see(
                            world,
                            &view,
                            &e.rect(),
                            e.min_height.get(),
                            e.max_height.get(),
                        )
                    })
                    .collect();
                self.state().fetch_pages(self.manifest_source(), &seen)?;
                for p in seen {
                    let e = &head.pages[p];
                    let first = u64::from(e.first_tile.get());
                    for (i, t) in self
                        .state()
                        .page(self.manifest_source(), p)?
                        .iter()
                        .enumerate()
                    {
                        if may_see(
                            world,
                            &view,
                            &t.rect(),
                            t.min_height.get(),
                            t.max_height.get(),
                        ) {
                            out.push(Tile {
                                index: first + i as u64,
                                record: *t,
                            });
                        }
                    }
                }
                Ok(out)
            }
        }
    }

    /// The blocks `camera` (in the dataset's world frame) needs at `options.tau`, with
    /// `options.window` in dataset samples. `spacing_m` overrides the dataset's spacing.
    pub fn scene(
        &self,
        camera: &Camera,
        options: &SceneOptions,
        spacing_m: Option<[f64; 2]>,
    ) -> Result<DatasetScene> {
        let frame = self.frame(spacing_m)?;
        self.scene_in(camera, options, TerrainFrame::Flat(frame))
    }

    /// The blocks `camera` (ECEF metres) needs at `options.tau` with the dataset on the WGS
    /// 84 ellipsoid ([`Dataset::globe_frame`]): each tile's scene on the globe
    /// ([`Terrain::on_globe`]'s, its grid placed by the dataset's georeference), tiles and
    /// blocks wholly below the horizon culled, distances true 3D distances. The tiles meet
    /// along shared sample lines as in the flat frame, so the cover is one cover still.
    pub fn scene_on_globe(&self, camera: &Camera, options: &SceneOptions) -> Result<DatasetScene> {
        let globe = self.globe_frame()?;
        self.scene_in(camera, options, TerrainFrame::Globe(globe))
    }

    /// The cut of the dataset within the static bound `max_error` over `window` (dataset
    /// samples): each tile's [`Terrain::cut`] over its part of the window, moved into
    /// dataset samples. Every tile's cut is a cut of its whole tree, so two windows get the
    /// same blocks wherever they overlap.
    pub fn cut(&self, window: SampleRect, max_error: f64) -> Result<DatasetScene> {
        let started = std::time::Instant::now();
        window.check_inside(&self.grid(), "dataset")?;
        let tiles = self.tiles_meeting(&window)?;
        let per_tile = self.for_tiles(&tiles, |tile| {
            let r = tile.rect();
            let Some(p) = window.intersect(&r) else {
                return Ok(None);
            };
            let local = unshifted(&p, &r);
            let store = self.open_tile(tile)?;
            let before = store.read_stats();
            let scene = Terrain::with_spacing(&store, None)?.cut(local, max_error, DEFAULT_GAP)?;
            let reads = store.read_stats().since(&before);
            Ok(Some((store, scene, reads)))
        })?;
        let (blocks, parts, mut stats) = assemble(&tiles, per_tile);
        stats.schedule_ns = started.elapsed().as_nanos() as u64;
        Ok(DatasetScene {
            mode: Mode::Uniform,
            tau: 0.0,
            window: Some(window),
            blocks,
            stats,
            tiles: parts,
        })
    }

    fn scene_in(
        &self,
        camera: &Camera,
        options: &SceneOptions,
        world: TerrainFrame,
    ) -> Result<DatasetScene> {
        let started = std::time::Instant::now();
        let view = camera.view()?;
        if let Some(w) = options.window {
            let grid = self.grid();
            w.check_inside(&grid, "dataset")?;
        }
        let tiles = self.tiles_seen(camera, options.window, &world)?;
        // Uniform mode: one static bound over the view, from the nearest tile part.
        let p_min = (options.mode == Mode::Uniform).then(|| {
            tiles
                .iter()
                .map(|t| {
                    let part = options
                        .window
                        .and_then(|w| w.intersect(&t.rect()))
                        .unwrap_or(t.rect());
                    rect_box(
                        &world,
                        &part,
                        t.record.min_height.get(),
                        t.record.max_height.get(),
                    )
                    .distance(view.eye)
                })
                .fold(f64::INFINITY, f64::min)
        });
        // Each tile's scene: one after another from local files; from a remote dataset, up
        // to [`TILE_WORKERS`] tiles at once, so that their rounds overlap.
        let per_tile = self.for_tiles(&tiles, |tile| {
            let r = tile.rect();
            let local_window = match options.window {
                Some(w) => match w.intersect(&r) {
                    Some(p) => Some(unshifted(&p, &r)),
                    None => return Ok(None),
                },
                None => None,
            };
            let store = self.open_tile(tile)?;
            let before = store.read_stats();
            let (terrain, local_camera) = match world {
                TerrainFrame::Flat(frame) => (
                    Terrain::with_spacing(&store, Some([frame.dx, frame.dy]))?,
                    in_tile(camera, &r, &frame),
                ),
                TerrainFrame::Globe(g) => {
                    // The tile's samples where the dataset's grid puts them, so that
                    // neighbours meet on exactly the same longitudes and latitudes.
                    let tile_frame = g.at_sample(r.col0, r.row0);
                    let flat = WorldFrame::new(store.header().metadata.spacing_m);
                    let t = Terrain::with_frame(&store, flat, TerrainFrame::Globe(tile_frame))?;
                    (t, *camera)
                }
            };
            let tile_options = SceneOptions {
                window: local_window,
                ..*options
            };
            let scene = terrain.scene_with(&local_camera, &tile_options, p_min)?;
            let reads = store.read_stats().since(&before);
            Ok(Some((store, scene, reads)))
        })?;
        let (blocks, parts, mut stats) = assemble(&tiles, per_tile);
        let window = parts
            .iter()
            .filter_map(|p| p.window)
            .reduce(|a, b| SampleRect {
                col0: a.col0.min(b.col0),
                row0: a.row0.min(b.row0),
                col1: a.col1.max(b.col1),
                row1: a.row1.max(b.row1),
            });
        stats.schedule_ns = started.elapsed().as_nanos() as u64;
        Ok(DatasetScene {
            mode: options.mode,
            tau: options.tau,
            window: options.window.or(window),
            blocks,
            stats,
            tiles: parts,
        })
    }
}

/// `camera` (in the dataset's world frame) as the tile whose samples are `tile` sees it in
/// its own frame: moved back by the tile's offset.
pub fn in_tile(camera: &Camera, tile: &SampleRect, frame: &WorldFrame) -> Camera {
    let shift = DVec3::new(
        tile.col0 as f64 * frame.dx,
        tile.row0 as f64 * frame.dy,
        0.0,
    );
    Camera {
        eye: camera.eye - shift,
        target: camera.target - shift,
        ..*camera
    }
}

/// Each tile's scene (`None`: the tile had no part) as one dataset scene's blocks (moved
/// into dataset samples, border neighbours set), tile parts and summed stats.
fn assemble<S: std::ops::Deref<Target = crate::store::Store<crate::store::AnySource>>>(
    tiles: &[Tile],
    per_tile: Vec<Option<(S, crate::scene::Scene, ReadStats)>>,
) -> (Vec<DatasetBlock>, Vec<TilePart>, SceneStats) {
    let mut blocks = Vec::new();
    let mut parts = Vec::new();
    let mut stats = SceneStats::default();
    let mut finest = Vec::new();
    for (tile, done) in tiles.iter().zip(per_tile) {
        let Some((store, scene, reads)) = done else {
            continue;
        };
        let r = tile.rect();
        stats.merge(&scene.stats);
        parts.push(TilePart {
            tile: tile.index,
            name: tile.name().to_string(),
            window: scene.window.map(|w| shifted(&w, &r)),
            blocks: scene.blocks.len() as u64,
            cluster: scene.stats.cluster,
            reads,
        });
        let fl = store.domain().finest_level();
        for mut block in scene.blocks {
            let w = shifted(&block.rect(), &r);
            (block.col0, block.row0, block.col1, block.row1) = (w.col0, w.row0, w.col1, w.row1);
            blocks.push(DatasetBlock {
                tile: tile.index,
                block,
            });
            finest.push((fl, store.domain().block_size(), r));
        }
    }
    set_border_neighbours(&mut blocks, &finest);
    (blocks, parts, stats)
}

/// `rect` (dataset samples, inside `tile`) in the tile's own samples.
fn unshifted(rect: &SampleRect, tile: &SampleRect) -> SampleRect {
    SampleRect {
        col0: rect.col0 - tile.col0,
        row0: rect.row0 - tile.row0,
        col1: rect.col1 - tile.col0,
        row1: rect.row1 - tile.row0,
    }
}

/// `rect` in a tile whose first sample is `tile`'s, moved into dataset samples.
fn shifted(rect: &SampleRect, tile: &SampleRect) -> SampleRect {
    SampleRect {
        col0: rect.col0 + tile.col0,
        row0: rect.row0 + tile.row0,
        col1: rect.col1 + tile.col0,
        row1: rect.row1 + tile.row0,
    }
}

/// Whether two spans of sample lines `[a0, a1]` and `[b0, b1]` share a positive length (or
/// a point, when one of them is a single line).
fn spans_meet(a0: u64, a1: u64, b0: u64, b1: u64) -> bool {
    let (lo, hi) = (a0.max(b0), a1.min(b1));
    lo < hi || (lo == hi && (a0 == a1 || b0 == b1))
}

/// Fills in the neighbour levels of blocks on tile borders from the blocks of the tiles
/// across. `geometry[i]` is block `i`'s tile's finest level, block size and rectangle.
fn set_border_neighbours(blocks: &mut [DatasetBlock], geometry: &[(u8, u32, SampleRect)]) {
    use std::collections::HashMap;
    // Blocks on each tile edge, keyed by the edge's line: (side, column or row).
    let mut edges: HashMap<(usize, u64), Vec<usize>> = HashMap::new();
    for (i, b) in blocks.iter().enumerate() {
        let t = geometry[i].2;
        let r = b.block.rect();
        if r.row0 == t.row0 {
            edges.entry((0, r.row0)).or_default().push(i);
        }
        if r.col1 == t.col1 {
            edges.entry((1, r.col1)).or_default().push(i);
        }
        if r.row1 == t.row1 {
            edges.entry((2, r.row1)).or_default().push(i);
        }
        if r.col0 == t.col0 {
            edges.entry((3, r.col0)).or_default().push(i);
        }
    }
    let mut updates = Vec::new();
    for (&(side, line), own) in &edges {
        // Across side `side` lie the blocks on the opposite side of another tile, on the
        // same line (a shared edge) or the next (tiles that meet without sharing).
        let opposite = (side + 2) % 4;
        let across: Vec<u64> = match side {
            0 | 3 => vec![line, line.wrapping_sub(1)],
            _ => vec![line, line + 1],
        };
        for &i in own {
            let bi = blocks[i];
            let (fi, bsi, _) = geometry[i];
            let mut levels: Option<NeighbourLevels> = None;
            // The shared line first; the next line (abutting tiles) only when nothing shares it,
            // so that a tile between two others is the neighbour, not the one beyond it.
            for &l in &across {
                if levels.is_some() {
                    break;
                }
                let Some(others) = edges.get(&(opposite, l)) else {
                    continue;
                };
                for &j in others {
                    let bj = blocks[j];
                    if bj.tile == bi.tile {
                        continue;
                    }
                    let (ri, rj) = (bi.block.rect(), bj.block.rect());
                    let meets = match side {
                        0 | 2 => spans_meet(ri.col0, ri.col1, rj.col0, rj.col1),
                        _ => spans_meet(ri.row0, ri.row1, rj.row0, rj.row1),
                    };
                    if !meets {
                        continue;
                    }
                    // The level of the same stride in block i's tile.
                    let (fj, bsj, _) = geometry[j];
                    let steps_j = i64::from(fj) - i64::from(bj.block.level);
                    let level = if bsi == bsj {
                        (i64::from(fi) - steps_j).clamp(0, i64::from(u8::MAX)) as u8
                    } else {
                        bj.block.level
                    };
                    levels = Some(match levels {
                        None => NeighbourLevels {
                            coarsest: level,
                            finest: level,
                        },
                        Some(n) => NeighbourLevels {
                            coarsest: n.coarsest.min(level),
                            finest: n.finest.max(level),
                        },
                    });
                }
            }
            if let Some(n) = levels {
                updates.push((i, side, n));
            }
        }
    }
    for (i, side, n) in updates {
        let slot = &mut blocks[i].block.neighbours[side];
        *slot = Some(match *slot {
            None => n,
            Some(m) => NeighbourLevels {
                coarsest: m.coarsest.min(n.coarsest),
                finest: m.finest.max(n.finest),
            },
        });
    }
}

impl DatasetScene {
    /// The part of the scene in `tile` (whose rectangle is `rect`), as that tile's own scene:
    /// its blocks moved back into the tile's samples.
    pub fn tile_scene(&self, tile: u64, rect: &SampleRect) -> crate::scene::Scene {
        let back = |r: &SampleRect| SampleRect {
            col0: r.col0 - rect.col0,
            row0: r.row0 - rect.row0,
            col1: r.col1 - rect.col0,
            row1: r.row1 - rect.row0,
        };
        let blocks: Vec<SceneBlock> = self
            .blocks
            .iter()
            .filter(|b| b.tile == tile)
            .map(|b| {
                let mut block = b.block;
                let r = back(&b.block.rect());
                (block.col0, block.row0, block.col1, block.row1) = (r.col0, r.row0, r.col1, r.row1);
                block
            })
            .collect();
        crate::scene::Scene {
            mode: self.mode,
            tau: self.tau,
            window: self
                .tiles
                .iter()
                .find(|p| p.tile == tile)
                .and_then(|p| p.window)
                .map(|w| back(&w)),
            blocks,
            stats: SceneStats::default(),
        }
    }
}

impl Dataset {
    /// Reads and decodes every block of `scene`, tile by tile (each tile's payloads in
    /// coalesced runs), as a renderer would. Returns what that read from the tiles.
    pub fn load(&self, scene: &DatasetScene) -> Result<ReadStats> {
        let tiles = scene
            .tiles
            .iter()
            .map(|part| self.tile(part.tile))
            .collect::<Result<Vec<_>>>()?;
        let reads = self.for_tiles(&tiles, |tile| {
            let store = self.open_tile(tile)?;
            let before = store.read_stats();
            let s = scene.tile_scene(tile.index, &tile.rect());
            crate::scene::load_blocks(&store, &s.blocks, crate::scene::PAYLOAD_GAP)?;
            Ok(store.read_stats().since(&before))
        })?;
        Ok(reads
            .iter()
            .fold(ReadStats::default(), |total, r| total.plus(r)))
    }

    /// Every block of `scene`, read and decoded (tile by tile, each tile's payloads in
    /// coalesced runs), in the scene's order, with the sample stride of each block's grid
    /// (its tile's).
    pub fn load_blocks(
        &self,
        scene: &DatasetScene,
    ) -> Result<Vec<(crate::scene::LoadedBlock, u64)>> {
        let mut out: Vec<Option<(crate::scene::LoadedBlock, u64)>> = vec![None; scene.blocks.len()];
        for part in &scene.tiles {
            let tile = self.tile(part.tile)?;
            let store = self.open_tile(&tile)?;
            let d = *store.domain();
            let s = scene.tile_scene(part.tile, &tile.rect());
            let loaded = crate::scene::load_blocks(&store, &s.blocks, crate::scene::PAYLOAD_GAP)?;
            let places = (0..scene.blocks.len()).filter(|&i| scene.blocks[i].tile == part.tile);
            for ((i, l), b) in places.zip(loaded).zip(&s.blocks) {
                out[i] = Some((l, d.stride(b.level)));
            }
        }
        out.into_iter()
            .enumerate()
            .map(|(i, l)| {
                l.ok_or_else(|| {
                    Error::InvalidArgument(format!(
                        "scene block {i} names a tile the scene did not meet"
                    ))
                })
            })
            .collect()
    }

    /// Samples `window` (dataset samples) from `scene`'s blocks, tile by tile: the surface
    /// the scene draws. Samples no block owns (holes, or outside the scene) are NaN.
    pub fn reconstruct(
        &self,
        scene: &DatasetScene,
        window: SampleRect,
    ) -> Result<crate::scene::Reconstruction> {
        let grid = self.grid();
        window.check_inside(&grid, "dataset")?;
        let w = (window.col1 - window.col0 + 1) as usize;
        let h = (window.row1 - window.row0 + 1) as usize;
        let mut values = vec![f64::NAN; w * h];
        let mut bound = vec![f64::NAN; w * h];
        let mut stride = 0;
        for part in &scene.tiles {
            let tile = self.tile(part.tile)?;
            let r = tile.rect();
            let Some(p) = r.intersect(&window) else {
                continue;
            };
            let store = self.open_tile(&tile)?;
            let local = SampleRect {
                col0: p.col0 - r.col0,
                row0: p.row0 - r.row0,
                col1: p.col1 - r.col0,
                row1: p.row1 - r.row0,
            };
            let rec = crate::scene::reconstruct(&store, &scene.tile_scene(part.tile, &r), local)?;
            if rec.stride != 0 {
                stride = if stride == 0 { rec.stride } else { stride.min(rec.stride) };
            }
            let pw = (p.col1 - p.col0 + 1) as usize;
            for y in 0..(p.row1 - p.row0 + 1) as usize {
                for x in 0..pw {
                    let v = rec.values[y * pw + x];
                    if v.is_nan() {
                        continue;
                    }
                    let at = ((p.row0 - window.row0) as usize + y) * w
                        + (p.col0 - window.col0) as usize
                        + x;
                    values[at] = v;
                    bound[at] = rec.bound[y * pw + x];
                }
            }
        }
        let uncovered = values.iter().filter(|v| v.is_nan()).count() as u64;
        Ok(crate::scene::Reconstruction {
            window,
            values,
            bound,
            uncovered,
            stride,
        })
    }
}
