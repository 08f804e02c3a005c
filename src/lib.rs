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
//! [`ingest::load`] reads a heightfield from any supported format. [`model::Model::build`]
//! turns it into the FMRH and its clusters, [`store`] keeps them in one checksummed file, and
//! [`scene`] answers a camera and a tolerance in pixels with exactly the blocks the view needs,
//! frame after frame. The curves in [`curve`] know nothing of terrain.

pub mod curve;
pub mod error;
pub mod format;
pub mod heightfield;
pub mod ingest;
pub mod model;
pub mod scene;
pub mod store;

pub use error::{Error, Result};
pub use heightfield::Heightfield;
pub use model::{BuildOptions, Model, Thresholds};
pub use store::Store;
