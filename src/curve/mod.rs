//! Space-filling curves over the quadtree: [`HilbertKey`] orders the nodes of a cluster,
//! [`MortonKey`] is seed 001's non-pointer index, and [`qtm`] addresses the whole globe by
//! seed 003's octahedral triangles. This module knows nothing of heights, files or cameras:
//! only cell coordinates (and, for the QTM, longitudes and latitudes).
//!
//! Coordinates follow the raster: `x` is the column (growing east), `y` is the row (growing
//! south, row 0 at the north edge). [`MortonKey`] converts to seed 001's south-up frame itself.

pub mod hilbert;
#[cfg(any(test, feature = "testing"))]
pub mod morton;
#[cfg(any(test, feature = "testing"))]
pub mod qtm;

pub use hilbert::{hilbert_decode, hilbert_encode, HilbertKey, HilbertType};
#[cfg(any(test, feature = "testing"))]
pub use morton::{MortonBounds, MortonKey};
#[cfg(any(test, feature = "testing"))]
pub use qtm::{QtmCell, QtmCode};
