//! Datasets of many files (issue 16): a directory of ordinary containers, one per tile, and a
//! manifest that places them in one sample grid and makes a change to several of them
//! atomic. The design, with the commit protocol's correctness argument, is
//! `docs/datasets-design.md`; the bytes are `format-spec/dataset.md`.
//!
//! Read in order: [`placement`] (where the tiles lie, which edges they share), [`seams`]
//! (whether neighbours agree on a shared edge, and how a policy settles them), [`manifest`]
//! (the manifest's commit slots, head and tile pages, read and written), [`reader`] (a
//! dataset opened: its tiles, each container at its pinned state, windows across them),
//! [`mod@scene`] (scenes across tiles), [`fly`] (frames across tiles), [`adjacency`] (the
//! adjacent-cluster tables), [`mod@build`] (tiles in, a dataset out, one tile in memory at a
//! time), [`mod@add`] (one more tile, or a whole tile replaced), [`commit`] (a change to
//! several tiles, atomic across the files), [`mod@compact`] (every tile rewritten fresh, one
//! commit) and [`mod@verify`] (the validator).

pub mod add;
pub mod adjacency;
pub mod build;
pub mod commit;
pub mod compact;
pub mod fly;
pub mod manifest;
pub mod placement;
pub mod plan;
pub mod reader;
pub mod scene;
pub mod seams;
pub mod verify;

pub use add::{add, replace_tile};
pub use build::{build, BuiltTile, DatasetSummary, TileInput};
pub use plan::DatasetOptions;
pub use commit::{recover, replace, DatasetCommit, Dir};
pub use compact::compact;
pub use commit::TileCommit;
#[cfg(any(test, feature = "testing"))]
pub use commit::{DatasetRecovery, Files};
pub use fly::DatasetScheduler;
#[cfg(any(test, feature = "testing"))]
pub use fly::DatasetFrame;
pub use reader::{is_dataset, Dataset};
#[cfg(any(test, feature = "testing"))]
pub use reader::{Tile, OPEN_TILES};
pub use scene::{in_tile, DatasetBlock, DatasetScene, TilePart};
pub use seams::SeamPolicy;
pub use verify::{verify, DatasetReport, TileReport};
