//! Scenes: a camera and a pixel tolerance in, exactly the blocks the view needs out.
//!
//! Read in order: [`camera`] (the view, the frustum, pixels per metre), [`ranges`] (a region
//! of the terrain as maximal aligned quadrants, then Hilbert key ranges), `result` (what a
//! scene asks and answers), `terrain` (boxes, regions, and the dispatch to a mode), the modes
//! `uniform` and `view_dependent` (the cuts, found through the clusters, over the shared
//! `search` state), `stitch` (neighbour levels across block edges), [`load`] (a scene's
//! payloads read in coalesced runs and decoded), [`mod@reconstruct`] (the
//! surface a scene draws, sampled back at full resolution), [`schedule`] (frames: what to
//! load, keep and evict as the camera moves, with prefetch), [`path`] (camera paths), and
//! [`baseline`] (naive answers kept as yardsticks). A new mode is a new file with an `impl`
//! block on `search::Search`, a [`Mode`] variant, and one arm in [`Terrain::scene`].
//!
//! A scene is always a *cover*: every point of its region lies in exactly one block (blocks
//! share edges, nothing more). In uniform mode every block is within one static bound in
//! metres; in view-dependent mode every block is within the tolerance in pixels where it is
//! seen, and no block could be replaced by its parent without breaking that.

#[cfg(any(test, feature = "testing"))]
pub mod baseline;
pub mod camera;
pub mod layers;
pub mod load;
pub mod path;
pub mod ranges;
pub mod reconstruct;
mod result;
pub mod schedule;
mod search;
mod select;
mod stitch;
pub mod surface;
mod terrain;
pub(crate) mod worker;
mod uniform;
mod view_dependent;

#[cfg(any(test, feature = "testing"))]
pub use crate::format::PayloadRef;
pub use camera::{Aabb, Camera, GlobeFrame, Handedness, TerrainFrame, View, WorldFrame};
#[cfg(any(test, feature = "testing"))]
pub use camera::Coverage;
pub use layers::{LayerBlock, Layers};
#[cfg(any(test, feature = "testing"))]
pub use layers::{LayeredScene, LonLatRect};
pub use load::{load_blocks, LoadedBlock, PAYLOAD_GAP};
#[cfg(any(test, feature = "testing"))]
pub use load::{load_blocks_reusing, HeldGrid};
pub use reconstruct::{reconstruct, Reconstruction};
pub use result::{Mode, NeighbourLevels, Scene, SceneBlock, SceneOptions, SceneStats, DEFAULT_GAP};
pub use schedule::{FrameStats, ScheduleOptions, Scheduler, Selection};
#[cfg(any(test, feature = "testing"))]
pub use schedule::{BlockId, Frame};
pub use terrain::Terrain;
