//! Writing a state's tables and blobs, and encoding a model's payloads: shared by the bulk
//! writer (a fresh file, pages in order) and by commits (pages wherever the allocator finds
//! room), which differ only in their [`PageSink`].
//!
//! The bytes are [`crate::format`]'s: this file turns a [`Model`] into records and payloads
//! and hands them to the sink.

use rayon::prelude::*;

use zerocopy::{FromBytes, IntoBytes};

use crate::error::{Error, Result};
use crate::format::bundle;
use crate::format::directory::{self, ClusterInfo, EdgeRange};
use crate::format::payload::{self, ParentGrid, PayloadRef, Placement};
use crate::format::tables;
use crate::format::{
    tag, AdjacencyEntry, BlobRef, BlockRecord, IndexEntry, NodeRecord, ScanEntry, StoredBlock,
    StoredNode, TreeRef, TreeSpec,
};
use crate::model::{cluster, Model, NodeGrid, Precision, SampleRect, NO_PARENT};


/// Payloads of at most this many bytes are stored once however many records have them (by
/// the bulk writer and by commits). Longer identical payloads are rare; keeping every
/// payload's bytes to find them would cost the whole file's size in memory.
pub(crate) const MAX_SHARED_PAYLOAD: usize = 256;

/// Where the pages of a state's tables and blobs go.
pub(crate) trait PageSink {
    /// Writes `records` (`spec.record_size` bytes each) as a tree of `spec.tag` pages.
    fn tree(&mut self, records: &[u8], spec: TreeSpec) -> Result<TreeRef>;
    /// Writes `content` as a blob of consecutive `tag` pages.
    fn blob(&mut self, content: &[u8], tag: [u8; 4]) -> Result<BlobRef>;
}

/// A [`PageSink`] that builds pages in memory at bundle page numbers, for a metadata
/// bundle (format §6.7).
pub(crate) struct BundleSink {
    page_size: u32,
    txn: u64,
    pages: Vec<Vec<u8>>,
}

impl BundleSink {
    fn next_page(&self) -> u64 {
        bundle::BUNDLE_FIRST_PAGE + self.pages.len() as u64
    }
}

impl PageSink for BundleSink {
    fn tree(&mut self, records: &[u8], spec: TreeSpec) -> Result<TreeRef> {
        let (first, txn, p) = (self.next_page(), self.txn, self.page_size);
        let pages = &mut self.pages;
        crate::format::tree::build::<Error>(records, spec, p, first, txn, &mut |page| {
            pages.push(page);
            Ok(())
        })
    }

    fn blob(&mut self, content: &[u8], tag: [u8; 4]) -> Result<BlobRef> {
        let (blob, pages) = crate::format::blob::encode_blob(
            content,
            tag,
            self.next_page(),
            self.txn,
            self.page_size,
        );
        self.pages.extend(pages);
        Ok(blob)
    }
}

/// A state's dataset header and tables built as a metadata bundle.
pub(crate) struct Bundled {
    /// The stored (compressed) bytes, to be written anywhere past the slots.
    pub stored: Vec<u8>,
    /// The record's reference to them, at offset 0 until they are placed ([`Bundled::at`]).
    pub reference: bundle::BundleRef,
    pub dataset_header: BlobRef,
    pub roots: TableRoots,
}

impl Bundled {
    fn new(
        (stored, head_len): (Vec<u8>, u32),
        pages: usize,
        dataset_header: BlobRef,
        roots: TableRoots,
    ) -> Self {
        use zerocopy::byteorder::little_endian::{U32, U64};
        let reference = bundle::BundleRef {
            offset: U64::new(0),
            // `stored` is at most the limit, and `pages` at most 16 MiB of pages.
            stored_len: U32::new(u32::try_from(stored.len()).unwrap_or(u32::MAX)),
            // The CRC covers the frame table; each frame's page carries its own.
            crc: U32::new(bundle::stored_crc(
                &stored[..(pages * bundle::FRAME_ENTRY_LEN).min(stored.len())],
            )),
            pages: U32::new(u32::try_from(pages).unwrap_or(u32::MAX)),
            head_len: U32::new(head_len),
        };
        Bundled {
            stored,
            reference,
            dataset_header,
            roots,
        }
    }
}

/// `reference` with its stored bytes placed at `offset`.
pub(crate) fn bundle_at(reference: bundle::BundleRef, offset: u64) -> bundle::BundleRef {
    bundle::BundleRef {
        offset: zerocopy::byteorder::little_endian::U64::new(offset),
        ..reference
    }
}

/// zstd levels up to this one are fast enough not to need a first pass at level 1.
const FAST_LEVEL: i32 = 3;

/// Builds the dataset header `header` and the tables of `model` as a metadata bundle written
/// by transaction `txn`, compressed at zstd `level`, if its stored form is at most `limit` bytes (and it decompresses
/// to at most [`bundle::MAX_BUNDLE_BYTES`]); `None` when the state should keep its pages in
/// the file. A fast first compression rules out metadata far over the limit without paying
/// for the strong one.
pub(crate) fn bundle_metadata(
    model: &Model,
    refs: &PayloadRefs,
    header: &[u8],
    page_size: u32,
    txn: u64,
    limit: u64,
    level: i32,
) -> Result<Option<Bundled>> {
    if limit == 0 {
        return Ok(None);
    }
    let mut sink = BundleSink {
        page_size,
        txn,
        pages: Vec::new(),
    };
    let dataset_header = sink.blob(header, tag::DATASET_HEADER)?;
    let roots = write_tables(model, refs, &mut sink)?;
    let raw = sink.pages.len() as u64 * u64::from(page_size);
    if raw > bundle::MAX_BUNDLE_BYTES {
        return Ok(None);
    }
    let io = |e: std::io::Error| Error::Internal(format!("compressing the metadata bundle: {e}"));
    // zstd's strongest levels keep 10-25 % less than level 1 on metadata pages: a fast
    // pass first rules out metadata far over the limit.
    if level > FAST_LEVEL
        && bundle::compress(&sink.pages, 1).map_err(io)?.len() as u64 > limit.saturating_mul(2)
    {
        return Ok(None);
    }
    // The pages opening reads (the dataset header and the cluster directory) are stored
    // first, so that opening reads them with the frame table in one call (format §6.7).
    let blob_pages = |b: &BlobRef| {
        let first = b.first_page.get().saturating_sub(bundle::BUNDLE_FIRST_PAGE);
        let n = crate::format::blob::blob_pages(b.length.get(), page_size);
        (first..first + n).filter_map(|i| usize::try_from(i).ok())
    };
    let head: Vec<usize> = blob_pages(&dataset_header)
        .chain(blob_pages(&roots.cluster_directory))
        .collect();
    let stored = bundle::compress_framed(&sink.pages, &head, level).map_err(io)?;
    if stored.0.len() as u64 > limit {
        return Ok(None);
    }
    Ok(Some(Bundled::new(
        stored,
        sink.pages.len(),
        dataset_header,
        roots,
    )))
}

/// A physical block's shape: the samples it holds and how many are void.
pub(crate) struct BlockShape {
    pub rect: SampleRect,
    pub void_count: u32,
}

impl BlockShape {
    /// Samples along a row and down a column (each at most a block side).
    pub fn size(&self) -> (u32, u32) {
        let side = |a: u64, b: u64| u32::try_from(b - a + 1).unwrap_or(u32::MAX);
        (
            side(self.rect.col0, self.rect.col1),
            side(self.rect.row0, self.rect.row1),
        )
    }

    /// Bytes of the block's layout before coding.
    pub fn raw_len(&self) -> u64 {
        let (w, h) = self.size();
        payload::block_len(w, h, self.void_count)
    }
}

/// Where each payload of a state lies, per node (its grid; unused at the finest level) and
/// per physical block (row-major), with what the tables need to describe them.
pub(crate) struct PayloadRefs {
    pub grid: Vec<PayloadRef>,
    pub block: Vec<PayloadRef>,
    /// Per block: the node whose grid it is coded against (format 4), if any.
    pub against: Vec<Option<u32>>,
    /// Per node: whether its grid is coded against its parent's (format 5).
    pub grid_against: Vec<bool>,
    /// Per node: whether its grid's void bitmap lies raw, as before format 5 (a grid a
    /// commit keeps from an older state); grids written now put it behind a void flag.
    pub grid_raw_bitmap: Vec<bool>,
    pub grid_voids: Vec<bool>,
    pub shapes: Vec<BlockShape>,
}

/// The roots [`write_tables`] returns.
pub(crate) struct TableRoots {
    pub node_table: TreeRef,
    pub block_table: TreeRef,
    pub adjacency: TreeRef,
    pub cluster_directory: BlobRef,
}

/// Writes the node table, block table, every cluster's index, the adjacency table and the
/// cluster directory of `model`, in that order, with payloads where `refs` says.
pub(crate) fn write_tables(
    model: &Model,
    refs: &PayloadRefs,
    sink: &mut dyn PageSink,
) -> Result<TableRoots> {
    let records = TableRecords::of(model, refs);
    let node_table = sink.tree(&records.nodes, tables::NODES)?;
    let block_table = sink.tree(&records.blocks, tables::BLOCKS)?;
    let (clusters, adjacency) = records.write_indexes(sink)?;
    let cluster_directory = sink.blob(&directory::encode(&clusters), tag::CLUSTER_DIRECTORY)?;
    Ok(TableRoots {
        node_table,
        block_table,
        adjacency,
        cluster_directory,
    })
}

/// One cluster's records: its threshold and largest error, its index's entries, and its
/// four edge lists' runs in the adjacency table.
pub(crate) struct ClusterRecords {
    threshold: f64,
    max_error: f64,
    index: Vec<u8>,
    edges: [EdgeRange; 4],
}

/// The records of a state's tables, before they are written as pages.
pub(crate) struct TableRecords {
    /// The node table's records, in the tree's pre-order.
    pub nodes: Vec<u8>,
    /// The block table's records, row-major.
    pub blocks: Vec<u8>,
    pub clusters: Vec<ClusterRecords>,
    /// Every cluster's edge lists, back to back.
    pub adjacency: Vec<u8>,
}

impl TableRecords {
    /// The records of `model`'s tables, with payloads where `refs` says.
    pub fn of(model: &Model, refs: &PayloadRefs) -> TableRecords {
        let domain = *model.domain();
        let tree = model.tree();
        let finest = domain.finest_level();
        let (cols, _) = domain.nodes_across(finest);

        let mut nodes = Vec::with_capacity(tree.nodes().len() * tables::NODES.record_size);
        for (i, n) in tree.nodes().iter().enumerate() {
            let at_finest = n.level == finest;
            let stored = StoredNode {
                key: n.key,
                level: n.level,
                x: n.x,
                y: n.y,
                child_mask: n.child_mask,
                parent: Some(n.parent).filter(|&p| p != NO_PARENT),
                subtree_len: n.subtree_len,
                static_error: n.static_error,
                monotone_error: n.monotone_error,
                min_height: n.min_height,
                max_height: n.max_height,
                valid_samples: n.valid_samples,
                payload: if at_finest {
                    refs.block[block_index(n.x, n.y, cols)]
                } else {
                    refs.grid[i]
                },
                grid_has_voids: !at_finest && refs.grid_voids[i],
                grid_against_parent: !at_finest && refs.grid_against[i],
                grid_bitmap_flagged: !at_finest
                    && refs.grid_voids[i]
                    && !refs.grid_raw_bitmap[i],
                grid_thin: if at_finest { 0 } else { n.thin },
            };
            nodes.extend_from_slice(NodeRecord::encode(&stored).as_bytes());
        }

        let mut blocks = Vec::with_capacity(refs.shapes.len() * tables::BLOCKS.record_size);
        for ((s, &payload), &against) in refs.shapes.iter().zip(&refs.block).zip(&refs.against) {
            let (width, height) = s.size();
            let block = StoredBlock {
                payload,
                width,
                height,
                void_count: s.void_count,
                against,
            };
            blocks.extend_from_slice(BlockRecord::encode(&block).as_bytes());
        }

        // Clusters: one index each; their edge lists go into the one adjacency table.
        let mut clusters = Vec::with_capacity(model.clusters().len());
        let mut adjacency: Vec<u8> = Vec::new();
        let adjacency_len = |bytes: &Vec<u8>| (bytes.len() / tables::ADJACENCY.record_size) as u64;
        for c in model.clusters() {
            let mut index = Vec::with_capacity(c.nodes.len() * tables::INDEX.record_size);
            for &i in &c.nodes {
                let n = tree.node(i);
                let e = ScanEntry {
                    key: n.key,
                    level: n.level,
                    node: i,
                };
                index.extend_from_slice(IndexEntry::encode(&e).as_bytes());
            }
            let mut edges = [EdgeRange::default(); 4];
            for (range, list) in edges.iter_mut().zip(cluster::edge_nodes(tree, &c.nodes)) {
                let first = adjacency_len(&adjacency);
                for i in list {
                    let e = AdjacencyEntry {
                        node: zerocopy::byteorder::little_endian::U32::new(i),
                    };
                    adjacency.extend_from_slice(e.as_bytes());
                }
                let end = adjacency_len(&adjacency);
                *range = EdgeRange {
                    first: first.into(),
                    count: (end - first).into(),
                };
            }
            clusters.push(ClusterRecords {
                threshold: c.threshold,
                max_error: c.max_error,
                index,
                edges,
            });
        }
        TableRecords {
            nodes,
            blocks,
            clusters,
            adjacency,
        }
    }

    /// Writes every cluster's index, then the adjacency table; returns the clusters as the
    /// directory describes them, and the adjacency table's root.
    pub fn write_indexes(&self, sink: &mut dyn PageSink) -> Result<(Vec<ClusterInfo>, TreeRef)> {
        let mut clusters = Vec::with_capacity(self.clusters.len());
        for c in &self.clusters {
            let index = sink.tree(&c.index, tables::INDEX)?;
            clusters.push(ClusterInfo::new(c.threshold, c.max_error, index, c.edges));
        }
        let adjacency = sink.tree(&self.adjacency, tables::ADJACENCY)?;
        Ok((clusters, adjacency))
    }

    /// The top of the tree (format 6.2): the records of every node of level below
    /// `levels`, with their ordinals.
    pub fn top(&self, levels: u8) -> Vec<u8> {
        let size = tables::NODES.record_size;
        let entries = self
            .nodes
            .chunks_exact(size)
            .zip(0u32..)
            .filter_map(|(bytes, i)| {
                let r = NodeRecord::ref_from_bytes(bytes).ok()?;
                (r.level < levels).then_some((i, r))
            });
        crate::format::top::encode(levels, entries)
    }
}

/// The row-major index of block `(x, y)` among `cols` columns.
pub(crate) fn block_index(x: u32, y: u32, cols: u32) -> usize {
    y as usize * cols as usize + x as usize
}

/// Every physical block's data rectangle and void count, row-major.
pub(crate) fn block_shapes(model: &Model) -> Vec<BlockShape> {
    let d = model.domain();
    let finest = d.finest_level();
    let (cols, rows) = d.nodes_across(finest);
    let data = d.data_rect();
    let raster = model.raster();
    (0..rows)
        .into_par_iter()
        .flat_map_iter(|y| {
            (0..cols).map(move |x| {
                let rect = d.footprint(finest, x, y).intersect(&data).unwrap_or(data);
                let valid: u64 = (rect.row0..=rect.row1)
                    .map(|r| raster.count_valid(r, rect.col0, rect.col1))
                    .sum();
                BlockShape {
                    rect,
                    // A block holds at most 1025² samples.
                    void_count: u32::try_from(rect.samples() - valid).unwrap_or(u32::MAX),
                }
            })
        })
        .collect()
}

/// Per node: whether its stored (clipped) coarse grid has a void or padding sample.
pub(crate) fn grid_void_flags(model: &Model) -> Vec<bool> {
    let d = model.domain();
    let tree = model.tree();
    let data = d.data_rect();
    tree.nodes()
        .par_iter()
        .enumerate()
        .map(|(i, n)| {
            if n.level == d.finest_level() {
                return false;
            }
            let fp = tree.footprint(node_id(i));
            if fp.intersect(&data) == Some(fp) && n.valid_samples == fp.samples() {
                return false;
            }
            let s = d.stride(n.level);
            let (gw, gh) = d.grid_dims(n.level, n.x, n.y);
            (0..u64::from(gh)).any(|j| {
                (0..u64::from(gw))
                    .any(|k| !model.raster().is_valid(fp.col0 + k * s, fp.row0 + j * s))
            })
        })
        .collect()
}

/// A node's index in a model's tree, which holds fewer than 2^32 nodes.
pub(crate) fn node_id(i: usize) -> u32 {
    u32::try_from(i).unwrap_or(u32::MAX)
}

/// The stored payload of `node`'s coarse grid (format 2: coded; every code raw when `raw`),
/// and whether it is coded against its parent's grid: when `against_parent` allows it and
/// that codes it smaller (format 5). The parent's grid is the model's, which is what its
/// stored payload decodes to, whether it is written now or kept.
pub(crate) fn encode_grid(
    model: &Model,
    node: u32,
    has_voids: bool,
    raw: bool,
    against_parent: bool,
    quick: bool,
) -> (Vec<u8>, bool) {
    let (g, _, _) = clipped_grid(model, node);
    let layout = payload::encode_grid(&g.heights, &g.void, has_voids);
    let coding = coding(model, raw, quick);
    let n = model.tree().node(node);
    let placement = Placement::node_grid(model.domain(), (n.level, n.x, n.y), has_voids, n.thin);
    let alone = payload::encode(&layout, &placement, coding, None).unwrap_or_default();
    let against = (against_parent && !raw && n.parent != NO_PARENT)
        .then(|| {
            payload::encode(
                &layout,
                &placement,
                coding,
                Some(&parent_grid(model, n.parent)),
            )
        })
        .flatten();
    // A tie goes to coding alone: then a reader needs nothing else to draw the grid.
    match against {
        Some(bytes) if bytes.len() < alone.len() => (bytes, true),
        _ => (alone, false),
    }
}

/// How `model`'s payloads are coded: every code raw when `raw`, else the smallest, with the
/// model's storage precision as one more lattice step.
fn coding(model: &Model, raw: bool, quick: bool) -> payload::Coding {
    payload::Coding {
        step: model.precision().map(Precision::step),
        raw,
        quick,
        // Format 7: tANS wherever it applies (the codec falls back to pco per stream where
        // a residual over the common factor does not fit an i32).
        coder: crate::codec::Coder::Tans,
    }
}

/// A node's grid as a payload coded against it sees it: its stored heights (the model's,
/// which its payload decodes to, whether written now or kept; only the kept columns of a
/// grid stored thinned, format 6) and where they lie.
fn parent_grid(model: &Model, node: u32) -> ParentGrid {
    let n = model.tree().node(node);
    let (g, _, _) = clipped_grid(model, node);
    // Whether it has voids does not change where its heights lie.
    let placement = Placement::node_grid(model.domain(), (n.level, n.x, n.y), false, n.thin);
    ParentGrid::new(node, PayloadRef::default(), &placement, g.heights)
}

/// The grid of `node` clipped to its stored `gw × gh` (see [`crate::model::Domain::grid_dims`]).
pub(crate) fn clipped_grid(model: &Model, node: u32) -> (NodeGrid, u32, u32) {
    let n = model.tree().node(node);
    let (gw, gh) = model.domain().grid_dims(n.level, n.x, n.y);
    let mut g = model.node_grid(node);
    let b = g.size as usize;
    let (w, h) = (gw as usize, gh as usize);
    // The top-left gw x gh, row by row (a commit clips a grid for every payload it codes).
    if w < b || h < b {
        for j in 0..h {
            g.heights.copy_within(j * b..j * b + w, j * w);
            g.void.copy_within(j * b..j * b + w, j * w);
        }
        g.heights.truncate(w * h);
        g.void.truncate(w * h);
    }
    (g, gw, gh)
}

/// The stored payload of the physical block of `shape` (format 2: coded; every code raw
/// when `raw`), and the node whose grid it is coded against: `parent` (the block's parent
/// node, when the block is a node of the tree) when that codes it smaller (format 4), else
/// none. A tie goes to coding alone: then a reader needs nothing else to draw the block.
pub(crate) fn encode_block(
    model: &Model,
    shape: &BlockShape,
    parent: Option<u32>,
    raw_codes: bool,
    quick: bool,
) -> (Vec<u8>, Option<u32>) {
    let raster = model.raster();
    let r = shape.rect;
    let samples = (r.row0..=r.row1).flat_map(|row| {
        (r.col0..=r.col1).map(move |col| (raster.value(col, row), raster.is_valid(col, row)))
    });
    let raw = payload::encode_block(samples, usize::try_from(r.samples()).unwrap_or(0));
    let coding = coding(model, raw_codes, quick);
    let placement = Placement::block(r, shape.void_count);
    let alone = payload::encode(&raw, &placement, coding, None).unwrap_or_default();
    let against = parent.filter(|_| !raw_codes).and_then(|p| {
        let bytes = payload::encode(&raw, &placement, coding, Some(&parent_grid(model, p)))?;
        Some((bytes, p))
    });
    match against {
        Some((bytes, p)) if bytes.len() < alone.len() => (bytes, Some(p)),
        _ => (alone, None),
    }
}

/// The node whose grid block `(x, y)` may be coded against: its parent, when the block is a
/// node of `model`'s tree (a block under a pruned leaf is coded alone: its leaf's grid
/// already draws it, and it is often one shared constant).
pub(crate) fn block_parent(model: &Model, node_at_finest: Option<u32>) -> Option<u32> {
    let n = model.tree().node(node_at_finest?);
    (n.parent != NO_PARENT).then_some(n.parent)
}
