//! Making containers: the bulk writer of fresh files, and the table writer it shares with
//! transactions.
//!
//! * `atomic`: a file appears complete or not at all (temporary file, fsync, rename).
//! * `bulk`: a whole model, front to back ([`write_to`]).
//! * `tables`: a state's tables and blobs into any page sink, and the payload encoders.
//!
//! [`create`] is the one call an application needs: heightfield in, container out.

mod atomic;
mod bulk;
pub(crate) mod tables;

use std::fmt;
use std::path::Path;
use std::sync::Arc;

use serde::Serialize;

pub use atomic::{remove_temporary_files, write_atomically};
pub use bulk::write_to;

use crate::error::Result;
use crate::format::DEFAULT_PAGE_SIZE;
use crate::heightfield::{Heightfield, Metadata};
use crate::model::{BuildOptions, Model, Thresholds, DEFAULT_BLOCK_SIZE};

pub use crate::progress::{Progress, Silent, Unit};

/// How to write a container.
#[derive(Clone)]
pub struct WriteOptions {
    /// Bytes per page: a power of two in 1024..=65536.
    pub page_size: u32,
    /// Told of the progress of long phases.
    pub progress: Arc<dyn Progress>,
    /// The most stored bytes the metadata may take as one compressed bundle (format §6.7);
    /// larger metadata stays in file pages. 0 never bundles.
    pub bundle_limit: u64,
    /// Store every payload's codes raw (format §7, encoding 0): a larger file whose reads
    /// decode nothing, what a benchmark compares the codec's cost with (format 1 stored raw
    /// `f32`). Commits code their payloads as usual. `fmrh build` never sets it.
    pub raw_payloads: bool,
    /// Code a physical block (format 4) or a node's grid (format 5) against its parent's
    /// grid where that is smaller (format §7, encodings 5 to 8): the samples the parent holds
    /// are then stored once. Off, every payload is coded alone (as before format 4), so
    /// drawing one needs no other payload: what the bytes-per-scene benchmarks compare with.
    /// Commits code the payloads they rewrite as a default build does.
    pub against_parents: bool,
}

impl Default for WriteOptions {
    fn default() -> Self {
        WriteOptions {
            page_size: DEFAULT_PAGE_SIZE,
            progress: Arc::new(Silent),
            bundle_limit: crate::format::bundle::DEFAULT_BUNDLE_LIMIT,
            raw_payloads: false,
            against_parents: true,
        }
    }
}

impl fmt::Debug for WriteOptions {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.debug_struct("WriteOptions")
            .field("page_size", &self.page_size)
            .field("bundle_limit", &self.bundle_limit)
            .field("raw_payloads", &self.raw_payloads)
            .field("against_parents", &self.against_parents)
            .finish_non_exhaustive()
    }
}

/// Bytes of each section of a written file (pages, except payloads: their bytes).
#[derive(Clone, Debug, Default, PartialEq, Eq, Serialize)]
pub struct SectionBytes {
    /// The two commit slots.
    pub commit_slots: u64,
    /// Dataset header pages.
    pub dataset_header: u64,
    /// Physical block payload bytes.
    pub blocks: u64,
    /// Coarse grid payload bytes.
    pub grids: u64,
    /// Alignment and page-tail zero bytes in the payload area.
    pub payload_padding: u64,
    /// Node table pages.
    pub node_table: u64,
    /// Block table pages.
    pub block_table: u64,
    /// Cluster index pages, all clusters.
    pub cluster_index: u64,
    /// Adjacency table pages (all clusters).
    pub adjacency: u64,
    /// Cluster directory pages.
    pub cluster_directory: u64,
    /// Stored bytes of the metadata bundle (format §6.7): the header, tables and directory,
    /// compressed, when they are small; the page counts above are then 0.
    pub bundle: u64,
}

/// What a write produced.
#[derive(Clone, Debug, PartialEq, Eq, Serialize)]
pub struct WriteSummary {
    /// File length in bytes.
    pub file_length: u64,
    /// Bytes per page.
    pub page_size: u32,
    /// Bytes per section.
    pub sections: SectionBytes,
}

/// Writes `model` (of a heightfield with `metadata`) to `path` atomically: the file appears
/// complete or not at all. Refuses to replace an existing `path` unless `overwrite`.
pub fn write_file(
    model: &Model,
    metadata: &Metadata,
    path: &Path,
    options: &WriteOptions,
    overwrite: bool,
) -> Result<WriteSummary> {
    write_atomically(path, overwrite, |w| {
        bulk::write_named(model, metadata, options, w, path)
    })
}

/// How [`create`] builds and writes a container.
#[derive(Clone, Debug)]
pub struct CreateOptions {
    /// Samples along a block side: `2^k + 1`, 9 to 1025.
    pub block_size: u32,
    /// Cluster thresholds: the default √2 ladder, or given ones.
    pub thresholds: Thresholds,
    /// Store heights to this step, within half of it (see [`crate::model::precision`]);
    /// `None` keeps them bit for bit.
    pub precision: Option<crate::model::Precision>,
    /// Thin nodes by area (format 6): by default where the heightfield is a
    /// longitude-latitude grid ([`crate::model::thinning`]).
    pub thin: crate::model::ThinByArea,
    /// Page size and progress.
    pub write: WriteOptions,
    /// Replace an existing file (atomically) instead of refusing.
    pub overwrite: bool,
}

impl Default for CreateOptions {
    fn default() -> Self {
        CreateOptions {
            block_size: DEFAULT_BLOCK_SIZE,
            thresholds: Thresholds::Ladder,
            precision: None,
            thin: crate::model::ThinByArea::Auto,
            write: WriteOptions::default(),
            overwrite: false,
        }
    }
}

/// Creates the container at `path` from `heightfield`: cuts it into blocks, measures every
/// node, builds the clusters, and writes the file atomically (it appears complete or not at
/// all). This is [`Model::build`] followed by [`write_file`].
///
/// ```
/// # fn main() -> fmrh::Result<()> {
/// # let dir = tempfile::tempdir().unwrap();
/// let path = dir.path().join("dome.fmrh");
/// let dome = fmrh::Heightfield::from_fn(200, 150, |x, y| {
///     let (dx, dy) = (x as f32 - 100.0, y as f32 - 75.0);
///     (4000.0 - dx * dx - dy * dy).max(0.0) * 0.05
/// })?;
/// let summary = fmrh::create(&path, dome, &fmrh::CreateOptions::default())?;
/// assert_eq!(summary.file_length, std::fs::metadata(&path).unwrap().len());
/// # Ok(()) }
/// ```
pub fn create(
    path: &Path,
    heightfield: Heightfield,
    options: &CreateOptions,
) -> Result<WriteSummary> {
    let metadata = heightfield.metadata.clone();
    let model = Model::build(
        heightfield,
        &BuildOptions {
            block_size: options.block_size,
            thresholds: options.thresholds.clone(),
            precision: options.precision,
            thin: options.thin,
        },
    )?;
    write_file(&model, &metadata, path, &options.write, options.overwrite)
}
