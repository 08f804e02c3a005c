//! Frames: the resident set kept across views, loaded incrementally, with prefetch and
//! phased residency.
//!
//! Each frame the [`Scheduler`] selects the scene `D` for the new camera and loads only
//! `D − (D_old ∩ D)` (seed 000 Algorithm 3, step 7), or rather only `D − R` with `R` every
//! block still resident, which is never more. Residency follows seed 002's three areas,
//! measured from the eye to each block's box:
//!
//! * **visible**: the blocks of `D`, always resident;
//! * **memory area** (within `memory_radius`): blocks that left the view stay resident, so
//!   turning back costs nothing, until the resident bytes exceed `memory_budget`; then the
//!   least recently visible go first (ties by key, so runs are reproducible);
//! * **cache area** (within `cache_radius`): the prefetch thread predicts the next camera
//!   by extrapolating the last two (eye and target move on as they moved), selects that
//!   scene, and reads the blocks the scheduler lacks into a warm cache (payloads read,
//!   CRC-checked and decoded, what `madvise(WILLNEED)` would only hint). Entries that drift beyond
//!   `cache_radius` are dropped. The next frame takes its loads from the cache when it can.
//!
//! What a frame loads, keeps and evicts depends only on the cameras, never on the prefetch
//! thread's timing: prefetch changes where bytes come from, not which.
//!
//! **Decoded once.** A loaded block is kept decoded ([`LoadedBlock`]: the heights it draws)
//! for as long as it is resident, so a fly-through decodes each block once, when it enters
//! (or when the prefetcher warms it), never per frame. A frame's missing blocks are read
//! together, with adjacent payloads coalesced into one read ([`super::load`]).

use std::collections::{HashMap, HashSet};
use std::sync::{Arc, Mutex};
use std::time::Instant;

use serde::Serialize;

use crate::error::Result;
use crate::format::StoredNode;
use crate::store::{Source, Store};

use super::camera::{Camera, GlobeFrame, TerrainFrame, WorldFrame};
use super::load::{load_blocks, load_blocks_reusing, LoadedBlock, PAYLOAD_GAP};
use super::worker::{lock, NewestWorker};
use super::terrain::block_box;
use super::{Scene, SceneBlock, SceneOptions, Terrain};

/// A block's identity: level and position (a node, or a physical block below a leaf).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, PartialOrd, Ord, Serialize)]
pub struct BlockId {
    /// Level.
    pub level: u8,
    /// Column among the level's nodes.
    pub x: u32,
    /// Row among the level's nodes.
    pub y: u32,
}

impl BlockId {
    /// The id of a scene block.
    pub fn of(b: &SceneBlock) -> BlockId {
        BlockId {
            level: b.level,
            x: b.x,
            y: b.y,
        }
    }
}

/// How the scheduler keeps blocks.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ScheduleOptions {
    /// How each frame's scene is selected.
    pub scene: SceneOptions,
    /// Metres: blocks out of view but this close to the eye stay resident.
    pub memory_radius: f64,
    /// Metres: the prefetcher warms predicted blocks this close; farther cache entries are
    /// dropped.
    pub cache_radius: f64,
    /// Resident bytes (stored payloads and their decoded heights) beyond which out-of-view
    /// blocks are evicted (visible blocks never are).
    pub memory_budget: u64,
    /// Run the prefetch thread.
    pub prefetch: bool,
    /// Ground spacing `[east, south]` in metres, instead of the store's (see
    /// [`Terrain::with_spacing`]).
    pub spacing_m: Option<[f64; 2]>,
    /// The store's samples on the WGS 84 ellipsoid and the cameras in ECEF metres
    /// ([`Terrain::on_globe`]; `spacing_m` is then unused).
    pub globe: bool,
    /// With `globe`: where the samples are, instead of the store's own georeference (a
    /// dataset places each tile by the dataset's grid).
    pub globe_frame: Option<GlobeFrame>,
}

impl ScheduleOptions {
    /// View-dependent scenes at `tau`, no memory ring, no prefetch, 256 MiB budget.
    #[cfg(any(test, feature = "testing"))]
    pub fn new(tau: f64) -> ScheduleOptions {
        ScheduleOptions {
            scene: SceneOptions::new(tau),
            memory_radius: 0.0,
            cache_radius: 0.0,
            memory_budget: 256 << 20,
            prefetch: false,
            spacing_m: None,
            globe: false,
            globe_frame: None,
        }
    }

    /// Checks the radii: finite and at least 0.
    pub fn check(&self) -> Result<()> {
        for (what, v) in [
            ("memory radius", self.memory_radius),
            ("cache radius", self.cache_radius),
        ] {
            if !(v.is_finite() && v >= 0.0) {
                return Err(crate::error::Error::InvalidArgument(format!(
                    "{what} {v}: must be finite and >= 0"
                )));
            }
        }
        Ok(())
    }

    /// The terrain these options select scenes on: flat, or on the globe.
    pub(crate) fn terrain<'s, S: Source>(&self, store: &'s Store<S>) -> Result<Terrain<'s, S>> {
        match (self.globe, self.globe_frame) {
            (false, _) => Terrain::with_spacing(store, self.spacing_m),
            (true, None) => Terrain::on_globe(store),
            (true, Some(g)) => Terrain::with_frame(
                store,
                WorldFrame::new(store.header().metadata.spacing_m),
                TerrainFrame::Globe(g),
            ),
        }
    }
}

/// What one frame changed.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct Frame {
    /// 0 for the first.
    pub index: u64,
    /// Blocks loaded for this frame (in view, not resident before), sorted by key.
    pub load: Vec<BlockId>,
    /// Blocks in view that were already resident.
    pub keep: Vec<BlockId>,
    /// Blocks no longer resident.
    pub evict: Vec<BlockId>,
    /// Counts and costs.
    pub stats: FrameStats,
}

/// A frame's scene and what of it is missing: [`Scheduler::select`]'s answer, which
/// [`Scheduler::apply`] acts on.
#[derive(Clone, Debug)]
pub struct Selection {
    scene: Scene,
    /// Scene blocks not resident, in scene order.
    load: Vec<SceneBlock>,
    /// Scene blocks already resident.
    keep: Vec<BlockId>,
    /// Where the terrain's samples are (eviction measures blocks in it).
    world: TerrainFrame,
    /// Time the selection took, in nanoseconds.
    schedule_ns: u64,
}

impl Selection {
    /// Time the selection took, in nanoseconds.
    pub fn schedule_ns(&self) -> u64 {
        self.schedule_ns
    }
}

/// A frame's figures (seed 000 Table 2 and more).
#[derive(Clone, Copy, Debug, Default, PartialEq, Serialize)]
pub struct FrameStats {
    /// Blocks in view.
    pub visible: u64,
    /// Blocks loaded.
    pub loaded: u64,
    /// Triangles of the loaded blocks.
    pub loaded_triangles: u64,
    /// Payload bytes loaded: the blocks', and the grids the blocks are coded against
    /// (format 4).
    pub loaded_bytes: u64,
    /// Loaded blocks the prefetcher had already read.
    pub prefetch_hits: u64,
    /// Blocks evicted.
    pub evicted: u64,
    /// Resident blocks after the frame (visible + memory area).
    pub resident: u64,
    /// Resident bytes after the frame: stored payloads and decoded heights.
    pub resident_bytes: u64,
    /// Time to select the scene and work out the difference, in nanoseconds.
    pub schedule_ns: u64,
    /// Time to bring the loaded payloads into memory, in nanoseconds.
    pub load_ns: u64,
    /// The scene's largest screen-space error, in pixels.
    pub max_screen_error: f64,
}

impl FrameStats {
    /// Adds another frame's (a tile's, in a dataset's frame): every count and time summed,
    /// the largest screen-space error kept.
    pub fn merge(&mut self, other: &FrameStats) {
        self.visible += other.visible;
        self.loaded += other.loaded;
        self.loaded_triangles += other.loaded_triangles;
        self.loaded_bytes += other.loaded_bytes;
        self.prefetch_hits += other.prefetch_hits;
        self.evicted += other.evicted;
        self.resident += other.resident;
        self.resident_bytes += other.resident_bytes;
        self.schedule_ns += other.schedule_ns;
        self.load_ns += other.load_ns;
        self.max_screen_error = self.max_screen_error.max(other.max_screen_error);
    }
}

struct Resident {
    block: SceneBlock,
    loaded: LoadedBlock,
    last_visible: u64,
}

/// Where [`Scheduler::apply_warmed`] takes warmed blocks from: the block, decoded, if warm.
pub type WarmSource<'a> = dyn FnMut(&SceneBlock) -> Option<LoadedBlock> + 'a;

type WarmCache = Arc<Mutex<HashMap<BlockId, (SceneBlock, LoadedBlock)>>>;

/// Keeps the resident set of a moving camera.
pub struct Scheduler<S: Source + 'static> {
    store: Arc<Store<S>>,
    options: ScheduleOptions,
    resident: HashMap<BlockId, Resident>,
    resident_bytes: u64,
    frames: u64,
    last_cameras: [Option<Camera>; 2],
    prefetcher: Option<Prefetcher>,
    last_scene: Option<Scene>,
}

impl<S: Source + 'static> Scheduler<S> {
    /// A scheduler over `store`; starts the prefetch thread when asked.
    pub fn new(store: Arc<Store<S>>, options: ScheduleOptions) -> Result<Self> {
        options.check()?;
        options.terrain(&store)?; // the root must be readable (and on the globe, placed)
        let prefetcher = options
            .prefetch
            .then(|| Prefetcher::start(Arc::clone(&store), options));
        Ok(Scheduler {
            store,
            options,
            resident: HashMap::new(),
            resident_bytes: 0,
            frames: 0,
            last_cameras: [None, None],
            prefetcher,
            last_scene: None,
        })
    }

    /// The store it schedules.
    pub fn store(&self) -> &Arc<Store<S>> {
        &self.store
    }

    /// The stored (coded) payload of a resident block.
    #[cfg(any(test, feature = "testing"))]
    pub fn payload(&self, id: &BlockId) -> Option<&[u8]> {
        self.resident.get(id).map(|r| &*r.loaded.stored)
    }

    /// A resident block, decoded: the heights it draws. Each block is decoded once, when
    /// it is loaded (or prefetched), and kept while it stays resident.
    #[cfg(any(test, feature = "testing"))]
    pub fn block(&self, id: &BlockId) -> Option<&LoadedBlock> {
        self.resident.get(id).map(|r| &r.loaded)
    }

    /// The resident blocks, in no order.
    pub fn resident(&self) -> impl Iterator<Item = &SceneBlock> {
        self.resident.values().map(|r| &r.block)
    }

    /// Blocks until the prefetch thread has finished every request made so far (for tests
    /// and for applications that want a deterministic warm cache).
    pub fn wait_prefetch(&self) {
        if let Some(p) = &self.prefetcher {
            p.wait();
        }
    }

    /// The scene of the last frame.
    #[cfg(any(test, feature = "testing"))]
    pub fn last_scene(&self) -> Option<&Scene> {
        self.last_scene.as_ref()
    }

    /// Moves to `camera`: selects its scene, loads what is missing, evicts what the areas
    /// and the budget say.
    pub fn frame(&mut self, camera: &Camera) -> Result<Frame> {
        let selection = self.select(camera)?;
        self.apply(camera, selection)
    }

    /// The first half of [`Scheduler::frame`]: `camera`'s scene and what of it is missing.
    /// It changes nothing; [`Scheduler::apply`] then loads and evicts (a dataset's
    /// scheduler selects every tile's scene first, then applies each).
    pub fn select(&self, camera: &Camera) -> Result<Selection> {
        let started = Instant::now();
        let terrain = self.options.terrain(&self.store)?;
        let scene = terrain.scene_blocks(camera, &self.options.scene)?;
        let (mut load, mut keep) = (Vec::new(), Vec::new());
        for b in &scene.blocks {
            let id = BlockId::of(b);
            if self.resident.contains_key(&id) {
                keep.push(id);
            } else {
                load.push(*b);
            }
        }
        Ok(Selection {
            scene,
            load,
            keep,
            world: terrain.world(),
            schedule_ns: started.elapsed().as_nanos() as u64,
        })
    }

    /// The second half of [`Scheduler::frame`]: loads what `selection` (made by
    /// [`Scheduler::select`] for `camera`) lacks, then evicts. A block the selection found
    /// missing that is resident by now (a selection applied late) is kept, not loaded
    /// again. The frame's `schedule_ns` is the selection's plus the eviction's.
    pub fn apply(&mut self, camera: &Camera, selection: Selection) -> Result<Frame> {
        self.apply_from(camera, selection, None)
    }

    /// As [`Scheduler::apply`], taking the blocks it lacks from `warm` first (a prefetcher
    /// outside this scheduler: a dataset's, which warms every tile from one thread) when it
    /// has them, then from this scheduler's own prefetcher, then from the store. A warmed
    /// block counts only if its payload is the scene block's.
    pub fn apply_warmed(
        &mut self,
        camera: &Camera,
        selection: Selection,
        warm: &mut WarmSource<'_>,
    ) -> Result<Frame> {
        self.apply_from(camera, selection, Some(warm))
    }

    fn apply_from(
        &mut self,
        camera: &Camera,
        selection: Selection,
        mut outside: Option<&mut WarmSource<'_>>,
    ) -> Result<Frame> {
        let Selection {
            scene,
            load,
            mut keep,
            world,
            schedule_ns,
        } = selection;
        let (load, late): (Vec<SceneBlock>, Vec<SceneBlock>) = load
            .into_iter()
            .partition(|b| !self.resident.contains_key(&BlockId::of(b)));
        keep.extend(late.iter().map(BlockId::of));
        let index = self.frames;

        let loading = Instant::now();
        let mut stats = FrameStats {
            visible: scene.blocks.len() as u64,
            loaded: load.len() as u64,
            schedule_ns,
            max_screen_error: scene.stats.max_screen_error,
            ..FrameStats::default()
        };
        let b = u64::from(self.store.domain().block_size());
        // Blocks the prefetcher warmed, then the rest read together (coalesced) and decoded.
        let mut ready: Vec<(SceneBlock, LoadedBlock)> = Vec::with_capacity(load.len());
        let mut missing: Vec<SceneBlock> = Vec::new();
        let mut own = self.prefetcher.as_ref().map(|p| lock(&p.cache));
        for block in &load {
            let from_outside = outside.as_mut().and_then(|take| take(block));
            let warmed = from_outside.or_else(|| {
                own.as_mut()
                    .and_then(|warm| warm.remove(&BlockId::of(block)))
                    .filter(|(cb, _)| cb.payload == block.payload)
                    .map(|(_, loaded)| loaded)
            });
            match warmed {
                Some(loaded) => {
                    stats.prefetch_hits += 1;
                    ready.push((*block, loaded));
                }
                None => missing.push(*block),
            }
        }
        drop(own);
        // A block coded against its parent's grid takes the grid from the parent block when
        // that is still resident (it was drawn in an earlier frame), instead of reading it.
        let resident = &self.resident;
        let held = |index: u32, node: &StoredNode| {
            resident
                .get(&BlockId {
                    level: node.level,
                    x: node.x,
                    y: node.y,
                })
                .filter(|r| r.block.node == Some(index) && r.block.payload == node.payload)
                .map(|r| Arc::clone(&r.loaded.heights))
        };
        let read = load_blocks_reusing(&self.store, &missing, PAYLOAD_GAP, &held)?;
        ready.extend(missing.into_iter().zip(read));
        for (block, loaded) in ready {
            stats.loaded_bytes += loaded.stored.len() as u64 + loaded.parent_bytes;
            stats.loaded_triangles += 2 * (b - 1) * (b - 1);
            self.resident_bytes += loaded.memory();
            self.resident.insert(
                BlockId::of(&block),
                Resident {
                    block,
                    loaded,
                    last_visible: index,
                },
            );
        }
        stats.load_ns = loading.elapsed().as_nanos() as u64;

        let evict_started = Instant::now();
        let visible: HashSet<BlockId> = scene.blocks.iter().map(BlockId::of).collect();
        for id in &keep {
            if let Some(r) = self.resident.get_mut(id) {
                r.last_visible = index;
            }
        }
        let evict = self.evict(camera, &visible, &world);
        stats.evicted = evict.len() as u64;
        stats.resident = self.resident.len() as u64;
        stats.resident_bytes = self.resident_bytes;
        stats.schedule_ns += evict_started.elapsed().as_nanos() as u64;

        self.last_cameras = [self.last_cameras[1], Some(*camera)];
        if let (Some(p), Some(predicted)) = (&mut self.prefetcher, predict(&self.last_cameras)) {
            let have: HashSet<BlockId> = self.resident.keys().copied().collect();
            p.ask(predicted, have);
        }
        self.frames += 1;
        let mut load: Vec<BlockId> = load.iter().map(BlockId::of).collect();
        load.sort_unstable();
        keep.sort_unstable();
        self.last_scene = Some(scene);
        Ok(Frame {
            index,
            load,
            keep,
            evict,
            stats,
        })
    }

    /// Drops out-of-view blocks beyond the memory area, then least recently visible ones
    /// while over budget.
    fn evict(
        &mut self,
        camera: &Camera,
        visible: &HashSet<BlockId>,
        world: &TerrainFrame,
    ) -> Vec<BlockId> {
        let eye = camera.eye;
        let radius = self.options.memory_radius;
        let mut out: Vec<BlockId> = self
            .resident
            .iter()
            .filter(|(id, r)| {
                !visible.contains(id) && block_box(world, &r.block).distance(eye) > radius
            })
            .map(|(id, _)| *id)
            .collect();
        for id in &out {
            if let Some(r) = self.resident.remove(id) {
                self.resident_bytes -= r.loaded.memory();
            }
        }
        if self.resident_bytes > self.options.memory_budget {
            let mut ring: Vec<(u64, u64, BlockId)> = self
                .resident
                .iter()
                .filter(|(id, _)| !visible.contains(id))
                .map(|(id, r)| (r.last_visible, r.block.key, *id))
                .collect();
            ring.sort_unstable();
            for (_, _, id) in ring {
                if self.resident_bytes <= self.options.memory_budget {
                    break;
                }
                if let Some(r) = self.resident.remove(&id) {
                    self.resident_bytes -= r.loaded.memory();
                    out.push(id);
                }
            }
        }
        out.sort_unstable();
        out
    }
}

/// The camera of the next frame, extrapolated from the last two (eye and target move on as
/// they moved); `None` before there are two.
pub(crate) fn predict(last: &[Option<Camera>; 2]) -> Option<Camera> {
    let [Some(a), Some(b)] = *last else {
        return None;
    };
    Some(Camera {
        eye: b.eye + (b.eye - a.eye),
        target: b.target + (b.target - a.target),
        ..b
    })
}

/// The prefetch thread and its warm cache.
struct Prefetcher {
    cache: WarmCache,
    worker: NewestWorker<(Camera, HashSet<BlockId>)>,
}

impl Prefetcher {
    fn start<S: Source + 'static>(store: Arc<Store<S>>, options: ScheduleOptions) -> Prefetcher {
        let cache: WarmCache = Arc::default();
        let thread_cache = Arc::clone(&cache);
        let worker = NewestWorker::start("fmrh-prefetch", move |(camera, have)| {
            warm(&store, &options, &thread_cache, &camera, &have);
        });
        Prefetcher { cache, worker }
    }

    fn ask(&mut self, camera: Camera, have: HashSet<BlockId>) {
        self.worker.ask((camera, have));
    }

    fn wait(&self) {
        self.worker.wait();
    }
}

/// What a prefetcher warms for one store: the blocks of `camera`'s scene over `terrain`
/// within `options.cache_radius` of the eye that `skip` does not rule out (resident, or
/// already warm), read together and decoded. Returns the scene's blocks (all of them, to
/// tell which warm entries are still wanted) and the warmed ones. An error is only ever a
/// miss: the frame that needs the block reads (and reports) it.
pub fn warm_blocks<S: Source>(
    terrain: &Terrain<'_, S>,
    options: &ScheduleOptions,
    camera: &Camera,
    skip: impl Fn(&BlockId) -> bool,
) -> (Vec<BlockId>, Vec<(SceneBlock, LoadedBlock)>) {
    let Ok(scene) = terrain.scene_blocks(camera, &options.scene) else {
        return (Vec::new(), Vec::new());
    };
    let wanted: Vec<SceneBlock> = scene
        .blocks
        .iter()
        .filter(|b| b.distance <= options.cache_radius && !skip(&BlockId::of(b)))
        .copied()
        .collect();
    let ids = scene.blocks.iter().map(BlockId::of).collect();
    match load_blocks(terrain.store(), &wanted, PAYLOAD_GAP) {
        Ok(loaded) => (ids, wanted.into_iter().zip(loaded).collect()),
        Err(_) => (ids, Vec::new()),
    }
}

/// Drops the warm entries beyond the cache radius of `camera`, then warms the blocks of its
/// scene that are neither in `have` nor warm.
fn warm<S: Source>(
    store: &Store<S>,
    options: &ScheduleOptions,
    cache: &WarmCache,
    camera: &Camera,
    have: &HashSet<BlockId>,
) {
    let Ok(terrain) = options.terrain(store) else {
        return;
    };
    lock(cache)
        .retain(|_, (b, _)| terrain.block_box(b).distance(camera.eye) <= options.cache_radius);
    let (_, warmed) = warm_blocks(&terrain, options, camera, |id| {
        have.contains(id) || lock(cache).contains_key(id)
    });
    let mut cached = lock(cache);
    for (b, l) in warmed {
        cached.insert(BlockId::of(&b), (b, l));
    }
}
