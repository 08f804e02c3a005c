//! The door: the few types a terrain application or a tool needs, over every room behind them.
//!
//! A [`Terrain`] is anything fmrh opens — a container file, a dataset directory, or either by
//! URL — behind one type: [`Terrain::open`] decides which. It describes itself ([`Info`]),
//! answers a camera and a tolerance with a [`Scene`] whose [`Block`]s carry their decoded
//! heights beside their rectangle, level, stride and error ([`Terrain::scene`]), and a moving
//! camera frame by frame with what entered and left the view ([`Terrain::fly`]), reads
//! full-resolution samples ([`Terrain::read`]) or the surface within an error bound
//! ([`Terrain::read_within`]), changes samples atomically ([`Terrain::edit`], an [`Edit`])
//! and checks every invariant ([`Terrain::verify`]). [`create`] and [`build`] make
//! containers, [`build_dataset`] and [`add_tile`] datasets, and [`distributed`] a dataset on
//! many machines. The parent chain a payload is coded against, read coalescing and the caches
//! are inside; [`crate::raw`] is the way down for a tool that wants them.
//!
//! This room owns no bytes and no algorithm: each method is a few calls into the store, the
//! scene, the dataset and the model. What it adds is one vocabulary for a container and a
//! dataset alike, and values that need nothing else to be used (a block's heights come with
//! the rectangle they cover).

mod approximate;
mod create;
mod datasets;
pub mod distributed;
mod edit;
mod flight;
mod scene;
mod verify;

use std::path::{Path, PathBuf};
use std::sync::Arc;

use serde::Serialize;

pub use approximate::{Approximation, Strided};
pub use create::{build, create, create_with_progress, load, CreateOptions, Created};
pub use datasets::{add_tile, build_dataset, DatasetBuildOptions, TileAdded};
pub use edit::{Committed, Edit};
pub use flight::{Flight, FlightFrame};
pub use scene::{Block, BlockKey, Scene};
pub use verify::Verification;

use crate::dataset::Dataset;
use crate::error::{Error, Result};
use crate::geoid::VerticalDatum;
use crate::heightfield::{Georeference, Heightfield};
use crate::model::SampleRect;
use crate::store::{is_url, AnySource, Store};

/// A container, a dataset, or either by URL, opened for reading (see the module docs).
///
/// A terrain reads the state it opened, whatever writers do meanwhile (a registered reader,
/// format §11.6; over HTTP the object's ETag is pinned): open it again to see a later commit.
pub struct Terrain {
    location: PathBuf,
    source: Source,
    /// Ground spacing that overrides the data's for flat scenes.
    spacing_m: Option<[f64; 2]>,
}

impl std::fmt::Debug for Terrain {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Terrain")
            .field("location", &self.location)
            .field(
                "kind",
                &match self.source {
                    Source::Container(_) => Kind::Container,
                    Source::Dataset(_) => Kind::Dataset,
                },
            )
            .finish_non_exhaustive()
    }
}

/// What a terrain reads.
enum Source {
    Container(Arc<Store<AnySource>>),
    Dataset(Box<Dataset>),
}

impl Terrain {
    /// Opens `location`: a container file, a dataset directory (one with a `MANIFEST`), or a
    /// URL (`http://`, `https://`, `s3://`) of either, where a URL ending in `/` or
    /// `/MANIFEST` names a dataset. Opening reads the commit slots and the little metadata a
    /// scene starts from (one round over a network), nothing else.
    ///
    /// ```
    /// # fn main() -> fmrh::Result<()> {
    /// # let dir = tempfile::tempdir().unwrap();
    /// # let path = dir.path().join("hill.fmrh");
    /// # let hill = fmrh::Heightfield::from_fn(100, 80, |x, y| (x * y) as f32 * 0.1)?;
    /// # fmrh::create(&path, hill, &fmrh::CreateOptions::default())?;
    /// let terrain = fmrh::Terrain::open(&path)?;
    /// let info = terrain.info()?;
    /// assert_eq!((info.width, info.height), (100, 80));
    /// # Ok(()) }
    /// ```
    pub fn open(location: impl AsRef<Path>) -> Result<Terrain> {
        let location = location.as_ref();
        let source = if names_dataset(location)? {
            Source::Dataset(Box::new(Dataset::open(location)?))
        } else {
            Source::Container(Arc::new(Store::from_source(AnySource::open(location)?)?))
        };
        Ok(Terrain {
            location: location.to_path_buf(),
            source,
            spacing_m: None,
        })
    }

    /// Where it was opened from.
    pub fn location(&self) -> &Path {
        &self.location
    }

    /// Places samples `spacing_m = [east, south]` metres apart in flat scenes, instead of the
    /// distance the data records (`None`: the data's again). Needed for data that records
    /// none ([`Info::spacing_m`] is `None`), where flat scenes are refused.
    pub fn set_spacing(&mut self, spacing_m: Option<[f64; 2]>) -> Result<()> {
        if let Some(s) = spacing_m {
            if !s.iter().all(|d| d.is_finite() && *d > 0.0) {
                return Err(Error::InvalidArgument(format!(
                    "spacing {s:?}: expected finite metres > 0"
                )));
            }
        }
        self.spacing_m = spacing_m;
        Ok(())
    }

    /// What it is: its size, georeference, heights, error levels, and the state it reads.
    ///
    /// ```
    /// # fn main() -> fmrh::Result<()> {
    /// # let dir = tempfile::tempdir().unwrap();
    /// # let path = dir.path().join("ramp.fmrh");
    /// let bumps = fmrh::Heightfield::from_fn(129, 129, |x, y| ((x * y) % 17) as f32)?;
    /// fmrh::create(&path, bumps, &fmrh::CreateOptions::default())?;
    /// let info = fmrh::Terrain::open(&path)?.info()?;
    /// assert_eq!(info.height_range, Some([0.0, 16.0]));
    /// // Error levels from the lossless one up to the coarsest.
    /// let levels = &info.error_levels;
    /// assert_eq!(levels[0].max_error, 0.0);
    /// assert!(levels.windows(2).all(|w| w[0].threshold < w[1].threshold));
    /// assert_eq!(levels.last().map(|l| l.max_error), info.max_error);
    /// # Ok(()) }
    /// ```
    pub fn info(&self) -> Result<Info> {
        Ok(match &self.source {
            Source::Container(store) => {
                let h = store.header();
                let root = store.node(0)?;
                let d = store.domain();
                let state = store.state();
                let valid = h.valid_samples > 0;
                Info {
                    kind: Kind::Container,
                    width: u64::from(d.width()),
                    height: u64::from(d.height()),
                    block_size: Some(d.block_size()),
                    spacing_m: h.metadata.spacing_m,
                    georeference: h.metadata.georeference.clone(),
                    units: h.metadata.units.clone(),
                    source_format: h.metadata.source_format.clone(),
                    vertical_datum: h.metadata.vertical_datum,
                    height_range: valid.then_some([root.min_height, root.max_height]),
                    max_error: Some(h.max_error),
                    storage_error: h.storage_error(),
                    error_levels: store
                        .clusters()
                        .iter()
                        .map(|c| ErrorLevel {
                            threshold: c.threshold,
                            max_error: c.max_error,
                            blocks: c.nodes(),
                        })
                        .collect(),
                    tiles: None,
                    txn_id: state.txn_id,
                    format_version: state.format_version,
                }
            }
            Source::Dataset(ds) => {
                let grid = ds.grid();
                let head = &ds.state().head;
                let range = head
                    .pages
                    .iter()
                    .map(|p| [p.min_height.get(), p.max_height.get()])
                    .filter(|[lo, hi]| lo <= hi)
                    .reduce(|a, b| [a[0].min(b[0]), a[1].max(b[1])]);
                Info {
                    kind: Kind::Dataset,
                    width: grid.col1 + 1,
                    height: grid.row1 + 1,
                    block_size: None,
                    spacing_m: ds.spacing_m(),
                    georeference: ds.georeference(),
                    units: None,
                    source_format: match ds.first_tile()? {
                        Some(t) => ds.open_tile(&t)?.header().metadata.source_format.clone(),
                        None => String::new(),
                    },
                    vertical_datum: ds.vertical_datum()?,
                    height_range: range,
                    max_error: None,
                    storage_error: 0.0,
                    error_levels: Vec::new(),
                    tiles: Some(ds.tile_count()),
                    txn_id: ds.txn_id(),
                    format_version: (
                        crate::format::manifest::MANIFEST_MAJOR,
                        ds.state().record.minor.get(),
                    ),
                }
            }
        })
    }

    /// The samples of `window` (inclusive sample coordinates; `None`: all of them) exactly as
    /// stored, voids (and a dataset's holes) as NaN, with the window's georeference.
    ///
    /// ```
    /// # fn main() -> fmrh::Result<()> {
    /// # let dir = tempfile::tempdir().unwrap();
    /// # let path = dir.path().join("ramp.fmrh");
    /// let ramp = fmrh::Heightfield::from_fn(50, 40, |x, y| (x + 2 * y) as f32)?;
    /// fmrh::create(&path, ramp, &fmrh::CreateOptions::default())?;
    /// let terrain = fmrh::Terrain::open(&path)?;
    /// let window = fmrh::types::SampleRect { col0: 10, row0: 5, col1: 12, row1: 6 };
    /// let samples = terrain.read(Some(window))?;
    /// assert_eq!(samples.samples(), &[20.0, 21.0, 22.0, 22.0, 23.0, 24.0]);
    /// # Ok(()) }
    /// ```
    pub fn read(&self, window: Option<SampleRect>) -> Result<Heightfield> {
        match &self.source {
            Source::Container(store) => {
                store.read_window(window.unwrap_or_else(|| store.domain().data_rect()))
            }
            Source::Dataset(ds) => ds.read_window(window.unwrap_or_else(|| ds.grid())),
        }
    }

    /// A dataset's tile files, by the names its manifest gives them (in its order); none
    /// for a container.
    pub fn tile_files(&self) -> Result<Vec<String>> {
        match &self.source {
            Source::Container(_) => Ok(Vec::new()),
            Source::Dataset(ds) => Ok(ds.tiles()?.iter().map(|t| t.name().to_string()).collect()),
        }
    }

    /// The container store, when it is one (the way down to [`crate::raw`]).
    pub fn store(&self) -> Option<&Store<AnySource>> {
        match &self.source {
            Source::Container(store) => Some(store),
            Source::Dataset(_) => None,
        }
    }

    /// A local path to write to, or why not.
    fn writable_path(&self) -> Result<&Path> {
        if self.location.to_str().is_some_and(is_url) {
            return Err(Error::InvalidArgument(format!(
                "{}: a terrain read over a network is read-only; edit the file where it lives",
                self.location.display()
            )));
        }
        Ok(&self.location)
    }
}

/// Whether `location` names a dataset rather than a container; a local directory without a
/// `MANIFEST` is an error, not a file to open.
pub(crate) fn names_dataset(location: &Path) -> Result<bool> {
    if location.to_str().is_some_and(is_url) {
        return Ok(crate::dataset::is_dataset(location));
    }
    if !location.is_dir() {
        return Ok(false);
    }
    if crate::dataset::is_dataset(location) {
        return Ok(true);
    }
    Err(Error::input(
        location,
        "a directory without a MANIFEST: not an fmrh dataset (nor a container file)",
    ))
}

/// Whether a terrain is one file or a dataset of many.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize)]
#[serde(rename_all = "lowercase")]
pub enum Kind {
    /// One container file.
    Container,
    /// A directory of containers placed by a manifest.
    Dataset,
}

/// What a terrain is ([`Terrain::info`]).
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct Info {
    /// A container or a dataset.
    pub kind: Kind,
    /// Samples along a row (a dataset's: of its whole grid, holes included).
    pub width: u64,
    /// Samples down a column.
    pub height: u64,
    /// Samples along a block side (a container's; a dataset's tiles each have theirs).
    pub block_size: Option<u32>,
    /// Metres between samples east and south, when the data says.
    pub spacing_m: Option<[f64; 2]>,
    /// Where sample `(0, 0)` lies and how samples step, in the data's CRS.
    pub georeference: Option<Georeference>,
    /// Units of the heights, when the data says.
    pub units: Option<String>,
    /// The reader that made it (`srtm-hgt`, `dted`, `geotiff`, …; a dataset's: its first
    /// tile's), which says what the heights are above when nothing else does.
    pub source_format: String,
    /// What the heights are above (a dataset's: its first tile's, as every tile's is).
    pub vertical_datum: VerticalDatum,
    /// The lowest and highest real height; `None` when every sample is void.
    pub height_range: Option<[f32; 2]>,
    /// The coarsest level's measured error, in height units (a container's: its root's `e*`).
    pub max_error: Option<f64>,
    /// How far a stored height may be from its source (`9Q/16` of a storage precision `Q`),
    /// 0 when heights are stored bit for bit.
    pub storage_error: f64,
    /// The error levels (clusters), by threshold ascending (the finest first): a scene at any
    /// tolerance is drawn from blocks of these levels (a container's; a dataset's tiles each
    /// have theirs).
    pub error_levels: Vec<ErrorLevel>,
    /// A dataset's tiles.
    pub tiles: Option<u64>,
    /// The state read: the container's or the manifest's transaction id.
    pub txn_id: u64,
    /// The container format's (or the manifest's) version, major and minor.
    pub format_version: (u16, u16),
}

/// One error level of a container: the cut of its tree whose blocks are all within a
/// threshold, covering the terrain exactly once.
#[derive(Clone, Copy, Debug, PartialEq, Serialize)]
pub struct ErrorLevel {
    /// The threshold, in height units.
    pub threshold: f64,
    /// The largest measured error of its blocks (at most the threshold).
    pub max_error: f64,
    /// Its blocks.
    pub blocks: u64,
}
