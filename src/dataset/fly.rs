//! Frames across tiles: the single-file [`Scheduler`] run per tile, each in its own frame
//! (the camera moved back by the tile's offset), with the dataset deciding which tiles take
//! part. A tile joins when its box meets the frustum, or lies within the memory radius of
//! the eye; a tile that no longer does is dropped, its blocks evicted. Each tile's scheduler
//! keeps its resident set, memory ring and budget as it does for a single file.
//!
//! **One prefetcher for the dataset.** With `prefetch`, one thread (not one per tile) takes
//! the camera predicted for the next frame (the last two extrapolated), and for every tile
//! that camera will see, selects that tile's scene and reads and decodes the blocks within
//! `cache_radius` that are neither resident nor warm. The next frame takes its loads from
//! that warm cache when it can, so on a steady path the decoding happens off the frame's
//! thread. What a frame loads never depends on the prefetcher: only where the bytes come
//! from. Entries the newest prediction no longer needs are dropped.
//!
//! On the globe (`ScheduleOptions::globe`) the camera is in ECEF and the same for every tile,
//! each tile placed by the dataset's grid, and tiles join by their ECEF boxes, less those
//! below the horizon, or by the longitude-latitude window of the radii.
//!
//! In uniform mode each tile picks its own bound from its own nearest distance (a dataset
//! scene, [`Dataset::scene`], gives every tile the nearest distance over all of them).

use std::collections::{BTreeMap, HashMap, HashSet};
use std::sync::{Arc, Mutex};
use std::time::Instant;

use glam::DVec3;
use serde::Serialize;

use super::reader::{Dataset, Tile};
use crate::error::Result;
use crate::model::SampleRect;
use crate::scene::schedule::{predict, warm_blocks, BlockId};
use crate::scene::worker::{lock, NewestWorker};
use crate::scene::{
    Camera, FrameStats, GlobeFrame, LoadedBlock, SceneBlock, ScheduleOptions, Scheduler,
    Selection, WorldFrame,
};
use crate::store::{AnySource, ReadStats, Store};

/// One frame over a dataset.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct DatasetFrame {
    /// 0 for the first.
    pub index: u64,
    /// The tiles' frame figures summed; `schedule_ns` includes choosing the tiles. The
    /// frame's wall time is `schedule_ns` plus `load_ns`.
    #[serde(flatten)]
    pub stats: FrameStats,
    /// Tiles scheduled this frame.
    pub tiles: u64,
    /// Tiles dropped this frame (out of every radius), their blocks evicted.
    pub tiles_dropped: u64,
}

/// Keeps the resident set of a moving camera over a dataset.
pub struct DatasetScheduler<'d> {
    dataset: &'d Dataset,
    options: ScheduleOptions,
    frame: WorldFrame,
    /// On the globe: the dataset's grid there.
    globe: Option<GlobeFrame>,
    tiles: BTreeMap<u64, (SampleRect, Scheduler<AnySource>)>,
    frames: u64,
    /// What the tiles read, of schedulers already dropped.
    dropped_reads: ReadStats,
    /// The last two cameras, for the prediction.
    last_cameras: [Option<Camera>; 2],
    prefetcher: Option<Prefetcher>,
}

impl<'d> DatasetScheduler<'d> {
    /// A scheduler over `dataset` (`options.spacing_m` overrides the dataset's spacing). With
    /// `options.globe` the dataset is on the WGS 84 ellipsoid ([`Dataset::globe_frame`]) and
    /// the cameras in ECEF: each tile placed as [`Dataset::scene_on_globe`] places it.
    pub fn new(dataset: &'d Dataset, options: ScheduleOptions) -> Result<Self> {
        let (frame, globe) = if options.globe {
            let g = dataset.globe_frame()?;
            let spacing = options.spacing_m.or(dataset.spacing_m());
            (WorldFrame::new(spacing), Some(g))
        } else {
            (dataset.frame(options.spacing_m)?, None)
        };
        options.check()?;
        Ok(DatasetScheduler {
            dataset,
            options: ScheduleOptions {
                spacing_m: Some([frame.dx, frame.dy]),
                ..options
            },
            frame,
            globe,
            tiles: BTreeMap::new(),
            frames: 0,
            dropped_reads: ReadStats::default(),
            last_cameras: [None, None],
            prefetcher: options.prefetch.then(Prefetcher::start),
        })
    }

    /// The tiles within `radius` metres of the eye (by their rectangles).
    fn near(&self, eye: DVec3, radius: f64) -> Result<Vec<Tile>> {
        if radius <= 0.0 {
            return Ok(Vec::new());
        }
        if let Some(g) = self.globe {
            return self.near_on_globe(&g, eye, radius);
        }
        let grid = self.dataset.grid();
        let span = |v: f64, step: f64, max: u64| -> (u64, u64) {
            let lo = ((v - radius) / step).floor().max(0.0);
            let hi = ((v + radius) / step).ceil().max(0.0);
            ((lo as u64).min(max), (hi as u64).min(max))
        };
        let (c0, c1) = span(eye.x, self.frame.dx, grid.col1);
        let (r0, r1) = span(eye.y, self.frame.dy, grid.row1);
        if eye.x + radius < 0.0 || eye.y + radius < 0.0 {
            return Ok(Vec::new());
        }
        self.dataset.tiles_meeting(&SampleRect {
            col0: c0,
            row0: r0,
            col1: c1,
            row1: r1,
        })
    }

    /// On the globe, the tiles of the longitude-latitude window that holds every point of
    /// the terrain within `radius` metres of `eye`. Terrain is at least 6,300 km from the
    /// Earth's centre, so such a point is at most `2 asin(radius / 12,600 km)` of arc from
    /// the eye's direction; geodetic and geocentric latitudes differ by less than 0.2°.
    fn near_on_globe(&self, g: &GlobeFrame, eye: DVec3, radius: f64) -> Result<Vec<Tile>> {
        const LEAST_RADIUS: f64 = 6_300_000.0;
        let grid = self.dataset.grid();
        let x = radius / (2.0 * LEAST_RADIUS);
        if x >= 1.0 {
            return self.dataset.tiles_meeting(&grid);
        }
        let arc = 2.0 * x.asin().to_degrees() + 0.2;
        let (lon, lat, _) = crate::globe::geodetic(eye);
        let (lat_a, lat_b) = ((lat - arc).max(-90.0), (lat + arc).min(90.0));
        let widest = lat_a.abs().max(lat_b.abs());
        let (ra, rb) = ((lat_a - g.lat0) / g.dlat, (lat_b - g.lat0) / g.dlat);
        let (r0, r1) = (ra.min(rb).floor(), ra.max(rb).ceil());
        if r1 < 0.0 || r0 > grid.row1 as f64 {
            return Ok(Vec::new());
        }
        let clamp = |v: f64, max: u64| (v.max(0.0) as u64).min(max);
        let (r0, r1) = (clamp(r0, grid.row1), clamp(r1, grid.row1));
        // Every longitude when the window reaches a pole or spans half the Earth; else the
        // window once a turn either side too, as the grid's longitudes may run past ±180°.
        let half = if widest >= 90.0 {
            f64::INFINITY
        } else {
            arc / widest.to_radians().cos()
        };
        let spans: Vec<(f64, f64)> = if half >= 180.0 {
            vec![(f64::NEG_INFINITY, f64::INFINITY)]
        } else {
            [-360.0, 0.0, 360.0]
                .iter()
                .map(|t| (lon + t - half, lon + t + half))
                .collect()
        };
        let mut out: BTreeMap<u64, Tile> = BTreeMap::new();
        for (a, b) in spans {
            let (ca, cb) = ((a - g.lon0) / g.dlon, (b - g.lon0) / g.dlon);
            let (c0, c1) = (ca.min(cb).floor(), ca.max(cb).ceil());
            if c1 < 0.0 || c0 > grid.col1 as f64 {
                continue;
            }
            let rect = SampleRect {
                col0: clamp(c0, grid.col1),
                row0: r0,
                col1: clamp(c1, grid.col1),
                row1: r1,
            };
            for t in self.dataset.tiles_meeting(&rect)? {
                out.insert(t.index, t);
            }
        }
        Ok(out.into_values().collect())
    }

    /// What the tiles' files have read since they were opened, schedulers dropped included.
    pub fn read_stats(&self) -> ReadStats {
        self.tiles.values().fold(self.dropped_reads, |a, (_, s)| {
            a.plus(&s.store().read_stats())
        })
    }

    /// Moves to `camera`: every tile the frustum or a radius meets takes its frame.
    pub fn frame(&mut self, camera: &Camera) -> Result<DatasetFrame> {
        let started = Instant::now();
        let mut wanted: BTreeMap<u64, Tile> = BTreeMap::new();
        for t in self.seen(camera)? {
            wanted.insert(t.index, t);
        }
        for t in self.near(camera.eye, self.options.memory_radius)? {
            wanted.insert(t.index, t);
        }
        let mut stats = FrameStats::default();
        let mut dropped = 0;
        let gone: Vec<u64> = self
            .tiles
            .keys()
            .filter(|k| !wanted.contains_key(k))
            .copied()
            .collect();
        for k in gone {
            if let Some((_, s)) = self.tiles.remove(&k) {
                stats.evicted += s.resident().count() as u64;
                self.dropped_reads = self.dropped_reads.plus(&s.store().read_stats());
                dropped += 1;
            }
        }
        let choose_ns = started.elapsed().as_nanos() as u64;
        for (k, t) in &wanted {
            if !self.tiles.contains_key(k) {
                let store = self.dataset.open_tile(t)?;
                let r = t.rect();
                let options = ScheduleOptions {
                    // The dataset's one prefetcher warms every tile.
                    prefetch: false,
                    ..self.tile_options(&r)
                };
                self.tiles.insert(*k, (r, Scheduler::new(store, options)?));
            }
        }
        // Every tile selects its scene, then each loads and evicts in turn (its decoding on
        // the pool). The selections run on this thread: spread over the pool they gained
        // nothing back to back (264 against 268 us a frame at tau 1 over the mosaic) and
        // lost 100 us at 60 frames a second, waking the pool's idle threads.
        let selecting = Instant::now();
        let (globe, frame) = (self.globe, self.frame);
        let local = |r: &SampleRect| tile_camera(globe.is_some(), camera, r, &frame);
        let selections: Vec<Selection> = self
            .tiles
            .values()
            .map(|(r, s)| s.select(&local(r)))
            .collect::<Result<_>>()?;
        let select_ns = selecting.elapsed().as_nanos() as u64;
        let mut tiles = 0;
        let mut evict_ns = 0;
        // The warm cache is locked a block at a time: the prefetch thread fills it meanwhile.
        let warm = self.prefetcher.as_ref().map(|p| Arc::clone(&p.cache));
        for ((k, (r, s)), selection) in self.tiles.iter_mut().zip(selections) {
            let selected_ns = selection.schedule_ns();
            let f = match &warm {
                Some(cache) => s.apply_warmed(&local(r), selection, &mut |b: &SceneBlock| {
                    lock(cache)
                        .remove(&(*k, BlockId::of(b)))
                        .filter(|(cb, _)| cb.payload == b.payload)
                        .map(|(_, loaded)| loaded)
                })?,
                None => s.apply(&local(r), selection)?,
            };
            stats.merge(&f.stats);
            evict_ns += f.stats.schedule_ns.saturating_sub(selected_ns);
            tiles += 1;
        }
        stats.schedule_ns = choose_ns + select_ns + evict_ns;
        self.last_cameras = [self.last_cameras[1], Some(*camera)];
        if let Some(predicted) = predict(&self.last_cameras).filter(|_| self.prefetcher.is_some()) {
            self.ask_prefetch(&predicted);
        }
        let index = self.frames;
        self.frames += 1;
        Ok(DatasetFrame {
            index,
            stats,
            tiles,
            tiles_dropped: dropped,
        })
    }

    /// The tiles `camera`'s frustum meets.
    fn seen(&self, camera: &Camera) -> Result<Vec<Tile>> {
        match self.globe {
            Some(_) => self.dataset.scene_tiles_on_globe(camera, None),
            None => self.dataset.scene_tiles(camera, None, &self.frame),
        }
    }

    /// The options of the tile whose samples are `r`: on the globe, placed where the
    /// dataset's grid puts it.
    fn tile_options(&self, r: &SampleRect) -> ScheduleOptions {
        ScheduleOptions {
            globe_frame: self.globe.map(|g| g.at_sample(r.col0, r.row0)),
            ..self.options
        }
    }

    /// Waits for the prefetch thread to finish every request made so far.
    pub fn wait_prefetch(&self) {
        if let Some(p) = &self.prefetcher {
            p.wait();
        }
    }

    /// Asks the prefetcher to warm what `predicted` will see: each tile its frustum meets,
    /// with the tile's resident blocks left out. Prefetch is a hint: a prediction that fails
    /// (a camera the next frame will refuse too) or a tile that does not open warms nothing,
    /// and the frame that needs it reads (and reports) it.
    fn ask_prefetch(&mut self, predicted: &Camera) {
        let Ok(seen) = self.seen(predicted) else {
            return;
        };
        let mut batch = Vec::with_capacity(seen.len());
        for t in seen {
            let r = t.rect();
            let (store, have) = match self.tiles.get(&t.index) {
                Some((_, s)) => (
                    Arc::clone(s.store()),
                    s.resident().map(BlockId::of).collect(),
                ),
                None => match self.dataset.open_tile(&t) {
                    Ok(store) => (store, HashSet::new()),
                    Err(_) => continue,
                },
            };
            batch.push(TileRequest {
                tile: t.index,
                store,
                camera: tile_camera(self.globe.is_some(), predicted, &r, &self.frame),
                options: self.tile_options(&r),
                have,
            });
        }
        if let Some(p) = &mut self.prefetcher {
            p.ask(batch);
        }
    }
}

/// The tiles' schedulers share the dataset's tile cache: a tile dropped and met again is
/// scheduled anew but not opened again while it stays among the dataset's open tiles.
impl std::fmt::Debug for DatasetScheduler<'_> {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("DatasetScheduler")
            .field("tiles", &self.tiles.keys().collect::<Vec<_>>())
            .field("frames", &self.frames)
            .finish_non_exhaustive()
    }
}

/// `camera` as the tile whose samples are `r` takes it: in its own frame on flat ground
/// ([`super::in_tile`]); on the globe every tile takes the ECEF camera as it is.
fn tile_camera(on_globe: bool, camera: &Camera, r: &SampleRect, frame: &WorldFrame) -> Camera {
    if on_globe {
        *camera
    } else {
        super::in_tile(camera, r, frame)
    }
}

/// Blocks warmed for the next frame, by tile and block.
type WarmCache = Arc<Mutex<HashMap<(u64, BlockId), (SceneBlock, LoadedBlock)>>>;

/// What the prefetcher warms for one tile.
struct TileRequest {
    tile: u64,
    store: Arc<Store<AnySource>>,
    /// The predicted camera in the tile's frame.
    camera: Camera,
    options: ScheduleOptions,
    /// The tile's resident blocks.
    have: HashSet<BlockId>,
}

/// The dataset's prefetch thread and its warm cache.
struct Prefetcher {
    cache: WarmCache,
    worker: NewestWorker<Vec<TileRequest>>,
}

impl Prefetcher {
    fn start() -> Prefetcher {
        let cache: WarmCache = Arc::default();
        let thread_cache = Arc::clone(&cache);
        let worker = NewestWorker::start("fmrh-dataset-prefetch", move |batch| {
            warm(&thread_cache, batch);
        });
        Prefetcher { cache, worker }
    }

    fn ask(&mut self, batch: Vec<TileRequest>) {
        self.worker.ask(batch);
    }

    fn wait(&self) {
        self.worker.wait();
    }
}

/// Warms each tile of `batch`, then drops what the prediction no longer sees.
fn warm(cache: &WarmCache, batch: Vec<TileRequest>) {
    let mut wanted: HashSet<(u64, BlockId)> = HashSet::new();
    for t in batch {
        let Ok(terrain) = t.options.terrain(&t.store) else {
            continue;
        };
        let (ids, warmed) = warm_blocks(&terrain, &t.options, &t.camera, |id| {
            t.have.contains(id) || lock(cache).contains_key(&(t.tile, *id))
        });
        wanted.extend(ids.into_iter().map(|id| (t.tile, id)));
        let mut c = lock(cache);
        for (b, l) in warmed {
            c.insert((t.tile, BlockId::of(&b)), (b, l));
        }
    }
    lock(cache).retain(|k, _| wanted.contains(k));
}
