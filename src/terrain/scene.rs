//! A scene through the door: the blocks a camera needs at a tolerance, selected and decoded in
//! one call, each [`Block`] carrying its heights with the rectangle, level, stride and error
//! they belong to.

use std::sync::Arc;

use serde::Serialize;

use super::{Source, Terrain};
use crate::error::{Error, Result};
use crate::model::SampleRect;
use crate::scene::{
    load_blocks, Camera, Mode, NeighbourLevels, SceneBlock, SceneOptions, SceneStats, PAYLOAD_GAP,
};

/// The blocks one view needs, decoded ([`Terrain::scene`]).
///
/// They cover the view's region exactly once (blocks share edges, nothing more), and each is
/// within the tolerance where it is seen: its measured error, seen from the eye, is at most
/// `tau` pixels (view-dependent mode), or every block is within one bound (uniform mode).
///
/// ```
/// use fmrh::glam::DVec3;
/// use fmrh::types::Mode;
/// use fmrh::{Camera, SceneOptions, Terrain};
///
/// # fn main() -> fmrh::Result<()> {
/// # let dir = tempfile::tempdir().unwrap();
/// # let path = dir.path().join("waves.fmrh");
/// let waves = fmrh::Heightfield::from_fn(513, 513, |x, y| {
///     (30.0 * (x as f32 * 0.03).sin() + 20.0 * (y as f32 * 0.05).cos()).round()
/// })?;
/// fmrh::create(&path, waves, &fmrh::CreateOptions::default())?;
/// let mut terrain = Terrain::open(&path)?;
/// terrain.set_spacing(Some([30.0, 30.0]))?;
/// let camera = Camera::looking_at(DVec3::new(-3000.0, -3000.0, 2000.0), DVec3::new(7000.0, 7000.0, 0.0));
/// let coarse = terrain.scene(&camera, &SceneOptions::new(8.0))?;
/// let fine = terrain.scene(&camera, &SceneOptions::new(0.5))?;
/// assert!(coarse.blocks.len() <= fine.blocks.len());
/// assert_eq!(fine.mode, Mode::View);
/// assert!(fine.stats.max_screen_error <= 0.5);
/// # Ok(()) }
/// ```
#[derive(Clone, Debug, Serialize)]
pub struct Scene {
    /// The mode used.
    pub mode: Mode,
    /// The tolerance in pixels.
    pub tau: f64,
    /// The samples the view's region spans (the explicit window, or what the frustum may
    /// see); `None` when the camera sees no terrain.
    pub window: Option<SampleRect>,
    /// The blocks, in Hilbert order (a dataset's: tile by tile).
    pub blocks: Vec<Block>,
    /// What the selection cost and guarantees.
    pub stats: SceneStats,
}

/// One block of a scene, decoded: the surface it draws over its rectangle.
///
/// Its grid is `width × height` heights, row-major from the north-west corner, grid point
/// `(i, j)` at sample `(rect.col0 + i·stride, rect.row0 + j·stride)`; a grid may reach past
/// the data's edge, where the heights repeat the edge (padding). Between grid points the
/// surface is each cell split along its north-west to south-east diagonal (`model.md` §4).
/// Voids are mended (their heights are what the model draws there).
///
/// ```
/// use fmrh::glam::DVec3;
/// use fmrh::{Camera, SceneOptions, Terrain};
///
/// # fn main() -> fmrh::Result<()> {
/// # let dir = tempfile::tempdir().unwrap();
/// # let path = dir.path().join("plane.fmrh");
/// // A tilted plane: every block draws it exactly, whatever its level.
/// let plane = fmrh::Heightfield::from_fn(300, 200, |x, y| (2 * x + y) as f32)?;
/// fmrh::create(&path, plane, &fmrh::CreateOptions::default())?;
/// let mut terrain = Terrain::open(&path)?;
/// terrain.set_spacing(Some([1.0, 1.0]))?;
/// let camera = Camera::looking_at(DVec3::new(150.0, -300.0, 400.0), DVec3::new(150.0, 100.0, 0.0));
/// for block in terrain.scene(&camera, &SceneOptions::new(0.5))?.blocks {
///     let (col, row) = (block.rect.col0 + block.stride, block.rect.row0);
///     assert_eq!(block.grid_height(1, 0), Some((2 * col + row) as f32));
/// }
/// # Ok(()) }
/// ```
#[derive(Clone, Debug, Serialize)]
pub struct Block {
    /// The samples it covers, inclusive, in the terrain's samples (a dataset's grid).
    pub rect: SampleRect,
    /// Its level in its file's tree: 0 the root, larger finer.
    pub level: u8,
    /// The tile it comes from (a dataset's index), or `None` for a container.
    pub tile: Option<u64>,
    /// Its measured error `e*`: no real sample it covers is farther from its surface, in
    /// height units.
    pub error: f64,
    /// That error seen from the eye, in pixels.
    pub screen_error: f64,
    /// Samples between its grid points.
    pub stride: u64,
    /// Metres between its grid points east and south, where the data's spacing is known.
    pub spacing_m: Option<[f64; 2]>,
    /// Grid points along a row of `heights`.
    pub width: u32,
    /// Rows of `heights`.
    pub height: u32,
    /// The heights, row-major from the north-west corner.
    #[serde(skip)]
    pub heights: Arc<[f32]>,
    /// The levels of the blocks across its north, east, south and west edges (`None`: the
    /// data's edge, or outside the scene), to stitch edges where levels differ.
    pub neighbours: [Option<NeighbourLevels>; 4],
}

impl Block {
    /// Its height at grid point `(i, j)`.
    pub fn grid_height(&self, i: u32, j: u32) -> Option<f32> {
        (i < self.width && j < self.height)
            .then(|| self.heights[j as usize * self.width as usize + i as usize])
    }
}

impl Terrain {
    /// The blocks `camera` needs at `options.tau` pixels of screen-space error, decoded.
    /// The camera is in the flat frame: metres east (`x = col · dx`), south (`y = row · dy`)
    /// and up from sample `(0, 0)`; data that does not record its spacing needs
    /// [`Terrain::set_spacing`] first.
    ///
    /// ```
    /// use fmrh::glam::DVec3;
    /// use fmrh::{Camera, SceneOptions, Terrain};
    ///
    /// # fn main() -> fmrh::Result<()> {
    /// # let dir = tempfile::tempdir().unwrap();
    /// # let path = dir.path().join("hills.fmrh");
    /// let hills = fmrh::Heightfield::from_fn(257, 257, |x, y| {
    ///     40.0 * (x as f32 * 0.05).sin() * (y as f32 * 0.07).cos()
    /// })?;
    /// fmrh::create(&path, hills, &fmrh::CreateOptions::default())?;
    /// let mut terrain = Terrain::open(&path)?;
    /// terrain.set_spacing(Some([1.0, 1.0]))?; // samples 1 m apart
    /// let camera = Camera::looking_at(DVec3::new(-50.0, -50.0, 120.0), DVec3::new(128.0, 128.0, 0.0));
    /// let scene = terrain.scene(&camera, &SceneOptions::new(1.0))?;
    /// assert!(scene.stats.max_screen_error <= 1.0);
    /// for block in &scene.blocks {
    ///     assert_eq!(block.heights.len(), (block.width * block.height) as usize);
    /// }
    /// # Ok(()) }
    /// ```
    pub fn scene(&self, camera: &Camera, options: &SceneOptions) -> Result<Scene> {
        self.select(camera, options, false)
    }

    /// As [`Terrain::scene`], with the samples on the WGS 84 ellipsoid and the camera in
    /// Earth-centred, Earth-fixed metres ([`Camera::on_globe`] places one by latitude,
    /// longitude and height): for data on a geographic grid.
    pub fn scene_on_globe(&self, camera: &Camera, options: &SceneOptions) -> Result<Scene> {
        self.select(camera, options, true)
    }

    fn select(&self, camera: &Camera, options: &SceneOptions, globe: bool) -> Result<Scene> {
        self.selected(camera, options, globe)?
            .decode(self, |_| true)
    }

    /// The blocks `camera` needs, selected but not yet read: flat (`globe` false) or on the
    /// globe.
    pub(super) fn selected(
        &self,
        camera: &Camera,
        options: &SceneOptions,
        globe: bool,
    ) -> Result<Selected> {
        let spacing = if globe {
            None
        } else {
            Some(self.flat_spacing()?)
        };
        Ok(match &self.source {
            Source::Container(store) => {
                let selector = match spacing {
                    Some(s) => crate::scene::Terrain::with_spacing(store, Some(s))?,
                    None => crate::scene::Terrain::on_globe(store)?,
                };
                Selected::Container(
                    selector.scene(camera, options)?,
                    spacing.or(store.header().metadata.spacing_m),
                )
            }
            Source::Dataset(ds) => {
                let scene = match spacing {
                    Some(s) => ds.scene(camera, options, Some(s))?,
                    None => ds.scene_on_globe(camera, options)?,
                };
                Selected::Dataset(scene, spacing.or(ds.spacing_m()))
            }
        })
    }

    /// The *cut* of the terrain within a static bound, decoded: the blocks over `window`
    /// (inclusive samples, inside the data) of the coarsest error level whose every block
    /// is within `max_error` of the source (exact physical blocks below the finest level).
    /// No camera: screen errors are 0. An error level is a cut of the whole tree, so two
    /// windows get the same blocks where they overlap (tiles of another pyramid cut from
    /// neighbouring windows agree along their edges).
    ///
    /// ```
    /// use fmrh::types::SampleRect;
    /// use fmrh::Terrain;
    ///
    /// # fn main() -> fmrh::Result<()> {
    /// # let dir = tempfile::tempdir().unwrap();
    /// # let path = dir.path().join("ridges.fmrh");
    /// let ridges = fmrh::Heightfield::from_fn(257, 257, |x, y| ((x * 3 + y) % 40) as f32)?;
    /// fmrh::create(&path, ridges, &fmrh::CreateOptions::default())?;
    /// let terrain = Terrain::open(&path)?;
    /// let window = SampleRect { col0: 10, row0: 20, col1: 200, row1: 120 };
    /// let exact = terrain.cut(window, 0.0)?;
    /// let coarse = terrain.cut(window, 25.0)?;
    /// assert!(exact.blocks.iter().all(|b| b.error == 0.0 && b.stride == 1));
    /// assert!(coarse.blocks.iter().all(|b| b.error <= 25.0));
    /// assert!(coarse.blocks.len() <= exact.blocks.len());
    /// # Ok(()) }
    /// ```
    pub fn cut(&self, window: SampleRect, max_error: f64) -> Result<Scene> {
        match &self.source {
            Source::Container(store) => {
                let selector = crate::scene::Terrain::with_spacing(store, None)?;
                let scene = selector.cut(window, max_error, crate::scene::DEFAULT_GAP)?;
                decoded(
                    store,
                    scene,
                    self.spacing_m.or(store.header().metadata.spacing_m),
                )
            }
            Source::Dataset(ds) => {
                let scene = ds.cut(window, max_error)?;
                decoded_dataset(ds, scene, self.spacing_m.or(ds.spacing_m()))
            }
        }
    }

    /// The spacing flat scenes place samples with: the one set, else the data's, else an
    /// error (a camera in metres over samples of unknown size would see the wrong terrain).
    fn flat_spacing(&self) -> Result<[f64; 2]> {
        let recorded = match &self.source {
            Source::Container(store) => store.header().metadata.spacing_m,
            Source::Dataset(ds) => ds.spacing_m(),
        };
        self.spacing_m.or(recorded).ok_or_else(|| {
            Error::InvalidArgument(format!(
                "{}: the distance between samples is unknown (its source did not say), so a \
                 camera in metres cannot be placed; give one with Terrain::set_spacing \
                 ([1.0, 1.0] measures the world in samples)",
                self.location.display()
            ))
        })
    }
}

/// A scene selected but not read: a container's or a dataset's, with the spacing its
/// blocks are placed at.
pub(super) enum Selected {
    Container(crate::scene::Scene, Option<[f64; 2]>),
    Dataset(crate::dataset::DatasetScene, Option<[f64; 2]>),
}

/// Which file a selected block comes from and where it is in that file's tree: the same
/// block in two frames has the same key (a terrain reads one state).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, PartialOrd, Ord, Serialize)]
pub struct BlockKey {
    /// The tile (a dataset's index), or `None` for a container.
    pub tile: Option<u64>,
    /// Its level in its file's tree.
    pub level: u8,
    /// Its column among the level's nodes.
    pub x: u32,
    /// Its row among the level's nodes.
    pub y: u32,
}

impl Selected {
    /// What the selection cost and guarantees.
    pub(super) fn stats(&self) -> crate::scene::SceneStats {
        match self {
            Selected::Container(s, _) => s.stats,
            Selected::Dataset(s, _) => s.stats,
        }
    }

    /// The keys of its blocks, in scene order.
    pub(super) fn keys(&self) -> Vec<BlockKey> {
        match self {
            Selected::Container(s, _) => s
                .blocks
                .iter()
                .map(|b| BlockKey {
                    tile: None,
                    level: b.level,
                    x: b.x,
                    y: b.y,
                })
                .collect(),
            Selected::Dataset(s, _) => s
                .blocks
                .iter()
                .map(|b| BlockKey {
                    tile: Some(b.tile),
                    level: b.block.level,
                    x: b.block.x,
                    y: b.block.y,
                })
                .collect(),
        }
    }

    /// The scene with the blocks `wanted` says yes to (by their index in the scene) read
    /// and decoded; the others are left out.
    pub(super) fn decode(self, terrain: &Terrain, wanted: impl Fn(usize) -> bool) -> Result<Scene> {
        match (self, &terrain.source) {
            (Selected::Container(mut scene, spacing), Source::Container(store)) => {
                let mut i = 0;
                scene.blocks.retain(|_| {
                    i += 1;
                    wanted(i - 1)
                });
                decoded(store, scene, spacing)
            }
            (Selected::Dataset(mut scene, spacing), Source::Dataset(ds)) => {
                let mut i = 0;
                scene.blocks.retain(|_| {
                    i += 1;
                    wanted(i - 1)
                });
                decoded_dataset(ds, scene, spacing)
            }
            _ => Err(Error::InvalidArgument(
                "a scene selected on one terrain cannot be read from another".into(),
            )),
        }
    }
}

/// A container's scene with its blocks read and decoded, samples `spacing_m` apart.
fn decoded(
    store: &crate::store::Store<crate::store::AnySource>,
    scene: crate::scene::Scene,
    spacing_m: Option<[f64; 2]>,
) -> Result<Scene> {
    let loaded = load_blocks(store, &scene.blocks, PAYLOAD_GAP)?;
    let d = store.domain();
    let blocks = scene
        .blocks
        .iter()
        .zip(loaded)
        .map(|(b, l)| block(b, None, d.stride(b.level), spacing_m, l))
        .collect();
    Ok(Scene {
        mode: scene.mode,
        tau: scene.tau,
        window: scene.window,
        blocks,
        stats: scene.stats,
    })
}

/// A dataset's scene with its blocks read and decoded, samples `spacing_m` apart.
fn decoded_dataset(
    ds: &crate::dataset::Dataset,
    scene: crate::dataset::DatasetScene,
    spacing_m: Option<[f64; 2]>,
) -> Result<Scene> {
    let loaded = ds.load_blocks(&scene)?;
    let blocks = scene
        .blocks
        .iter()
        .zip(loaded)
        .map(|(b, (l, stride))| block(&b.block, Some(b.tile), stride, spacing_m, l))
        .collect();
    Ok(Scene {
        mode: scene.mode,
        tau: scene.tau,
        window: scene.window,
        blocks,
        stats: scene.stats,
    })
}

/// The door's block of scene block `b` with its decoded grid `l`.
fn block(
    b: &SceneBlock,
    tile: Option<u64>,
    stride: u64,
    spacing_m: Option<[f64; 2]>,
    l: crate::scene::LoadedBlock,
) -> Block {
    Block {
        rect: b.rect(),
        level: b.level,
        tile,
        error: b.error,
        screen_error: b.screen_error,
        stride,
        spacing_m: spacing_m.map(|[dx, dy]| [dx * stride as f64, dy * stride as f64]),
        width: l.width,
        height: l.height,
        heights: l.heights,
        neighbours: b.neighbours,
    }
}
