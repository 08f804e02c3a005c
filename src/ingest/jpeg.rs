//! Baseline JPEG heightfields (placeholder until the decoder lands).

use std::path::Path;

use super::IngestOptions;
use crate::error::{Error, Result};
use crate::heightfield::Heightfield;

/// Reads a JPEG heightfield.
pub fn read(path: &Path, _options: &IngestOptions) -> Result<Heightfield> {
    Err(Error::unsupported(path, "JPEG input is not readable yet"))
}
