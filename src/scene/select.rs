//! Scene selection: a camera and a pixel tolerance in, the blocks the view needs out.
//!
//! **Uniform mode** (seed 000 §5.1). The tolerance `τ` becomes one static bound,
//! `ε = τ / λ · P_min`, with `P_min` the distance from the eye to the nearest point the region
//! can hold (its box, from the data's lowest to highest height). The answer is the cluster
//! with the largest threshold `δᵢ <= ε`, never a coarser one, scanned over the region's key
//! ranges. When even the finest cluster is above `ε` (thresholds given without 0), the
//! physical blocks of the region are returned: they are exact.
//!
//! **View-dependent mode** (seed 004 eq. 2). Node `n` seen from the eye covers
//! `ρ(n) = e*(n) · λ / d(n)` pixels, `d(n)` the distance to its box (footprint by
//! `[min_height, max_height]`). A child's box lies inside its parent's and `e*` never grows
//! downwards, so `ρ` never grows from parent to child: the predicate `ρ <= τ` is monotone and
//! its cut `V = { n : ρ(n) <= τ, ρ(parent) > τ }` covers the region once. fmrh finds `V`
//! through the clusters instead of from the root. With `D` the distance from the eye to the
//! farthest point of the region, any `V` node meeting the region is at most `D` away, so its
//! `e*` is at most `τ · D / λ`. Take the cluster with the smallest `δ >= τ · D / λ`: at each
//! place its node is at or above the `V` node. Scan it over the region's keys; a scanned node
//! that meets `τ` is in `V` (its parent has `e* > δ`, and is at most `D` away, so it fails);
//! one that does not is refined through its children, only where they meet the region.
//! Nodes above that cluster are never read. (Seeding each quadrant of the region from its
//! own farthest point, and splitting quadrants until their nearest and farthest points pick
//! the same cluster, were both measured on Puget Sound 1k and 4k: the extra range scans cost
//! more than the refinement they save, 10-30 % slower.)
//! A tree leaf above the finest level that still misses `τ` (possible only when the finest
//! threshold is above 0) is replaced by its physical blocks.
//!
//! **Region.** An explicit window (inclusive samples), or the frustum's footprint: the
//! quadrants whose box, from the data's lowest to highest height, may meet the frustum. In
//! the second case, blocks whose own box misses the frustum (exact separating-axis test) are
//! dropped at the end: they hold nothing visible. The scene then covers every visible point
//! of the terrain exactly once.
//!
//! The selection asks the store for key ranges and node records; it never parses a page.

use std::time::Instant;

use serde::Serialize;

use crate::curve::HilbertKey;
use crate::error::{Error, Result};
use crate::format::invariant;
use crate::format::records::NodeRecord;
use crate::model::{Domain, SampleRect};
use crate::store::{Source, Store};

use super::camera::{Aabb, Camera, View, WorldFrame};
use super::ranges::{self, KeyRange, KeyRun, Quadrant};

/// Gap merge used when none is given: runs separated by at most this many keys are scanned
/// as one (see [`ranges`]).
pub const DEFAULT_GAP: u64 = 4;

/// How the tolerance in pixels turns into blocks.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize)]
#[serde(rename_all = "lowercase")]
pub enum Mode {
    /// One static bound for the whole region: one cluster.
    Uniform,
    /// Each node meets the tolerance where it is seen.
    #[default]
    View,
}

/// What a scene asks for besides the camera.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct SceneOptions {
    /// Tolerance in pixels (finite, `>= 0`).
    pub tau: f64,
    /// Uniform or view-dependent.
    pub mode: Mode,
    /// An explicit window (inclusive samples, inside the data); the frustum's footprint when
    /// `None`.
    pub window: Option<SampleRect>,
    /// Gap merge, in keys.
    pub gap: u64,
}

impl SceneOptions {
    /// View-dependent, no window, [`DEFAULT_GAP`].
    pub fn new(tau: f64) -> SceneOptions {
        SceneOptions {
            tau,
            mode: Mode::View,
            window: None,
            gap: DEFAULT_GAP,
        }
    }
}

/// Where a block's bytes are: offset, length and CRC-32 of its payload.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Hash, Serialize)]
pub struct PayloadRef {
    /// Byte offset in the container.
    pub offset: u64,
    /// Bytes.
    pub len: u32,
    /// CRC-32 of the bytes.
    pub crc: u32,
}

/// The levels of the scene blocks across one edge of a block.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize)]
pub struct NeighbourLevels {
    /// The coarsest (smallest level number): the one to stitch to.
    pub coarsest: u8,
    /// The finest.
    pub finest: u8,
}

/// One block of a scene: a node of the FMRH, or a physical block below a tree leaf.
#[derive(Clone, Copy, Debug, PartialEq, Serialize)]
pub struct SceneBlock {
    /// Index in the node table; `None` for a physical block below a pruned leaf.
    pub node: Option<u32>,
    /// Level (0 root, `L` physical blocks).
    pub level: u8,
    /// Column among the level's nodes.
    pub x: u32,
    /// Row among the level's nodes.
    pub y: u32,
    /// Hilbert key.
    pub key: u64,
    /// Footprint clipped to the data, inclusive samples.
    pub col0: u64,
    /// North row.
    pub row0: u64,
    /// East column (inclusive).
    pub col1: u64,
    /// South row (inclusive).
    pub row1: u64,
    /// `e*`: the static error this block guarantees, in metres.
    pub error: f64,
    /// `e*` seen from the eye, in pixels.
    pub screen_error: f64,
    /// Distance from the eye to the block's box.
    pub distance: f64,
    /// Least height the block can draw.
    pub min_height: f32,
    /// Greatest height the block can draw.
    pub max_height: f32,
    /// Its payload: the coarse grid, or at level `L` the physical block.
    pub payload: PayloadRef,
    /// Scene blocks across the north, east, south and west edges (`None`: the data's edge,
    /// or outside the scene).
    pub neighbours: [Option<NeighbourLevels>; 4],
}

impl SceneBlock {
    /// Footprint clipped to the data.
    pub fn rect(&self) -> SampleRect {
        SampleRect {
            col0: self.col0,
            row0: self.row0,
            col1: self.col1,
            row1: self.row1,
        }
    }

    /// Its finest-level Hilbert keys.
    pub fn keys(&self, domain: &Domain) -> KeyRange {
        KeyRange {
            lo: self.key,
            hi: HilbertKey(self.key).last(domain.finest_level(), self.level),
        }
    }
}

/// What a scene cost and what it guarantees.
#[derive(Clone, Copy, Debug, Default, PartialEq, Serialize)]
pub struct SceneStats {
    /// Blocks.
    pub blocks: u64,
    /// Grid samples of the blocks, `b²` each.
    pub samples: u64,
    /// Triangles to draw them, `2 (b-1)²` each.
    pub triangles: u64,
    /// Payload bytes.
    pub bytes: u64,
    /// Aligned quadrants of the region.
    pub quadrants: u64,
    /// Range scans run.
    pub ranges: u64,
    /// Index pages read by the scans.
    pub index_pages: u64,
    /// Node records read.
    pub node_reads: u64,
    /// Wall time of the selection, in nanoseconds.
    pub schedule_ns: u64,
    /// Uniform mode: the chosen cluster's threshold in metres (0 for physical blocks).
    pub threshold: Option<f64>,
    /// Uniform mode: the chosen cluster (`None` for physical blocks).
    pub cluster: Option<usize>,
    /// Uniform mode: `ε = τ / λ · P_min`, the largest static error the view allows.
    pub allowed_error: Option<f64>,
    /// Uniform mode: `P_min`.
    pub p_min: Option<f64>,
    /// The largest `e*` among the blocks, in metres.
    pub max_error: f64,
    /// The largest screen-space error among the blocks, in pixels.
    pub max_screen_error: f64,
}

/// The answer to one view.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct Scene {
    /// The mode used.
    pub mode: Mode,
    /// The tolerance in pixels.
    pub tau: f64,
    /// The explicit window, or the samples the frustum's footprint spans; `None` when the
    /// frustum sees no terrain.
    pub window: Option<SampleRect>,
    /// The blocks, sorted by Hilbert key.
    pub blocks: Vec<SceneBlock>,
    /// Counts and guarantees.
    pub stats: SceneStats,
}

/// A store seen as terrain in the world frame: what every scene over it shares.
pub struct Terrain<'s, S: Source> {
    store: &'s Store<S>,
    domain: Domain,
    frame: WorldFrame,
    root: NodeRecord,
    thresholds: Vec<f64>,
}

impl<'s, S: Source> Terrain<'s, S> {
    /// Reads what scenes need once: the root's height range and the cluster thresholds.
    pub fn new(store: &'s Store<S>) -> Result<Self> {
        let root = store.node(0)?;
        Ok(Terrain {
            store,
            domain: *store.domain(),
            frame: WorldFrame::new(store.header().metadata.spacing_m),
            root,
            thresholds: store.clusters().iter().map(|c| c.threshold).collect(),
        })
    }

    /// The store.
    pub fn store(&self) -> &'s Store<S> {
        self.store
    }

    /// The world frame.
    pub fn frame(&self) -> WorldFrame {
        self.frame
    }

    /// The geometry.
    pub fn domain(&self) -> &Domain {
        &self.domain
    }

    /// The box of the samples `rect` between heights `zmin` and `zmax`.
    pub fn rect_box(&self, rect: &SampleRect, zmin: f32, zmax: f32) -> Aabb {
        Aabb {
            min: self
                .frame
                .point(rect.col0 as f64, rect.row0 as f64, f64::from(zmin)),
            max: self
                .frame
                .point(rect.col1 as f64, rect.row1 as f64, f64::from(zmax)),
        }
    }

    /// The box of a node record: its footprint clipped to the data, by its height range.
    pub fn node_box(&self, n: &NodeRecord) -> Aabb {
        let rect = Quadrant {
            level: n.level,
            x: n.x.get(),
            y: n.y.get(),
        }
        .samples(&self.domain);
        self.rect_box(&rect, n.min_height.get(), n.max_height.get())
    }

    fn quadrant_box(&self, q: &Quadrant) -> Aabb {
        self.rect_box(
            &q.samples(&self.domain),
            self.root.min_height.get(),
            self.root.max_height.get(),
        )
    }

    /// The region a scene covers, as maximal aligned quadrants sorted by key, and the
    /// samples it spans: `window` itself, or the quadrants the frustum may see.
    pub fn region(
        &self,
        view: &View,
        window: Option<SampleRect>,
    ) -> Result<(Vec<Quadrant>, Option<SampleRect>)> {
        let d = self.domain;
        let data = d.data_rect();
        let quadrants = match window {
            Some(w) => {
                if w.col0 > w.col1 || w.row0 > w.row1 || w.intersect(&data) != Some(w) {
                    return Err(Error::InvalidArgument(format!(
                        "window {},{},{},{} is not inside the data 0,0,{},{}",
                        w.col0, w.row0, w.col1, w.row1, data.col1, data.row1
                    )));
                }
                let blocks = ranges::window_blocks(&d, &w);
                ranges::decompose(&d, ranges::window_classifier(&d, blocks))
            }
            None => ranges::decompose(&d, |q| view.classify(&self.quadrant_box(q))),
        };
        let span = window.or_else(|| {
            quadrants
                .iter()
                .map(|q| q.samples(&d))
                .reduce(|a, b| SampleRect {
                    col0: a.col0.min(b.col0),
                    row0: a.row0.min(b.row0),
                    col1: a.col1.max(b.col1),
                    row1: a.row1.max(b.row1),
                })
        });
        Ok((quadrants, span))
    }

    /// The scene block of node `index`, seen from `view`.
    pub fn node_block(&self, view: &View, index: u32, n: &NodeRecord) -> SceneBlock {
        self.node_block_at(view, index, n, self.node_box(n).distance(view.eye))
    }

    fn node_block_at(&self, view: &View, index: u32, n: &NodeRecord, distance: f64) -> SceneBlock {
        let rect = Quadrant {
            level: n.level,
            x: n.x.get(),
            y: n.y.get(),
        }
        .samples(&self.domain);
        SceneBlock {
            node: Some(index),
            level: n.level,
            x: n.x.get(),
            y: n.y.get(),
            key: n.key.get(),
            col0: rect.col0,
            row0: rect.row0,
            col1: rect.col1,
            row1: rect.row1,
            error: n.monotone_error.get(),
            screen_error: view.screen_error(n.monotone_error.get(), distance),
            distance,
            min_height: n.min_height.get(),
            max_height: n.max_height.get(),
            payload: PayloadRef {
                offset: n.payload_offset.get(),
                len: n.payload_len.get(),
                crc: n.payload_crc.get(),
            },
            neighbours: [None; 4],
        }
    }

    /// Physical block `(x, y)`, exact, its heights bounded by `zmin..=zmax`.
    pub fn physical_block(
        &self,
        view: &View,
        x: u32,
        y: u32,
        zmin: f32,
        zmax: f32,
    ) -> Result<SceneBlock> {
        let d = self.domain;
        let rec = self.store.block_record(x, y)?;
        let finest = d.finest_level();
        let rect = Quadrant {
            level: finest,
            x,
            y,
        }
        .samples(&d);
        Ok(SceneBlock {
            node: None,
            level: finest,
            x,
            y,
            key: ranges::block_key(&d, x, y),
            col0: rect.col0,
            row0: rect.row0,
            col1: rect.col1,
            row1: rect.row1,
            error: 0.0,
            screen_error: 0.0,
            distance: self.rect_box(&rect, zmin, zmax).distance(view.eye),
            min_height: zmin,
            max_height: zmax,
            payload: PayloadRef {
                offset: rec.payload_offset.get(),
                len: rec.payload_len.get(),
                crc: rec.payload_crc.get(),
            },
            neighbours: [None; 4],
        })
    }

    /// The box of a scene block: its samples by its height range.
    pub fn block_box(&self, b: &SceneBlock) -> Aabb {
        self.rect_box(&b.rect(), b.min_height, b.max_height)
    }

    /// The root's height range: bounds every height of the terrain.
    pub fn height_range(&self) -> (f32, f32) {
        (self.root.min_height.get(), self.root.max_height.get())
    }

    /// Sorts `blocks` by key, drops repeats and (for a frustum region) blocks whose own box
    /// misses the frustum, and fills in neighbour levels.
    pub fn finish(&self, view: &View, window: Option<SampleRect>, blocks: &mut Vec<SceneBlock>) {
        blocks.sort_unstable_by_key(|b| (b.key, b.level));
        blocks.dedup_by_key(|b| (b.key, b.level));
        if window.is_none() {
            blocks.retain(|b| view.intersects(&self.block_box(b)));
        }
        set_neighbours(&self.domain, blocks, CellMap::CELLS_PER_BLOCK);
    }

    /// Selects the blocks `camera` needs at tolerance `options.tau`.
    pub fn scene(&self, camera: &Camera, options: &SceneOptions) -> Result<Scene> {
        let started = Instant::now();
        let view = camera.view()?;
        if !options.tau.is_finite() || options.tau < 0.0 {
            return Err(Error::InvalidArgument(format!(
                "tolerance {} px: must be finite and >= 0",
                options.tau
            )));
        }
        let d = self.domain;
        let (quadrants, window) = self.region(&view, options.window)?;
        let mut search = Search {
            terrain: self,
            view: &view,
            tau: options.tau,
            out: Vec::new(),
            stats: SceneStats {
                quadrants: quadrants.len() as u64,
                ..SceneStats::default()
            },
        };
        match options.mode {
            Mode::Uniform => {
                let p_min = match options.window {
                    Some(w) => self
                        .rect_box(&w, self.root.min_height.get(), self.root.max_height.get())
                        .distance(view.eye),
                    None => quadrants
                        .iter()
                        .map(|q| self.quadrant_box(q).distance(view.eye))
                        .fold(f64::INFINITY, f64::min),
                };
                search.uniform(&quadrants, p_min, options.gap)?;
            }
            Mode::View => search.view_dependent(&quadrants, options.gap)?,
        }
        let Search {
            mut out, mut stats, ..
        } = search;
        self.finish(&view, options.window, &mut out);
        let b = u64::from(d.block_size());
        stats.blocks = out.len() as u64;
        stats.samples = stats.blocks * b * b;
        stats.triangles = stats.blocks * 2 * (b - 1) * (b - 1);
        stats.bytes = out.iter().map(|b| u64::from(b.payload.len)).sum();
        stats.max_error = out.iter().map(|b| b.error).fold(0.0, f64::max);
        stats.max_screen_error = out.iter().map(|b| b.screen_error).fold(0.0, f64::max);
        stats.schedule_ns = started.elapsed().as_nanos() as u64;
        Ok(Scene {
            mode: options.mode,
            tau: options.tau,
            window,
            blocks: out,
            stats,
        })
    }
}

/// The working state of one selection.
struct Search<'t, 's, S: Source> {
    terrain: &'t Terrain<'s, S>,
    view: &'t View,
    tau: f64,
    out: Vec<SceneBlock>,
    stats: SceneStats,
}

impl<S: Source> Search<'_, '_, S> {
    fn node(&mut self, index: u32) -> Result<NodeRecord> {
        self.stats.node_reads += 1;
        self.terrain.store.node(index)
    }

    fn emit(&mut self, index: u32, n: &NodeRecord) {
        let block = self.terrain.node_block(self.view, index, n);
        self.out.push(block);
    }

    /// Emits the physical blocks of `q` that meet `run`, exact (`e* = 0`), bounded by the
    /// heights `zmin..=zmax` of the node above them.
    fn emit_physical(&mut self, q: &Quadrant, run: &KeyRun, zmin: f32, zmax: f32) -> Result<()> {
        let d = self.terrain.domain;
        let (xs, ys) = q.blocks(&d);
        for y in ys {
            for x in xs.clone() {
                let key = ranges::block_key(&d, x, y);
                if run.meets(&KeyRange { lo: key, hi: key }) {
                    self.stats.node_reads += 1;
                    let block = self.terrain.physical_block(self.view, x, y, zmin, zmax)?;
                    self.out.push(block);
                }
            }
        }
        Ok(())
    }

    /// Runs the range scan of `run` in `cluster`, calling `visit` with every node whose keys
    /// meet the region (not merely the run's gaps), each once.
    fn scan(
        &mut self,
        cluster: usize,
        run: &KeyRun,
        mut visit: impl FnMut(&mut Self, u32, NodeRecord) -> Result<()>,
    ) -> Result<()> {
        let finest = self.terrain.domain.finest_level();
        let mut scan = self
            .terrain
            .store
            .scan_hilbert(cluster, run.scan.lo..=run.scan.hi)?;
        self.stats.ranges += 1;
        let mut entries = Vec::new();
        for e in scan.by_ref() {
            let e = e?;
            let keys = KeyRange {
                lo: e.key.0,
                hi: e.key.last(finest, e.level.min(finest)),
            };
            if run.meets(&keys) {
                entries.push(e);
            }
        }
        self.stats.index_pages += u64::from(scan.pages_read());
        for e in entries {
            let n = self.node(e.node)?;
            if n.key.get() != e.key.0 || n.level != e.level {
                return Err(Error::corrupt(
                    invariant::CLUSTER_INDEX,
                    format!("cluster {cluster} index, key {}", e.key.0),
                    format!("names node {}, which is not that node", e.node),
                ));
            }
            visit(self, e.node, n)?;
        }
        Ok(())
    }

    fn uniform(&mut self, quadrants: &[Quadrant], p_min: f64, gap: u64) -> Result<()> {
        let d = self.terrain.domain;
        let allowed = self.view.allowed_error(self.tau, p_min);
        self.stats.p_min = Some(p_min);
        self.stats.allowed_error = Some(allowed);
        // The largest threshold within the bound: the thresholds ascend.
        let cluster = self
            .terrain
            .thresholds
            .partition_point(|&t| t <= allowed)
            .checked_sub(1);
        self.stats.cluster = cluster;
        self.stats.threshold = Some(cluster.map_or(0.0, |c| self.terrain.thresholds[c]));
        let keys: Vec<KeyRange> = quadrants.iter().map(|q| q.keys(&d)).collect();
        let (zmin, zmax) = (
            self.terrain.root.min_height.get(),
            self.terrain.root.max_height.get(),
        );
        for run in ranges::merge(&keys, gap) {
            match cluster {
                Some(c) => self.scan(c, &run, |s, i, n| {
                    s.emit(i, &n);
                    Ok(())
                })?,
                None => {
                    for q in quadrants.iter().filter(|q| run.meets(&q.keys(&d))) {
                        self.emit_physical(q, &run, zmin, zmax)?;
                    }
                }
            }
        }
        Ok(())
    }

    fn view_dependent(&mut self, quadrants: &[Quadrant], gap: u64) -> Result<()> {
        let terrain = self.terrain;
        let d = terrain.domain;
        let thresholds = &terrain.thresholds;
        let (tau, view) = (self.tau, self.view);
        // One seed for the whole region, from its farthest point: the finest cluster at or
        // above every V node of the region; None: the root.
        let far = quadrants
            .iter()
            .map(|q| terrain.quadrant_box(q).max_distance(view.eye))
            .fold(0.0, f64::max);
        let need = view.allowed_error(tau, far);
        let first = thresholds.partition_point(|&t| t < need);
        let seed = (first < thresholds.len()).then_some(first);
        let keys: Vec<KeyRange> = quadrants.iter().map(|q| q.keys(&d)).collect();
        for run in ranges::merge(&keys, gap) {
            match seed {
                Some(c) => self.scan(c, &run, |s, i, n| s.refine(i, n, &run))?,
                None => {
                    let root = self.terrain.root;
                    self.refine(0, root, &run)?;
                }
            }
        }
        Ok(())
    }

    /// Emits the V nodes at or below node `index` that meet `run`.
    fn refine(&mut self, index: u32, n: NodeRecord, run: &KeyRun) -> Result<()> {
        let d = self.terrain.domain;
        let finest = d.finest_level();
        let mut stack = vec![(index, n)];
        while let Some((i, n)) = stack.pop() {
            let distance = self.terrain.node_box(&n).distance(self.view.eye);
            if self.view.screen_error(n.monotone_error.get(), distance) <= self.tau
                || n.level >= finest
            {
                let block = self.terrain.node_block_at(self.view, i, &n, distance);
                self.out.push(block);
                continue;
            }
            let len = n.subtree_len.get();
            if len <= 1 {
                // A pruned leaf that misses the tolerance: its physical blocks are exact.
                let q = Quadrant {
                    level: n.level,
                    x: n.x.get(),
                    y: n.y.get(),
                };
                self.emit_physical(&q, run, n.min_height.get(), n.max_height.get())?;
                continue;
            }
            let end = i.saturating_add(len);
            let mut c = i + 1;
            while c < end {
                let child = self.node(c)?;
                let child_len = child.subtree_len.get();
                if child.parent.get() != i || child.level != n.level + 1 || child_len == 0 {
                    return Err(Error::corrupt(
                        invariant::NODE_TABLE,
                        format!("node {c}"),
                        format!("not a child of node {i} in pre-order"),
                    ));
                }
                let keys = KeyRange {
                    lo: child.key.get(),
                    hi: HilbertKey(child.key.get()).last(finest, child.level),
                };
                if run.meets(&keys) {
                    stack.push((c, child));
                }
                c = c.saturating_add(child_len);
            }
        }
        Ok(())
    }
}

/// Which block holds each finest-block cell of the scene's bounding rectangle, when that
/// rectangle is small enough to tabulate cheaply (otherwise lookups fall back to a binary
/// search by key).
struct CellMap {
    x0: u32,
    y0: u32,
    width: u32,
    height: u32,
    /// Row-major block index + 1; 0 for no block.
    cells: Vec<u32>,
}

impl CellMap {
    /// The most cells tabulated per block of the scene (and at most 2^20 in all).
    const CELLS_PER_BLOCK: u64 = 64;

    fn new(d: &Domain, blocks: &[SceneBlock], cells_per_block: u64) -> CellMap {
        let empty = CellMap {
            x0: 0,
            y0: 0,
            width: 0,
            height: 0,
            cells: Vec::new(),
        };
        let spans: Vec<_> = blocks
            .iter()
            .map(|b| {
                Quadrant {
                    level: b.level,
                    x: b.x,
                    y: b.y,
                }
                .blocks(d)
            })
            .collect();
        let (Some(x0), Some(y0), Some(x1), Some(y1)) = (
            spans.iter().map(|s| s.0.start).min(),
            spans.iter().map(|s| s.1.start).min(),
            spans.iter().map(|s| s.0.end).max(),
            spans.iter().map(|s| s.1.end).max(),
        ) else {
            return empty;
        };
        let (width, height) = (x1 - x0, y1 - y0);
        let area = u64::from(width) * u64::from(height);
        if area > (blocks.len() as u64 * cells_per_block).min(1 << 20) {
            return empty;
        }
        let mut cells = vec![0u32; area as usize];
        for (i, (xs, ys)) in spans.iter().enumerate() {
            for y in ys.clone() {
                let row = ((y - y0) * width) as usize;
                cells[row + (xs.start - x0) as usize..row + (xs.end - x0) as usize]
                    .fill(i as u32 + 1);
            }
        }
        CellMap {
            x0,
            y0,
            width,
            height,
            cells,
        }
    }

    /// `Some(answer)` when the cell is tabulated or outside the rectangle (no block);
    /// `None` when the map could not be built.
    fn get(&self, x: u32, y: u32) -> Option<Option<usize>> {
        if self.cells.is_empty() {
            return None;
        }
        if x < self.x0 || y < self.y0 || x - self.x0 >= self.width || y - self.y0 >= self.height {
            return Some(None);
        }
        let v = self.cells[((y - self.y0) * self.width + (x - self.x0)) as usize];
        Some(v.checked_sub(1).map(|i| i as usize))
    }
}

/// Fills every block's neighbour levels. `blocks` must be sorted by key and disjoint.
fn set_neighbours(d: &Domain, blocks: &mut [SceneBlock], cells_per_block: u64) {
    let finest = d.finest_level();
    let (cols, rows) = d.nodes_across(finest);
    let cells = CellMap::new(d, blocks, cells_per_block);
    let find = |blocks: &[SceneBlock], x: u32, y: u32| -> Option<usize> {
        if let Some(found) = cells.get(x, y) {
            return found;
        }
        let key = ranges::block_key(d, x, y);
        let i = blocks.partition_point(|b| b.key <= key).checked_sub(1)?;
        (key <= HilbertKey(blocks[i].key).last(finest, blocks[i].level)).then_some(i)
    };
    for i in 0..blocks.len() {
        let b = blocks[i];
        let q = Quadrant {
            level: b.level,
            x: b.x,
            y: b.y,
        };
        let (xs, ys) = q.blocks(d);
        // For each edge: the fixed coordinate just outside it, and whether it runs along x.
        let edges: [Option<(u32, bool)>; 4] = [
            ys.start.checked_sub(1).map(|y| (y, true)),
            (xs.end < cols).then_some((xs.end, false)),
            (ys.end < rows).then_some((ys.end, true)),
            xs.start.checked_sub(1).map(|x| (x, false)),
        ];
        for (e, edge) in edges.into_iter().enumerate() {
            let Some((fixed, along_x)) = edge else {
                continue;
            };
            let span = if along_x { xs.clone() } else { ys.clone() };
            let mut levels: Option<NeighbourLevels> = None;
            let mut t = span.start;
            while t < span.end {
                let (x, y) = if along_x { (t, fixed) } else { (fixed, t) };
                match find(blocks, x, y) {
                    Some(j) => {
                        let nb = &blocks[j];
                        let l = nb.level;
                        levels = Some(match levels {
                            None => NeighbourLevels {
                                coarsest: l,
                                finest: l,
                            },
                            Some(v) => NeighbourLevels {
                                coarsest: v.coarsest.min(l),
                                finest: v.finest.max(l),
                            },
                        });
                        let (nxs, nys) = Quadrant {
                            level: nb.level,
                            x: nb.x,
                            y: nb.y,
                        }
                        .blocks(d);
                        t = if along_x { nxs.end } else { nys.end };
                    }
                    None => t += 1,
                }
            }
            blocks[i].neighbours[e] = levels;
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::heightfield::Heightfield;
    use crate::model::{BuildOptions, Model};

    /// The tabulated and the binary-search neighbour lookups agree on every cluster cut.
    #[test]
    fn neighbour_lookups_agree() {
        let hf = Heightfield::from_fn(300, 200, |x, y| {
            ((x as f32 * 0.07).sin() * 40.0 + (y as f32 * 0.05).cos() * 30.0) * (x as f32 / 100.0)
        })
        .unwrap();
        let model = Model::build(
            hf,
            &BuildOptions {
                block_size: 9,
                ..BuildOptions::default()
            },
        )
        .unwrap();
        let d = *model.domain();
        for c in model.clusters() {
            let mut blocks: Vec<SceneBlock> = c
                .nodes
                .iter()
                .map(|&i| {
                    let n = model.tree().node(i);
                    let rect = Quadrant {
                        level: n.level,
                        x: n.x,
                        y: n.y,
                    }
                    .samples(&d);
                    SceneBlock {
                        node: Some(i),
                        level: n.level,
                        x: n.x,
                        y: n.y,
                        key: n.key.0,
                        col0: rect.col0,
                        row0: rect.row0,
                        col1: rect.col1,
                        row1: rect.row1,
                        error: n.monotone_error,
                        screen_error: 0.0,
                        distance: 0.0,
                        min_height: n.min_height,
                        max_height: n.max_height,
                        payload: PayloadRef::default(),
                        neighbours: [None; 4],
                    }
                })
                .collect();
            // Drop every third block so that some edges face no block.
            let mut i = 0;
            blocks.retain(|_| {
                i += 1;
                i % 3 != 0
            });
            let mut searched = blocks.clone();
            set_neighbours(&d, &mut blocks, u64::MAX);
            set_neighbours(&d, &mut searched, 0);
            assert_eq!(blocks, searched, "cluster {}", c.threshold);
            if blocks.len() > 2 {
                assert!(blocks
                    .iter()
                    .any(|b| b.neighbours.iter().any(Option::is_some)));
            }
        }
    }
}
