//! Making containers: the bulk writer of fresh files, and the table writer it shares with
//! transactions.
//!
//! * `atomic`: a file appears complete or not at all (temporary file, fsync, rename).
//! * `bulk`: a whole model, front to back ([`write_to`]).
//! * `tables`: a state's tables and blobs into any page sink, and the payload encoders.
//!
//! The door's `fmrh::create` is the one call an application needs: heightfield in,
//! container out.

mod atomic;
mod bulk;
pub(crate) mod tables;

use std::fmt;
use std::path::Path;
use std::sync::Arc;

use serde::Serialize;

pub use atomic::{
    remove_temporary_files, write_atomically, write_atomically_checked, write_dir_atomically,
};
#[cfg(any(test, feature = "testing"))]
pub use bulk::write_to;

use crate::error::Result;
use crate::format::DEFAULT_PAGE_SIZE;
use crate::heightfield::Metadata;
use crate::model::Model;

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
    /// Pages of the top of the tree (format 6.2): a copy of the coarsest levels' node
    /// records, written with paged tables.
    pub top: u64,
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
    write_file_checked(model, metadata, path, options, overwrite, |_| Ok(()))
}

/// [`write_file`], with `check` run on the complete temporary file before it takes `path`'s
/// name ([`write_atomically_checked`]).
pub fn write_file_checked(
    model: &Model,
    metadata: &Metadata,
    path: &Path,
    options: &WriteOptions,
    overwrite: bool,
    check: impl FnOnce(&Path) -> Result<()>,
) -> Result<WriteSummary> {
    write_atomically_checked(
        path,
        overwrite,
        |w| bulk::write_named(model, metadata, options, w, path),
        check,
    )
}

