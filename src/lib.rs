//! # fmrh — an embedded storage engine for multiresolution terrain
//!
//! fmrh keeps a digital elevation model (a grid of heights) so that a terrain application can
//! ask, every frame, for exactly the blocks a view needs, each exact to a known error.
//!
//! ## The data structure, before the API
//!
//! **Blocks.** The grid is cut into square blocks of `b = 2^k + 1` samples a side (65 by
//! default). Neighbouring blocks share their edge row and column. The domain is squared up to
//! `2^L · (b - 1) + 1` samples, and the padding is void and never reported as terrain.
//!
//! **FMRH** (seed 000 §3). A quadtree over the blocks. Level `L` holds the blocks themselves, at
//! full resolution. Each level up halves the resolution, and the root covers everything with
//! one `b × b` grid. Every node carries its *measured static error*: the largest vertical
//! distance between a real sample in its footprint and the surface its grid draws (cells split
//! NW–SE). It also carries the *monotone error* `e*`, the largest error in its subtree, which
//! never grows from parent to child. The tree is cut short where `e*` is already within the
//! finest threshold, so flat ground costs one node.
//!
//! **Clusters** (seed 000 §3.2, corrected). For a threshold δ, the cluster `C(δ)` is the set of
//! nodes with `e* <= δ` whose parent has `e* > δ`. It covers the terrain exactly once and every
//! node in it is exact to δ. A ladder of thresholds gives a ladder of clusters, from one coarse
//! root down to the lossless blocks.
//!
//! **Order** (seed 000 §4). Inside a cluster the nodes are sorted by [`curve::HilbertKey`]: the
//! position of their first finest block on the Hilbert curve. A square window of the terrain
//! is then a few contiguous runs of a cluster, which a store scans instead of walking the tree.
//!
//! ## The API
//!
//! Three calls cover a terrain application's life, all at the crate root:
//!
//! * [`create`] turns a [`Heightfield`] into a container file, atomically;
//! * [`Store::open`] opens a file for reading: nodes, blocks, range scans;
//! * [`Container::open`] opens it for writing: [`Container::read`] takes a snapshot that
//!   keeps its state while [`Container::begin_write`]'s transaction replaces samples and
//!   commits, all at once or not at all, and crash-safe.
//!
//! A [`scene::Terrain`] over a store answers a camera and a tolerance in pixels with the
//! blocks the view needs; a [`scene::Scheduler`] does it frame after frame.
//!
//! ```
//! use fmrh::scene::{Camera, SceneOptions, Terrain};
//! use glam::DVec3;
//!
//! # fn main() -> fmrh::Result<()> {
//! # let dir = tempfile::tempdir().unwrap();
//! let path = dir.path().join("hills.fmrh");
//! // Any DEM: `fmrh::ingest::load` reads GeoTIFF, SRTM, PNG, ASCII grids and more.
//! let hills = fmrh::Heightfield::from_fn(257, 257, |x, y| {
//!     let (x, y) = (x as f32 * 0.05, y as f32 * 0.07);
//!     40.0 * x.sin() * y.cos() + 3.0 * (5.0 * x).sin()
//! })?;
//! fmrh::create(&path, hills, &fmrh::CreateOptions::default())?;
//!
//! // Read: the blocks a camera needs at 1 pixel of screen-space error, and their samples.
//! let store = fmrh::Store::open(&path)?;
//! let camera = Camera::looking_at(DVec3::new(-50.0, -50.0, 120.0), DVec3::new(128.0, 128.0, 0.0));
//! let scene = Terrain::new(&store)?.scene(&camera, &SceneOptions::new(1.0))?;
//! assert!(!scene.blocks.is_empty() && scene.stats.max_screen_error <= 1.0);
//! for block in &scene.blocks {
//!     let bytes = store.payload(block.payload)?; // CRC-checked
//!     assert_eq!(bytes.len() as u32, block.payload.len);
//! }
//!
//! // Write: dig a pit; a snapshot taken before keeps seeing the hills.
//! let container = fmrh::Container::open(&path)?;
//! let before = container.read()?;
//! let mut txn = container.begin_write()?;
//! txn.replace_region(100, 100, &fmrh::Heightfield::from_fn(20, 20, |_, _| -10.0)?)?;
//! let summary = txn.commit()?;
//! assert!(summary.blocks >= 1 && before.txn_id() < summary.txn_id);
//! # drop(before);
//! container.close()?;
//! # Ok(()) }
//! ```
//!
//! Underneath: [`ingest`] reads DEMs, [`export`] writes them as GeoTIFF and meshes as glTF,
//! [`model`] builds the FMRH and its clusters, [`mod@format`] is every byte of the file
//! format, [`store`] reads, writes and verifies files, [`scene`] selects blocks for cameras,
//! [`mesh`] turns them into crack-free triangles, [`render`] draws them, and [`curve`] knows
//! Hilbert and Morton keys and nothing of terrain. Errors say whose
//! fault they are ([`Error`]).

pub mod codec;
pub mod crs;
pub mod curve;
pub mod dataset;
pub mod error;
pub mod export;
pub mod format;
pub mod globe;
pub mod heightfield;
pub mod ingest;
pub mod mesh;
pub mod model;
pub mod progress;
pub mod render;
pub mod scene;
pub mod store;

pub use error::{Error, Result};
pub use format::Invariant;
pub use heightfield::Heightfield;
pub use model::{BuildOptions, Model, Thresholds};
pub use store::{
    create, verify, CommitSummary, Container, CreateOptions, Snapshot, Store, VerifyMode,
    VerifyReport, WriteTxn,
};
