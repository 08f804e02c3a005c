//! Writing a model to a new container, all at once.
//!
//! The file is laid out front to back (`format-spec/container.md` §3): the two commit slots,
//! the dataset header, every payload in the tree's Hilbert pre-order, then the tables (nodes,
//! blocks, each cluster's index, the adjacency table) and the cluster directory. The commit
//! record goes into slot 0 last, once every page it points to is written. The second slot is
//! left zero.
//!
//! [`write_file`] writes into a temporary file in the target's directory, flushes and fsyncs
//! it, and only then renames it into place (and fsyncs the directory). A failure or a crash at
//! any point leaves the target as it was: absent, or the previous file intact.

use std::io::{BufWriter, Seek, SeekFrom, Write};
use std::path::Path;

use indicatif::{ProgressBar, ProgressDrawTarget, ProgressStyle};
use rayon::prelude::*;
use serde::Serialize;
use zerocopy::byteorder::little_endian::{F32, F64, U16, U32, U64};
use zerocopy::IntoBytes;

use super::btree;
use crate::curve::HilbertKey;
use crate::error::{Error, Result};
use crate::format::{
    self, payload, tag, AdjacencyEntry, BlobRef, BlockRecord, ClusterRecord, CommitRecord,
    DatasetHeader, EdgeRange, FreeEntry, IndexEntry, NodeRecord, PageHeader, TreeRef,
    CLUSTER_DIRECTORY_PREFIX, DEFAULT_PAGE_SIZE, FORMAT_MAJOR, FORMAT_MINOR, MAGIC,
    NODE_GRID_HAS_VOIDS, PAGE_HEADER_LEN, PAYLOAD_ALIGN, VOID_BITS,
};
use crate::heightfield::Metadata;
use crate::model::{cluster, Model, SampleRect};

/// How to write a container.
#[derive(Clone, Debug)]
pub struct WriteOptions {
    /// Bytes per page: a power of two in 1024..=65536.
    pub page_size: u32,
    /// Draw a progress bar on stderr (only when stderr is a terminal).
    pub progress: bool,
}

impl Default for WriteOptions {
    fn default() -> Self {
        WriteOptions {
            page_size: DEFAULT_PAGE_SIZE,
            progress: false,
        }
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

/// One payload, in file order.
#[derive(Clone, Copy, Debug)]
enum Item {
    Grid { node: u32 },
    Block { x: u32, y: u32 },
}

/// The physical blocks' shapes, row-major over the finest level.
pub(crate) struct BlockShape {
    pub rect: SampleRect,
    pub void_count: u32,
}

/// Writes `model` (of a heightfield with `metadata`) to `path` through a temporary file (see
/// the module docs). Refuses to replace an existing `path` unless `overwrite`.
pub fn write_file(
    model: &Model,
    metadata: &Metadata,
    path: &Path,
    options: &WriteOptions,
    overwrite: bool,
) -> Result<WriteSummary> {
    write_atomically(path, overwrite, |w| write_to(model, metadata, options, w))
}

/// Creates `path` with what `fill` writes, atomically. The bytes go to a temporary file in the
/// same directory, which is flushed, synced and renamed into place, then the directory is
/// synced. On any failure the temporary file is removed and `path` is untouched. An existing
/// `path` is refused unless `overwrite`, and is then replaced in one rename.
pub fn write_atomically<T>(
    path: &Path,
    overwrite: bool,
    fill: impl FnOnce(&mut BufWriter<&std::fs::File>) -> Result<T>,
) -> Result<T> {
    if !overwrite && path.exists() {
        return Err(Error::InvalidArgument(format!(
            "{} exists; pass --force to replace it",
            path.display()
        )));
    }
    let dir = match path.parent() {
        Some(d) if !d.as_os_str().is_empty() => d,
        _ => Path::new("."),
    };
    let temp = tempfile::Builder::new()
        .prefix(".fmrh-")
        .suffix(".tmp")
        .tempfile_in(dir)
        .map_err(|e| Error::io(dir, e))?;
    let value = {
        let mut w = BufWriter::with_capacity(1 << 20, temp.as_file());
        let value = fill(&mut w)?;
        w.flush().map_err(|e| Error::io(temp.path(), e))?;
        value
    };
    temp.as_file()
        .sync_all()
        .map_err(|e| Error::io(temp.path(), e))?;
    let persisted = if overwrite {
        temp.persist(path).map_err(|e| Error::io(path, e.error))?
    } else {
        temp.persist_noclobber(path)
            .map_err(|e| Error::io(path, e.error))?
    };
    drop(persisted);
    sync_dir(dir)?;
    Ok(value)
}

/// Makes a rename in `dir` durable.
fn sync_dir(dir: &Path) -> Result<()> {
    #[cfg(unix)]
    {
        std::fs::File::open(dir)
            .and_then(|d| d.sync_all())
            .map_err(|e| Error::io(dir, e))?;
    }
    #[cfg(not(unix))]
    let _ = dir;
    Ok(())
}

/// Writes the whole container to `w`, which must start empty (positioned at 0).
pub fn write_to<W: Write + Seek>(
    model: &Model,
    metadata: &Metadata,
    options: &WriteOptions,
    w: &mut W,
) -> Result<WriteSummary> {
    let p = options.page_size;
    if !format::page_size_is_valid(p) {
        return Err(Error::InvalidArgument(format!(
            "page size {p}: must be a power of two from {} to {}",
            format::MIN_PAGE_SIZE,
            format::MAX_PAGE_SIZE
        )));
    }
    let mut out = PageWriter {
        w,
        page_size: u64::from(p),
        written: 0,
    };
    let mut sections = SectionBytes {
        commit_slots: 2 * u64::from(p),
        ..SectionBytes::default()
    };
    out.write(&vec![0u8; 2 * p as usize])?;
    let mut next_page = 2u64;

    // Dataset header.
    let header = DatasetHeader::of_model(model, metadata).encode();
    let dataset_header = write_blob(&mut out, &header, tag::DATASET_HEADER, &mut next_page, p)?;
    sections.dataset_header = out.written - sections.commit_slots;

    // Payloads.
    let domain = *model.domain();
    let tree = model.tree();
    let finest = domain.finest_level();
    let (cols, _) = domain.nodes_across(finest);
    let shapes = block_shapes(model);
    let grid_voids = grid_void_flags(model);
    let items = payload_order(model);
    let len_of = |item: &Item| match *item {
        Item::Grid { node } => {
            let n = tree.node(node);
            let (gw, gh) = payload::grid_dims(&domain, n.level, n.x, n.y);
            payload::grid_len(gw, gh, grid_voids[node as usize])
        }
        Item::Block { x, y } => {
            let s = &shapes[(y * cols + x) as usize];
            payload::block_len(
                (s.rect.col1 - s.rect.col0 + 1) as u32,
                (s.rect.row1 - s.rect.row0 + 1) as u32,
                s.void_count,
            )
        }
    };
    let mut offsets = Vec::with_capacity(items.len());
    let mut at = next_page * u64::from(p);
    for item in &items {
        at = at.next_multiple_of(PAYLOAD_ALIGN);
        offsets.push(at);
        at += len_of(item);
    }
    let progress = progress_bar(options.progress, at - next_page * u64::from(p));
    let mut grid_ref = vec![(0u64, 0u32, 0u32); tree.nodes().len()];
    let mut block_ref = vec![(0u64, 0u32, 0u32); shapes.len()];
    const WINDOW: usize = 256;
    for (w_items, w_offsets) in items.chunks(WINDOW).zip(offsets.chunks(WINDOW)) {
        let encoded: Vec<(Vec<u8>, u32)> = w_items
            .par_iter()
            .map(|item| {
                let bytes = match *item {
                    Item::Grid { node } => encode_grid(model, node, grid_voids[node as usize]),
                    Item::Block { x, y } => encode_block(model, &shapes[(y * cols + x) as usize]),
                };
                let crc = format::crc32(&bytes);
                (bytes, crc)
            })
            .collect();
        for ((item, &offset), (bytes, crc)) in w_items.iter().zip(w_offsets).zip(encoded) {
            let before = out.written;
            out.write(&vec![0u8; (offset - out.written) as usize])?;
            sections.payload_padding += out.written - before;
            out.write(&bytes)?;
            let r = (offset, bytes.len() as u32, crc);
            match *item {
                Item::Grid { node } => {
                    grid_ref[node as usize] = r;
                    sections.grids += bytes.len() as u64;
                }
                Item::Block { x, y } => {
                    block_ref[(y * cols + x) as usize] = r;
                    sections.blocks += bytes.len() as u64;
                }
            }
            progress.inc(bytes.len() as u64);
        }
    }
    progress.finish_and_clear();
    let before = out.written;
    out.pad_to_page()?;
    sections.payload_padding += out.written - before;
    next_page = out.written / u64::from(p);

    let refs = PayloadRefs {
        grid: grid_ref,
        block: block_ref,
        grid_voids,
        shapes,
    };
    let mut sink = SeqSink {
        out: &mut out,
        next_page: &mut next_page,
        page_size: p,
        bytes: Default::default(),
    };
    let roots = write_tables(model, &refs, &mut sink)?;
    let bytes = std::mem::take(&mut sink.bytes);
    let of = |t: [u8; 4]| bytes.get(&t).copied().unwrap_or(0);
    sections.node_table = of(tag::NODE_TABLE);
    sections.block_table = of(tag::BLOCK_TABLE);
    sections.cluster_index = of(tag::CLUSTER_INDEX);
    sections.adjacency = of(tag::ADJACENCY);
    sections.cluster_directory = of(tag::CLUSTER_DIRECTORY);
    let Roots {
        node_table,
        block_table,
        adjacency,
        cluster_directory,
    } = roots;

    // The commit record, last.
    let file_length = out.written;
    debug_assert_eq!(file_length, next_page * u64::from(p));
    let record = commit_record(
        p,
        1,
        file_length,
        dataset_header,
        cluster_directory,
        node_table,
        block_table,
        btree::empty(size_of::<FreeEntry>()),
        adjacency,
    );
    out.w.seek(SeekFrom::Start(0)).map_err(io_err)?;
    out.w.write_all(record.as_bytes()).map_err(io_err)?;
    out.w.seek(SeekFrom::Start(file_length)).map_err(io_err)?;
    Ok(WriteSummary {
        file_length,
        page_size: p,
        sections,
    })
}

/// Where each payload of a state lies: `(offset, len, crc)` per node (its grid; unused at the
/// finest level) and per physical block (row-major), with what the tables need to describe
/// them.
pub(crate) struct PayloadRefs {
    pub grid: Vec<(u64, u32, u32)>,
    pub block: Vec<(u64, u32, u32)>,
    pub grid_voids: Vec<bool>,
    pub shapes: Vec<BlockShape>,
}

/// Where the pages of a state's tables and blobs go: in order for a fresh file, wherever
/// the allocator finds room for a commit.
pub(crate) trait PageSink {
    /// Writes `records` (`record_size` bytes each) as a tree of `tag` pages.
    fn tree(
        &mut self,
        records: &[u8],
        record_size: usize,
        keyed: bool,
        tag: [u8; 4],
    ) -> Result<TreeRef>;
    /// Writes `content` as a blob of consecutive `tag` pages.
    fn blob(&mut self, content: &[u8], tag: [u8; 4]) -> Result<BlobRef>;
}

/// The roots [`write_tables`] returns.
pub(crate) struct Roots {
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
) -> Result<Roots> {
    let domain = *model.domain();
    let tree = model.tree();
    let finest = domain.finest_level();
    let (cols, rows) = domain.nodes_across(finest);

    let mut node_records = Vec::with_capacity(tree.nodes().len() * size_of::<NodeRecord>());
    for (i, n) in tree.nodes().iter().enumerate() {
        let (offset, len, crc) = if n.level == finest {
            refs.block[(n.y * cols + n.x) as usize]
        } else {
            refs.grid[i]
        };
        let flags = if n.level < finest && refs.grid_voids[i] {
            NODE_GRID_HAS_VOIDS
        } else {
            0
        };
        let rec = NodeRecord {
            key: U64::new(n.key.0),
            level: n.level,
            child_mask: n.child_mask,
            flags: U16::new(flags),
            x: U32::new(n.x),
            y: U32::new(n.y),
            parent: U32::new(n.parent),
            subtree_len: U32::new(n.subtree_len),
            payload_crc: U32::new(crc),
            static_error: F64::new(n.static_error),
            monotone_error: F64::new(n.monotone_error),
            min_height: F32::new(n.min_height),
            max_height: F32::new(n.max_height),
            valid_samples: U64::new(n.valid_samples),
            payload_offset: U64::new(offset),
            payload_len: U32::new(len),
            reserved: U32::new(0),
        };
        node_records.extend_from_slice(rec.as_bytes());
    }
    let node_table = sink.tree(
        &node_records,
        size_of::<NodeRecord>(),
        false,
        tag::NODE_TABLE,
    )?;

    let mut block_records = Vec::with_capacity(refs.shapes.len() * size_of::<BlockRecord>());
    for (s, &(offset, len, crc)) in refs.shapes.iter().zip(&refs.block) {
        let rec = BlockRecord {
            payload_offset: U64::new(offset),
            payload_len: U32::new(len),
            payload_crc: U32::new(crc),
            width: U32::new((s.rect.col1 - s.rect.col0 + 1) as u32),
            height: U32::new((s.rect.row1 - s.rect.row0 + 1) as u32),
            void_count: U32::new(s.void_count),
            reserved: U32::new(0),
        };
        block_records.extend_from_slice(rec.as_bytes());
    }
    debug_assert_eq!(refs.shapes.len() as u64, u64::from(cols) * u64::from(rows));
    let block_table = sink.tree(
        &block_records,
        size_of::<BlockRecord>(),
        false,
        tag::BLOCK_TABLE,
    )?;

    // Clusters: one index each; their edge lists go into the one adjacency table.
    let mut directory = Vec::with_capacity(
        CLUSTER_DIRECTORY_PREFIX + model.clusters().len() * size_of::<ClusterRecord>(),
    );
    directory.extend_from_slice(&(model.clusters().len() as u32).to_le_bytes());
    directory.extend_from_slice(&0u32.to_le_bytes());
    let mut adjacency_entries: Vec<u8> = Vec::new();
    for c in model.clusters() {
        let mut entries = Vec::with_capacity(c.nodes.len() * size_of::<IndexEntry>());
        for &i in &c.nodes {
            let n = tree.node(i);
            let e = IndexEntry {
                key: U64::new(n.key.0),
                node: U32::new(i),
                level: n.level,
                reserved: [0; 3],
            };
            entries.extend_from_slice(e.as_bytes());
        }
        let index = sink.tree(&entries, size_of::<IndexEntry>(), true, tag::CLUSTER_INDEX)?;
        let mut adjacency = [EdgeRange::default(); 4];
        for (range, list) in adjacency
            .iter_mut()
            .zip(cluster::edge_nodes(tree, &c.nodes))
        {
            let first = (adjacency_entries.len() / size_of::<AdjacencyEntry>()) as u64;
            for i in list {
                adjacency_entries
                    .extend_from_slice(AdjacencyEntry { node: U32::new(i) }.as_bytes());
            }
            let end = (adjacency_entries.len() / size_of::<AdjacencyEntry>()) as u64;
            *range = EdgeRange {
                first: U64::new(first),
                count: U64::new(end - first),
            };
        }
        let rec = ClusterRecord {
            threshold: F64::new(c.threshold),
            max_error: F64::new(c.max_error),
            index,
            adjacency,
        };
        directory.extend_from_slice(rec.as_bytes());
    }
    let adjacency = sink.tree(
        &adjacency_entries,
        size_of::<AdjacencyEntry>(),
        false,
        tag::ADJACENCY,
    )?;
    let cluster_directory = sink.blob(&directory, tag::CLUSTER_DIRECTORY)?;
    Ok(Roots {
        node_table,
        block_table,
        adjacency,
        cluster_directory,
    })
}

/// A [`PageSink`] that appends pages in order (a fresh file), counting bytes per tag.
struct SeqSink<'a, 'w, W: Write> {
    out: &'a mut PageWriter<'w, W>,
    next_page: &'a mut u64,
    page_size: u32,
    bytes: std::collections::HashMap<[u8; 4], u64>,
}

impl<W: Write> PageSink for SeqSink<'_, '_, W> {
    fn tree(
        &mut self,
        records: &[u8],
        record_size: usize,
        keyed: bool,
        tag: [u8; 4],
    ) -> Result<TreeRef> {
        let before = self.out.written;
        let r = write_tree(
            self.out,
            records,
            record_size,
            keyed,
            tag,
            self.next_page,
            self.page_size,
        )?;
        *self.bytes.entry(tag).or_default() += self.out.written - before;
        Ok(r)
    }

    fn blob(&mut self, content: &[u8], tag: [u8; 4]) -> Result<BlobRef> {
        let before = self.out.written;
        let r = write_blob(self.out, content, tag, self.next_page, self.page_size)?;
        *self.bytes.entry(tag).or_default() += self.out.written - before;
        Ok(r)
    }
}

/// A commit record with its CRC.
#[allow(clippy::too_many_arguments)]
pub fn commit_record(
    page_size: u32,
    txn_id: u64,
    file_length: u64,
    dataset_header: BlobRef,
    cluster_directory: BlobRef,
    node_table: TreeRef,
    block_table: TreeRef,
    free_list: TreeRef,
    adjacency: TreeRef,
) -> CommitRecord {
    let mut r = CommitRecord {
        magic: MAGIC,
        major: U16::new(FORMAT_MAJOR),
        minor: U16::new(FORMAT_MINOR),
        page_size: U32::new(page_size),
        txn_id: U64::new(txn_id),
        file_length: U64::new(file_length),
        flags: U32::new(0),
        reserved0: U32::new(0),
        dataset_header,
        cluster_directory,
        node_table,
        block_table,
        free_list,
        adjacency,
        reserved: [0; 84],
        crc: U32::new(0),
    };
    r.crc = U32::new(format::crc32(&r.as_bytes()[..252]));
    r
}

fn io_err(e: std::io::Error) -> Error {
    Error::io("<container being written>", e)
}

struct PageWriter<'w, W: Write> {
    w: &'w mut W,
    page_size: u64,
    written: u64,
}

impl<W: Write> PageWriter<'_, W> {
    fn write(&mut self, bytes: &[u8]) -> Result<()> {
        self.w.write_all(bytes).map_err(io_err)?;
        self.written += bytes.len() as u64;
        Ok(())
    }

    fn pad_to_page(&mut self) -> Result<()> {
        let pad = self.written.next_multiple_of(self.page_size) - self.written;
        self.write(&vec![0u8; pad as usize])
    }
}

fn write_tree<W: Write>(
    out: &mut PageWriter<'_, W>,
    records: &[u8],
    record_size: usize,
    keyed: bool,
    tag: [u8; 4],
    next_page: &mut u64,
    page_size: u32,
) -> Result<TreeRef> {
    btree::build(
        records,
        record_size,
        keyed,
        tag,
        page_size,
        next_page,
        &mut |page| out.write(&page),
    )
}

/// Writes `content` as a blob of consecutive pages.
fn write_blob<W: Write>(
    out: &mut PageWriter<'_, W>,
    content: &[u8],
    tag: [u8; 4],
    next_page: &mut u64,
    page_size: u32,
) -> Result<BlobRef> {
    let first_page = *next_page;
    for page in blob_pages(content, tag, first_page, page_size) {
        out.write(&page)?;
        *next_page += 1;
    }
    Ok(BlobRef {
        first_page: U64::new(first_page),
        length: U64::new(content.len() as u64),
    })
}

/// The sealed pages of a blob of `content` starting at page `first_page`.
pub(crate) fn blob_pages(
    content: &[u8],
    tag: [u8; 4],
    first_page: u64,
    page_size: u32,
) -> Vec<Vec<u8>> {
    let per_page = page_size as usize - PAGE_HEADER_LEN;
    content
        .chunks(per_page)
        .enumerate()
        .map(|(i, chunk)| {
            let mut page = vec![0u8; page_size as usize];
            let h = PageHeader {
                tag,
                crc: U32::new(0),
                page_no: U64::new(first_page + i as u64),
                level: U16::new(0),
                reserved: U16::new(0),
                count: U32::new(chunk.len() as u32),
            };
            page[..PAGE_HEADER_LEN].copy_from_slice(h.as_bytes());
            page[PAGE_HEADER_LEN..PAGE_HEADER_LEN + chunk.len()].copy_from_slice(chunk);
            format::seal_page(&mut page);
            page
        })
        .collect()
}

fn progress_bar(enabled: bool, total: u64) -> ProgressBar {
    if !enabled {
        return ProgressBar::hidden();
    }
    let bar = ProgressBar::with_draw_target(Some(total), ProgressDrawTarget::stderr());
    if let Ok(style) =
        ProgressStyle::with_template("{msg} [{bar:40}] {bytes}/{total_bytes} ({eta})")
    {
        bar.set_style(style.progress_chars("=> "));
    }
    bar.set_message("writing payloads");
    bar
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
                    void_count: (rect.samples() - valid) as u32,
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
    (0..tree.nodes().len() as u32)
        .into_par_iter()
        .map(|i| {
            let n = tree.node(i);
            if n.level == d.finest_level() {
                return false;
            }
            let fp = tree.footprint(i);
            if fp.intersect(&data) == Some(fp) && n.valid_samples == fp.samples() {
                return false;
            }
            let s = d.stride(n.level);
            let (gw, gh) = payload::grid_dims(d, n.level, n.x, n.y);
            (0..u64::from(gh)).any(|j| {
                (0..u64::from(gw))
                    .any(|k| !model.raster().is_valid(fp.col0 + k * s, fp.row0 + j * s))
            })
        })
        .collect()
}

/// The payloads in file order: the tree in Hilbert pre-order, each node's grid (or, at the
/// finest level, its block), and after each leaf above the finest level the blocks under it
/// in Hilbert order.
fn payload_order(model: &Model) -> Vec<Item> {
    let d = model.domain();
    let finest = d.finest_level();
    let mut items = Vec::new();
    for (i, n) in model.tree().nodes().iter().enumerate() {
        if n.level == finest {
            items.push(Item::Block { x: n.x, y: n.y });
            continue;
        }
        items.push(Item::Grid { node: i as u32 });
        if n.subtree_len == 1 {
            blocks_under(d, n.level, n.x, n.y, &mut items);
        }
    }
    items
}

fn blocks_under(d: &crate::model::Domain, level: u8, x: u32, y: u32, items: &mut Vec<Item>) {
    if !d.exists(level, x, y) {
        return;
    }
    if level == d.finest_level() {
        items.push(Item::Block { x, y });
        return;
    }
    let mut children: Vec<(HilbertKey, u32, u32)> = (0..4u32)
        .map(|q| (2 * x + (q & 1), 2 * y + (q >> 1)))
        .map(|(cx, cy)| {
            (
                HilbertKey::of_node(d.finest_level(), level + 1, cx, cy),
                cx,
                cy,
            )
        })
        .collect();
    children.sort_unstable();
    for (_, cx, cy) in children {
        blocks_under(d, level + 1, cx, cy, items);
    }
}

/// The stored (clipped) grid of `node`: the top-left `gw × gh` of its `b × b` grid.
pub(crate) fn encode_grid(model: &Model, node: u32, has_voids: bool) -> Vec<u8> {
    let (g, gw, gh) = clipped_grid(model, node);
    let mut bytes = Vec::with_capacity(payload::grid_len(gw, gh, has_voids) as usize);
    for h in &g.heights {
        bytes.extend_from_slice(&h.to_le_bytes());
    }
    if has_voids {
        let mut bitmap = vec![0u8; g.heights.len().div_ceil(8)];
        for (i, &v) in g.void.iter().enumerate() {
            if v {
                bitmap[i / 8] |= 1 << (i % 8);
            }
        }
        bytes.extend_from_slice(&bitmap);
    }
    bytes
}

/// The grid of `node` clipped to its stored `gw × gh` (see [`payload::grid_dims`]).
pub(crate) fn clipped_grid(model: &Model, node: u32) -> (crate::model::NodeGrid, u32, u32) {
    let n = model.tree().node(node);
    let (gw, gh) = payload::grid_dims(model.domain(), n.level, n.x, n.y);
    let mut g = model.node_grid(node);
    let b = g.size as usize;
    let inside = |k: usize| k % b < gw as usize && k / b < gh as usize;
    let mut k = 0;
    g.heights.retain(|_| {
        k += 1;
        inside(k - 1)
    });
    k = 0;
    g.void.retain(|_| {
        k += 1;
        inside(k - 1)
    });
    (g, gw, gh)
}

pub(crate) fn encode_block(model: &Model, shape: &BlockShape) -> Vec<u8> {
    let raster = model.raster();
    let r = shape.rect;
    let n = r.samples() as usize + shape.void_count as usize;
    let mut bytes = Vec::with_capacity(4 * n);
    let mut stand_ins = Vec::with_capacity(shape.void_count as usize);
    for row in r.row0..=r.row1 {
        let values = &raster.row(row)[r.col0 as usize..=r.col1 as usize];
        for (col, &v) in (r.col0..=r.col1).zip(values) {
            if raster.is_valid(col, row) {
                bytes.extend_from_slice(&v.to_le_bytes());
            } else {
                bytes.extend_from_slice(&VOID_BITS.to_le_bytes());
                stand_ins.push(v);
            }
        }
    }
    for v in stand_ins {
        bytes.extend_from_slice(&v.to_le_bytes());
    }
    bytes
}
