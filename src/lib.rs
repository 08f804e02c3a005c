//! # fmrh — an embedded storage engine for multiresolution terrain
//!
//! fmrh keeps a digital elevation model (a grid of heights) so that a terrain application can
//! ask, every frame, for exactly the blocks a view needs, each exact to a known error, and
//! change heights atomically while others read.
//!
//! ## The data structure, before the API
//!
//! **Blocks.** The grid is cut into square blocks of `b = 2^k + 1` samples a side (65 by
//! default); neighbouring blocks share their edge row and column.
//!
//! **The FMRH** (seed 000 §3). A quadtree over the blocks: the finest level holds the blocks
//! at full resolution, each level up halves the resolution, the root covers everything with
//! one `b × b` grid. Every node carries its *measured* error: the largest vertical distance
//! between a real sample under it and the surface its grid draws. The tree is cut short where
//! the error is already within the finest threshold, so flat ground costs one node.
//!
//! **Error levels** (seed 000's clusters, corrected). For a threshold δ, the level is the cut
//! of the tree whose nodes are all within δ: it covers the terrain exactly once. A ladder of
//! thresholds gives a ladder of levels, from one coarse root down to the lossless blocks.
//!
//! **Hilbert order** (seed 000 §4). Inside a level, nodes are sorted along a multiresolution
//! Hilbert curve, so a view's window is a few contiguous runs: a scene is a few range scans.
//!
//! **Transactions.** Replacing samples rewrites every block, error, level and table they touch,
//! copy-on-write, published by one commit record: readers keep the state they opened, and a
//! crash at any instant leaves the old state or the new one (`format-spec/container.md` §11).
//!
//! ## The door
//!
//! | type | what for |
//! |---|---|
//! | [`Terrain`] | anything fmrh opens: a container file, a dataset directory, or a URL of either |
//! | [`Info`] | what a terrain is: size, georeference, heights, error levels |
//! | [`Camera`], [`SceneOptions`] | a view (glam's `DVec3`, re-exported as [`glam`]) and its tolerance in pixels |
//! | [`Scene`], [`Block`] | the blocks a view needs, each with its decoded heights, rectangle, level, stride and error |
//! | [`Edit`] | replacements of samples, committed atomically |
//! | [`Heightfield`], [`CreateOptions`] | heights in memory, and how [`create`] (or [`build`], from a DEM file) makes a container |
//! | [`Verification`] | every numbered invariant checked |
//! | [`Error`] | what went wrong, and whose fault it is |
//!
//! The values these take and give (rectangles, georeferences, modes, reports) are in
//! [`types`]. Which grid a block is coded against, read coalescing and the caches are inside.
//!
//! ```
//! use fmrh::glam::DVec3;
//! use fmrh::{Camera, CreateOptions, Heightfield, SceneOptions, Terrain};
//!
//! # fn main() -> fmrh::Result<()> {
//! # let dir = tempfile::tempdir().unwrap();
//! # let path = dir.path().join("hills.fmrh");
//! let hills = Heightfield::from_fn(257, 257, |x, y| {
//!     40.0 * (x as f32 * 0.05).sin() * (y as f32 * 0.07).cos() // or fmrh::build from a DEM file
//! })?;
//! fmrh::create(&path, hills, &CreateOptions::default())?;
//! let mut terrain = Terrain::open(&path)?; // a file, a dataset directory, or a URL
//! terrain.set_spacing(Some([10.0, 10.0]))?; // metres between samples (a georeferenced DEM says)
//! let camera = Camera::looking_at(DVec3::new(-500.0, -500.0, 900.0), DVec3::new(1280.0, 1280.0, 0.0));
//! let scene = terrain.scene(&camera, &SceneOptions::new(1.0))?; // at most 1 pixel of error
//! for block in &scene.blocks {
//!     // `width × height` heights, `stride` samples apart from the corner of `rect`.
//!     assert_eq!(block.heights.len(), (block.width * block.height) as usize);
//!     assert!(block.screen_error <= 1.0);
//! }
//! # Ok(()) }
//! ```
//!
//! ## Going lower
//!
//! [`raw`] is the format itself, for a tool: a container's nodes, blocks and error levels
//! (clusters), Hilbert range scans, payloads as stored, transactions with snapshots, the
//! validator, and the format's version ([`raw::FORMAT_MAJOR`], [`raw::FORMAT_MINOR`]: a
//! major changes when an older reader would misread a file, and readers refuse newer majors;
//! a minor adds what older readers may ignore; `format-spec/container.md` §8).
//!
//! ## Cargo features
//!
//! * `remote` (default): reading containers and datasets over HTTP(S) range requests and
//!   from S3 (`Terrain::open("https://…")`).
//! * `testing`: fmrh's own tests, benches and fuzz targets: it makes the crate's internal
//!   rooms public (hidden from these docs) and adds a simulated crashing disk. No stability
//!   is promised for anything it exposes.

/// Declares the crate's rooms: crate-private, so that the public API is only what this file
/// exports; with the `testing` feature (fmrh's own tests, benches and fuzz targets) they are
/// public and hidden from the docs, so those can test each room directly. Nothing outside
/// fmrh may rely on them.
macro_rules! rooms {
    ($($name:ident),* $(,)?) => {$(
        #[cfg(feature = "testing")]
        #[doc(hidden)]
        pub mod $name;
        #[cfg(not(feature = "testing"))]
        pub(crate) mod $name;
    )*};
}

mod cli;
rooms!(
    codec,
    crs,
    curve,
    dataset,
    error,
    export,
    geoid,
    format,
    globe,
    heightfield,
    http,
    ingest,
    mesh,
    model,
    progress,
    pyramid,
    render,
    scene,
    store,
);

mod terrain;

pub use error::{Error, Result};
pub use heightfield::Heightfield;
pub use scene::{Camera, SceneOptions};
pub use terrain::distributed;
pub use terrain::{
    add_tile, build, build_dataset, create, create_with_progress, load, Block, CreateOptions,
    DatasetBuildOptions, Edit, Flight, FlightFrame, Info, Scene, Terrain, Verification,
};

/// glam, whose `DVec3` places cameras ([`Camera`]): re-exported so that a caller needs no
/// second dependency, and gets the version fmrh was built with.
pub use glam;

/// The values the door's types take and give: options, rectangles, georeferences, reports.
///
/// ```
/// use fmrh::types::{Kind, SampleRect};
///
/// # fn main() -> fmrh::Result<()> {
/// # let dir = tempfile::tempdir().unwrap();
/// # let path = dir.path().join("t.fmrh");
/// # fmrh::create(&path, fmrh::Heightfield::from_fn(90, 60, |x, _| x as f32)?, &Default::default())?;
/// let terrain = fmrh::Terrain::open(&path)?;
/// let info = terrain.info()?;
/// assert_eq!(info.kind, Kind::Container);
/// let all = SampleRect { col0: 0, row0: 0, col1: info.width - 1, row1: info.height - 1 };
/// assert_eq!(all.samples(), 90 * 60);
/// # Ok(()) }
/// ```
pub mod types {
    pub use crate::dataset::{
        BuiltTile, DatasetCommit, DatasetReport, DatasetSummary, SeamPolicy, TileCommit, TileReport,
    };
    pub use crate::error::Invariant;
    pub use crate::geoid::VerticalDatum;
    pub use crate::heightfield::{Georeference, Metadata};
    pub use crate::ingest::{ColorEncoding, Format, IngestLimits, IngestOptions};
    pub use crate::model::{SampleRect, ThinByArea, Thresholds};
    pub use crate::progress::{Progress, Silent, Unit};
    pub use crate::scene::{Handedness, Mode, NeighbourLevels, SceneStats};
    pub use crate::store::{CheckReport, CheckStatus, CommitSummary, VerifyMode, VerifyReport};
    pub use crate::terrain::{
        Approximation, BlockKey, Committed, Created, ErrorLevel, Kind, Strided, TileAdded,
    };
}

/// The `fmrh` command line, run on this process's arguments: the binary's `main` is this one
/// call. Not an API: the command line is the interface it offers.
#[doc(hidden)]
pub fn run_cli() -> std::process::ExitCode {
    cli::main()
}

/// The low level, for format tools: a container's records, nodes and blocks, its error levels
/// as clusters, Hilbert range scans over them, payloads as stored, transactions, and the
/// validator. Nothing here is needed to draw terrain (the crate root is); everything here is
/// the format of `format-spec/container.md`, read and written exactly.
///
/// ```
/// use fmrh::raw::{HilbertKey, Store};
///
/// # fn main() -> fmrh::Result<()> {
/// # let dir = tempfile::tempdir().unwrap();
/// # let path = dir.path().join("t.fmrh");
/// # let dem = fmrh::Heightfield::from_fn(257, 257, |x, y| ((x * 7 + y * 3) % 50) as f32)?;
/// # fmrh::create(&path, dem, &fmrh::CreateOptions { block_size: 33, ..Default::default() })?;
/// let store = Store::open(&path)?;
/// // The lossless level (clusters ascend by threshold: the first, at 0): its nodes whose
/// // footprints meet the first quarter of the finest Hilbert curve, in one seek and one
/// // contiguous run.
/// let lossless = 0;
/// assert_eq!(store.clusters()[lossless].threshold, 0.0);
/// let finest = store.domain().finest_level();
/// let quarter = HilbertKey::span(finest, 1);
/// for entry in store.scan_hilbert(lossless, 0..=quarter - 1)? {
///     let node = store.node_of(lossless, &entry?)?;
///     assert!(node.key.0 < quarter && node.monotone_error == 0.0);
/// }
/// # Ok(()) }
/// ```
pub mod raw {
    pub use crate::curve::{hilbert_decode, hilbert_encode, HilbertKey, HilbertType};
    pub use crate::format::{
        ClusterInfo, DatasetHeader, FreePage, PayloadRef, ScanEntry, StoredBlock, StoredNode,
        FORMAT_MAJOR, FORMAT_MINOR, MAX_TXN_ID,
    };
    pub use crate::model::Domain;
    pub use crate::store::verify::verify;
    pub use crate::store::{
        compact, AnySource, Block, Bytes, Children, CodeScan, CommitSummary, CompactOptions,
        Compacted, Container, FileSource, Grid, HeldGrid, HilbertScan, Layout, LoadedBlock,
        MmapSource, ReadStats, Snapshot, Source, StateInfo, Store, Wanted, WriteTxn,
        ANCESTOR_CACHE_BYTES,
    };
}

/// README.md's Rust example, compiled with the doctests (it is `no_run`: it opens the file the
/// README's first command builds).
#[cfg(doctest)]
#[doc = include_str!("../README.md")]
pub struct ReadmeDoctests;
