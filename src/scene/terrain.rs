//! A store seen as terrain in the world frame: boxes, the region a view covers, scene
//! blocks, and [`Terrain::scene`], which hands the selection to the chosen mode (`uniform`,
//! `view_dependent`) and finishes its answer (sort, cull, neighbour levels).
//!
//! **Region.** An explicit window (inclusive samples), or the frustum's footprint: the
//! quadrants whose box, from the data's lowest to highest height, may meet the frustum. In
//! the second case, blocks whose own box misses the frustum (exact separating-axis test) are
//! dropped at the end: they hold nothing visible. On the globe ([`Terrain::on_globe`]) so
//! are the quadrants and blocks wholly below the horizon. The scene then covers every
//! visible point of the terrain exactly once.
//!
//! The selection asks the store for key ranges and node records; it never parses a page.

use super::camera::{Aabb, Coverage, GlobeFrame, TerrainFrame, View, WorldFrame};
use super::ranges::{self, KeyRange, Quadrant};
use super::result::SceneBlock;
use super::stitch;
use crate::error::{Error, Result};
use crate::format::StoredNode;
use crate::model::{Domain, SampleRect};
use crate::store::{Ahead, Source, Store};

/// The region of a scene: maximal aligned quadrants, and what the search needs of them.
#[derive(Clone, Debug)]
pub struct Region {
    /// The quadrants, sorted by key.
    pub quadrants: Vec<Quadrant>,
    /// Each quadrant's Hilbert keys, in the same order.
    pub keys: Vec<KeyRange>,
    /// The window that decided the region; `None`: the frustum did.
    pub window: Option<SampleRect>,
    /// The frustum's quadrants were split short of the finest level
    /// ([`Terrain::scene_blocks`]).
    pub coarse: bool,
    /// The samples the region spans: the window, or the quadrants' bounding rectangle
    /// (`None`: no quadrant).
    pub span: Option<SampleRect>,
    /// The least distance from the eye to a quadrant's box (from the data's lowest to
    /// highest height); infinite when there is none.
    pub near: f64,
    /// The greatest distance from the eye to a point of a quadrant's box; 0 when there is
    /// none.
    pub far: f64,
}

/// The box of scene block `b` in `world`: its samples by its height range
/// ([`Terrain::block_box`], for a caller that holds the frame and not the terrain).
pub fn block_box(world: &TerrainFrame, b: &SceneBlock) -> Aabb {
    world.rect_box(&b.rect(), f64::from(b.min_height), f64::from(b.max_height))
}

/// A store seen as terrain in the world frame: what every scene over it shares.
pub struct Terrain<'s, S: Source> {
    pub(super) store: &'s Store<S>,
    domain: Domain,
    #[cfg_attr(not(any(test, feature = "testing")), allow(dead_code))] // read by the tests
    frame: WorldFrame,
    /// Where the samples are in the world frame cameras are given in.
    world: TerrainFrame,
    root: StoredNode,
    thresholds: Vec<f64>,
    storage_error: f64,
}

impl<'s, S: Source> Terrain<'s, S> {
    /// Reads what scenes need once: the root's height range and the cluster thresholds.
    ///
    /// The world frame's spacing is the one the store records. **When the store does not know
    /// its spacing** (`store.header().metadata.spacing_m` is `None`: a PNG, a grid with no
    /// CRS), samples are taken as 1 m apart, and a camera placed in metres sees the wrong
    /// terrain. Check, and use [`Terrain::with_spacing`]; the CLI refuses such scenes
    /// without `--spacing`.
    #[cfg(any(test, feature = "testing"))]
    pub fn new(store: &'s Store<S>) -> Result<Self> {
        Terrain::with_spacing(store, None)
    }

    /// As [`Terrain::new`], with the ground spacing `[east, south]` in metres given by the
    /// caller instead of the store when `spacing_m` is `Some`.
    pub fn with_spacing(store: &'s Store<S>, spacing_m: Option<[f64; 2]>) -> Result<Self> {
        // On a remote source, the root's page alone (not a chunk around it).
        store.fetch_ahead(Ahead::new().nodes(0, 0))?;
        let frame = WorldFrame::new(spacing_m.or(store.header().metadata.spacing_m));
        Terrain::with_frame(store, frame, TerrainFrame::Flat(frame))
    }

    /// The store's terrain on the WGS 84 ellipsoid: cameras in ECEF metres, boxes the ECEF
    /// boxes of the cells' shells, and blocks below the horizon culled. The store's
    /// georeference must be geographic ([`GlobeFrame::of`]); heights above the EGM96 geoid
    /// are placed on the ellipsoid ([`GlobeFrame::with_datum`]).
    pub fn on_globe(store: &'s Store<S>) -> Result<Self> {
        let g = store
            .header()
            .metadata
            .georeference
            .as_ref()
            .ok_or_else(|| {
                Error::InvalidArgument(
                    "the globe frame needs a georeferenced grid; this file has no georeference"
                        .into(),
                )
            })?;
        let globe = GlobeFrame::of(g)?.with_datum(store.header().metadata.vertical_datum)?;
        let frame = WorldFrame::new(store.header().metadata.spacing_m);
        Terrain::with_frame(store, frame, TerrainFrame::Globe(globe))
    }

    /// The store's terrain with `world` placing its samples (`frame` is the flat frame of
    /// its spacing, which [`Terrain::frame`] reports).
    pub fn with_frame(store: &'s Store<S>, frame: WorldFrame, world: TerrainFrame) -> Result<Self> {
        store.fetch_ahead(Ahead::new().nodes(0, 0))?;
        let root = store.node(0)?;
        Ok(Terrain {
            store,
            domain: *store.domain(),
            frame,
            world,
            root,
            thresholds: store.clusters().iter().map(|c| c.threshold).collect(),
            storage_error: store.header().storage_error(),
        })
    }

    /// How far a stored height may be from its source: `9Q/16` of a storage precision
    /// (format 2.1), else 0. No block is more exact: a physical block with real heights
    /// has this error, and a node whose `e*` is this small cannot be refined to better.
    pub fn storage_error(&self) -> f64 {
        self.storage_error
    }

    /// The store.
    pub fn store(&self) -> &'s Store<S> {
        self.store
    }

    /// The root node.
    pub fn root(&self) -> StoredNode {
        self.root
    }

    /// The cluster thresholds, ascending.
    pub fn thresholds(&self) -> &[f64] {
        &self.thresholds
    }

    /// The flat frame of the store's spacing (the world frame unless on the globe).
    #[cfg(any(test, feature = "testing"))]
    pub fn frame(&self) -> WorldFrame {
        self.frame
    }

    /// Where the samples are in the world frame cameras are given in.
    pub fn world(&self) -> TerrainFrame {
        self.world
    }

    /// Whether everything over `rect` up to `zmax` is below the horizon seen from `view`
    /// (only ever on the globe).
    pub fn hidden(&self, view: &View, rect: &SampleRect, zmax: f32) -> bool {
        self.world.hidden(view.eye, rect, f64::from(zmax))
    }

    /// The geometry.
    pub fn domain(&self) -> &Domain {
        &self.domain
    }

    /// The box of the samples `rect` between heights `zmin` and `zmax`.
    pub fn rect_box(&self, rect: &SampleRect, zmin: f32, zmax: f32) -> Aabb {
        self.world.rect_box(rect, f64::from(zmin), f64::from(zmax))
    }

    /// The box of a node record: its footprint clipped to the data, by its height range.
    pub fn node_box(&self, n: &StoredNode) -> Aabb {
        let rect = Quadrant {
            level: n.level,
            x: n.x,
            y: n.y,
        }
        .samples(&self.domain);
        self.rect_box(&rect, n.min_height, n.max_height)
    }

    /// The box of quadrant `q`, from the terrain's lowest to its highest height.
    pub(super) fn quadrant_box(&self, q: &Quadrant) -> Aabb {
        self.rect_box(
            &q.samples(&self.domain),
            self.root.min_height,
            self.root.max_height,
        )
    }

    /// The region a scene covers ([`Region`]): `window` itself, or the quadrants the
    /// frustum may see.
    pub fn region(&self, view: &View, window: Option<SampleRect>) -> Result<Region> {
        self.region_to(view, window, self.domain.finest_level())
    }

    /// As [`Terrain::region`], with the frustum's quadrants split no deeper than level
    /// `deepest`: fewer, coarser quadrants that hold the same visible terrain and more
    /// besides. A window's quadrants are always exact.
    pub(super) fn region_to(
        &self,
        view: &View,
        window: Option<SampleRect>,
        deepest: u8,
    ) -> Result<Region> {
        let d = self.domain;
        let deepest = deepest.min(d.finest_level());
        let data = d.data_rect();
        let (mut near, mut far) = (f64::INFINITY, 0.0f64);
        let (quadrants, keys) = match window {
            Some(w) => {
                w.check_inside(&data, "data")?;
                let blocks = ranges::window_blocks(&d, &w);
                let (quadrants, keys) =
                    ranges::decompose(&d, d.finest_level(), ranges::window_classifier(&d, blocks));
                for q in &quadrants {
                    let b = self.quadrant_box(q);
                    near = near.min(b.distance(view.eye));
                    far = far.max(b.max_distance(view.eye));
                }
                (quadrants, keys)
            }
            // Each candidate's box is made once: to classify it, and if it is kept, to
            // measure it.
            None => ranges::decompose(&d, deepest, |q| {
                let rect = q.samples(&d);
                if self.hidden(view, &rect, self.root.max_height) {
                    return Coverage::Outside;
                }
                // The quadrant's box: `quadrant_box`, its rectangle made once.
                let b = self.rect_box(&rect, self.root.min_height, self.root.max_height);
                let c = view.classify(&b);
                if ranges::kept_whole(c, q.level, deepest) {
                    near = near.min(b.distance(view.eye));
                    far = far.max(b.max_distance(view.eye));
                }
                c
            }),
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
        Ok(Region {
            quadrants,
            keys,
            window,
            coarse: window.is_none() && deepest < d.finest_level(),
            span,
            near,
            far,
        })
    }

    /// The scene block of node `index`, seen from `view`.
    pub fn node_block(&self, view: &View, index: u32, n: &StoredNode) -> SceneBlock {
        self.node_block_at(view, index, n, self.node_box(n).distance(view.eye))
    }

    /// The scene block of node `index` at `distance` from the eye.
    pub(super) fn node_block_at(
        &self,
        view: &View,
        index: u32,
        n: &StoredNode,
        distance: f64,
    ) -> SceneBlock {
        let rect = Quadrant {
            level: n.level,
            x: n.x,
            y: n.y,
        }
        .samples(&self.domain);
        SceneBlock {
            node: Some(index),
            level: n.level,
            x: n.x,
            y: n.y,
            key: n.key.0,
            col0: rect.col0,
            row0: rect.row0,
            col1: rect.col1,
            row1: rect.row1,
            error: n.monotone_error,
            screen_error: view.screen_error(n.monotone_error, distance),
            distance,
            min_height: n.min_height,
            max_height: n.max_height,
            payload: n.payload,
            neighbours: [None; 4],
        }
    }

    /// Physical block `(x, y)`, its heights bounded by `zmin..=zmax`: exact, or within the
    /// storage error of a file with a precision.
    pub fn physical_block(
        &self,
        view: &View,
        x: u32,
        y: u32,
        zmin: f32,
        zmax: f32,
    ) -> Result<SceneBlock> {
        let d = self.domain;
        let stored = self.store.stored_block(x, y)?;
        let finest = d.finest_level();
        let rect = Quadrant {
            level: finest,
            x,
            y,
        }
        .samples(&d);
        let real =
            u64::from(stored.width) * u64::from(stored.height) > u64::from(stored.void_count);
        let error = if real { self.storage_error } else { 0.0 };
        let distance = self.rect_box(&rect, zmin, zmax).distance(view.eye);
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
            error,
            screen_error: view.screen_error(error, distance),
            distance,
            min_height: zmin,
            max_height: zmax,
            payload: stored.payload,
            neighbours: [None; 4],
        })
    }

    /// The box of a scene block: its samples by its height range.
    pub fn block_box(&self, b: &SceneBlock) -> Aabb {
        block_box(&self.world, b)
    }

    /// The root's height range: bounds every height of the terrain.
    pub fn height_range(&self) -> (f32, f32) {
        (self.root.min_height, self.root.max_height)
    }

    /// Sorts `blocks` by key, drops repeats and (for a frustum region) blocks whose own box
    /// misses the frustum, and fills in neighbour levels.
    pub fn finish(&self, view: &View, window: Option<SampleRect>, blocks: &mut Vec<SceneBlock>) {
        blocks.sort_unstable_by_key(|b| (b.key, b.level));
        blocks.dedup_by_key(|b| (b.key, b.level));
        if window.is_none() {
            blocks.retain(|b| {
                view.intersects(&self.block_box(b)) && !self.hidden(view, &b.rect(), b.max_height)
            });
        }
        stitch::set_neighbours(&self.domain, blocks);
    }
}
