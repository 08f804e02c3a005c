//! Writing a model to a new container, all at once.
//!
//! The file is laid out front to back (`format-spec/container.md` §2): the two commit slots,
//! every payload in the tree's Hilbert pre-order, then the metadata: the dataset header and
//! the tables (nodes, blocks, each cluster's index, the adjacency table) and the cluster
//! directory. Small metadata is one compressed bundle straight after the last payload
//! (§6.7); larger metadata is pages of its own. The commit record goes into slot 0 last,
//! once every page it points to is written. The second slot is left zero.

use std::collections::HashMap;
use std::io::{Seek, SeekFrom, Write};
use std::path::Path;

use rayon::prelude::*;
use zerocopy::IntoBytes;

use super::tables::{self, block_index, PageSink, PayloadRefs, TableRoots};
use super::{SectionBytes, WriteOptions, WriteSummary};
use crate::curve::HilbertKey;
use crate::error::{Error, Result};
use crate::format::blob::encode_blob;
use crate::format::bundle::BundleRef;
use crate::format::payload::{self, PayloadRef};
use crate::format::tables::FREE;
use crate::format::top::TOP_LEVELS;
use crate::format::tree::{self, TreeSpec};
use crate::format::{self, tag, BlobRef, CommitRecord, DatasetHeader, StateRoots, TreeRef};
use crate::heightfield::Metadata;
use crate::model::{Domain, Model};

/// The transaction id of a freshly built file's one state: every page of it carries its tag.
const FIRST_TXN: u64 = 1;

/// One payload, in file order.
#[derive(Clone, Copy, Debug)]
enum Item {
    Grid {
        node: u32,
    },
    /// A physical block, and its node when it is one of the tree's.
    Block {
        x: u32,
        y: u32,
        node: Option<u32>,
    },
}

/// Writes the whole container to `w`, which must start empty (positioned at 0). A failed
/// write is an I/O error about `<writer>`; [`super::write_file`] names the file.
#[cfg(any(test, feature = "testing"))]
pub fn write_to<W: Write + Seek>(
    model: &Model,
    metadata: &Metadata,
    options: &WriteOptions,
    w: &mut W,
) -> Result<WriteSummary> {
    write_named(model, metadata, options, w, Path::new("<writer>"))
}

/// [`write_to`], with I/O errors about the file `name`.
pub(crate) fn write_named<W: Write + Seek>(
    model: &Model,
    metadata: &Metadata,
    options: &WriteOptions,
    w: &mut W,
    name: &Path,
) -> Result<WriteSummary> {
    let io_err = |e| Error::io(name, e);
    let p = options.page_size;
    if !format::page_size_is_valid(p) {
        return Err(Error::InvalidArgument(format!(
            "page size {p}: must be a power of two from {} to {}",
            format::MIN_PAGE_SIZE,
            format::MAX_PAGE_SIZE
        )));
    }
    // A reader and an editor thin by the georeference's spacing (format 6): a model thinned
    // by any other would be stored with errors no one could measure again.
    let georeferenced = metadata
        .georeference
        .as_ref()
        .and_then(crate::model::LatLonSpacing::of_georeference);
    if model.thinning().is_some() && model.thinning() != georeferenced {
        return Err(Error::InvalidArgument(
            "the model is thinned by area by a spacing its georeference does not give: \
             build it from a longitude-latitude heightfield, or without thinning"
                .into(),
        ));
    }
    let mut out = PageWriter {
        w,
        name,
        page_size: u64::from(p),
        written: 0,
    };
    let mut sections = SectionBytes {
        commit_slots: 2 * u64::from(p),
        ..SectionBytes::default()
    };
    out.write(&vec![0u8; 2 * p as usize])?;
    let mut sink = SeqSink {
        out: &mut out,
        next_page: 2,
        page_size: p,
        bytes: HashMap::new(),
    };
    let refs = write_payloads(model, options, sink.out, &mut sections)?;
    let header = DatasetHeader::of_model(model, metadata).encode();
    // Small metadata goes into one compressed bundle right after the payloads (format
    // §6.7); larger metadata into pages of its own after them.
    let bundled = tables::bundle_metadata(
        model,
        &refs,
        &header,
        p,
        FIRST_TXN,
        options.bundle_limit,
        crate::format::bundle::BUNDLE_ZSTD_LEVEL,
    )?;
    // The bundle's stored bytes follow the last payload on any byte; the page's tail is
    // zero. Without a bundle, the tables take pages of their own after it.
    let bundle = match &bundled {
        Some(b) => {
            let at = tables::bundle_at(b.reference, sink.out.written);
            sink.out.write(&b.stored)?;
            sections.bundle = b.stored.len() as u64;
            at
        }
        None => BundleRef::default(),
    };
    let before = sink.out.written;
    sink.out.pad_to_page()?;
    sections.payload_padding += sink.out.written - before;
    let (dataset_header, roots, top) = match bundled {
        Some(b) => (b.dataset_header, b.roots, BlobRef::default()),
        None => {
            sink.next_page = sink.out.written / u64::from(p);
            write_paged(model, &refs, &header, &mut sink)?
        }
    };
    let of = |t: [u8; 4]| sink.bytes.get(&t).copied().unwrap_or(0);
    sections.dataset_header = of(tag::DATASET_HEADER);
    sections.node_table = of(tag::NODE_TABLE);
    sections.block_table = of(tag::BLOCK_TABLE);
    sections.cluster_index = of(tag::CLUSTER_INDEX);
    sections.adjacency = of(tag::ADJACENCY);
    sections.cluster_directory = of(tag::CLUSTER_DIRECTORY);
    sections.top = of(tag::TOP);
    let TableRoots {
        node_table,
        block_table,
        adjacency,
        cluster_directory,
    } = roots;

    // The commit record, last.
    let file_length = out.written;
    let roots = StateRoots {
        dataset_header,
        cluster_directory,
        node_table,
        block_table,
        free_list: tree::empty(FREE.record_size),
        adjacency,
    };
    let record = CommitRecord::new(p, FIRST_TXN, file_length, 0, roots)
        .with_bundle(bundle)
        .with_top(top);
    out.w.seek(SeekFrom::Start(0)).map_err(io_err)?;
    out.w.write_all(record.as_bytes()).map_err(io_err)?;
    out.w.seek(SeekFrom::Start(file_length)).map_err(io_err)?;
    Ok(WriteSummary {
        file_length,
        page_size: p,
        sections,
    })
}

/// Writes every payload in file order from the current position (page-aligned), back to
/// back; returns where each lies.
fn write_payloads<W: Write>(
    model: &Model,
    options: &WriteOptions,
    out: &mut PageWriter<'_, W>,
    sections: &mut SectionBytes,
) -> Result<PayloadRefs> {
    let domain = *model.domain();
    let tree = model.tree();
    let (cols, _) = domain.nodes_across(domain.finest_level());
    let shapes = tables::block_shapes(model);
    let grid_voids = tables::grid_void_flags(model);
    let items = payload_order(model);
    // Progress counts the samples' layout bytes coded and written (the coded lengths are
    // not known ahead).
    let raw_len = |item: &Item| match *item {
        Item::Grid { node } => {
            let n = tree.node(node);
            let (gw, gh) = domain.grid_dims(n.level, n.x, n.y);
            payload::grid_len(gw, gh, grid_voids[node as usize])
        }
        Item::Block { x, y, .. } => shapes[block_index(x, y, cols)].raw_len(),
    };
    let phase = crate::progress::Phase::start(
        &*options.progress,
        "coding and writing payloads",
        items.iter().map(raw_len).sum(),
        super::Unit::Bytes,
    );
    let mut grid = vec![PayloadRef::default(); tree.nodes().len()];
    let mut block = vec![PayloadRef::default(); shapes.len()];
    let mut against = vec![None; shapes.len()];
    let mut grid_against = vec![false; tree.nodes().len()];
    // Small payloads that repeat (sea, void and flat blocks code to a few bytes, the same
    // ones by the thousand) are stored once and shared by every record that has them.
    let mut small: HashMap<Vec<u8>, PayloadRef> = HashMap::new();
    // Coded in parallel a window at a time, written in order, each on the next aligned byte.
    const WINDOW: usize = 256;
    for w_items in items.chunks(WINDOW) {
        let encoded: Vec<(Vec<u8>, Option<u32>)> = w_items
            .par_iter()
            .map(|item| match *item {
                Item::Grid { node } => {
                    let (bytes, against) = tables::encode_grid(
                        model,
                        node,
                        grid_voids[node as usize],
                        options.raw_payloads,
                        options.against_parents,
                        false,
                    );
                    (bytes, against.then(|| tree.node(node).parent))
                }
                Item::Block { x, y, node } => tables::encode_block(
                    model,
                    &shapes[block_index(x, y, cols)],
                    tables::block_parent(model, node).filter(|_| options.against_parents),
                    options.raw_payloads,
                    false,
                ),
            })
            .collect();
        for (item, (bytes, parent)) in w_items.iter().zip(encoded) {
            phase.advance(raw_len(item));
            let shared = (bytes.len() <= tables::MAX_SHARED_PAYLOAD)
                .then(|| small.get(&bytes).copied())
                .flatten();
            let r = match shared {
                Some(r) => r,
                None => {
                    // 2.x payloads are coded, decoded on read: no alignment, back to back.
                    let offset = out.written.next_multiple_of(format::payload_align(true));
                    let before = out.written;
                    out.zeros(offset - out.written)?;
                    sections.payload_padding += out.written - before;
                    out.write(&bytes)?;
                    let r = PayloadRef::of(offset, &bytes).ok_or_else(|| {
                        Error::Internal(format!("a payload of {} bytes", bytes.len()))
                    })?;
                    match *item {
                        Item::Grid { .. } => sections.grids += bytes.len() as u64,
                        Item::Block { .. } => sections.blocks += bytes.len() as u64,
                    }
                    if bytes.len() <= tables::MAX_SHARED_PAYLOAD {
                        small.insert(bytes, r);
                    }
                    r
                }
            };
            match *item {
                Item::Grid { node } => {
                    grid[node as usize] = r;
                    grid_against[node as usize] = parent.is_some();
                }
                Item::Block { x, y, .. } => {
                    block[block_index(x, y, cols)] = r;
                    against[block_index(x, y, cols)] = parent;
                }
            }
        }
    }
    drop(phase);
    Ok(PayloadRefs {
        grid,
        block,
        against,
        grid_raw_bitmap: vec![false; grid_against.len()],
        grid_against,
        grid_voids,
        shapes,
    })
}

/// A paged state's metadata, laid out so that what a remote reader needs first lies in the
/// file's last pages, which it fetches at open with the commit slots (format §2): the
/// cluster indexes and the adjacency table, the leaves of the node and block tables, then
/// their branches, the top of the tree (6.2), the cluster directory and the dataset
/// header. Returns the header's blob, the tables' roots and the top's blob.
fn write_paged<W: Write>(
    model: &Model,
    refs: &PayloadRefs,
    header: &[u8],
    sink: &mut SeqSink<'_, '_, W>,
) -> Result<(BlobRef, TableRoots, BlobRef)> {
    let records = tables::TableRecords::of(model, refs);
    let (clusters, adjacency) = records.write_indexes(sink)?;
    let p = sink.page_size;
    let leaves = |bytes: &[u8], spec: TreeSpec| {
        tree::leaf_pages(
            (bytes.len() / spec.record_size) as u64,
            p,
            spec.record_size,
        )
    };
    let (nodes, blocks) = (crate::format::tables::NODES, crate::format::tables::BLOCKS);
    let branches_at = sink.next_page + leaves(&records.nodes, nodes) + leaves(&records.blocks, blocks);
    let mut branches = Vec::new();
    let node_table = sink.split_tree(&records.nodes, nodes, branches_at, &mut branches)?;
    let block_table = sink.split_tree(
        &records.blocks,
        blocks,
        branches_at + branches.len() as u64,
        &mut branches,
    )?;
    if sink.next_page != branches_at {
        return Err(Error::Internal(format!(
            "the tables' leaves end at page {}, not {branches_at}",
            sink.next_page
        )));
    }
    for (tag, page) in branches {
        sink.pages(tag, &[page])?;
    }
    let levels = TOP_LEVELS.min(model.domain().finest_level().saturating_add(1));
    let top = sink.blob(&records.top(levels), tag::TOP)?;
    let cluster_directory = sink.blob(
        &crate::format::directory::encode(&clusters),
        tag::CLUSTER_DIRECTORY,
    )?;
    let dataset_header = sink.blob(header, tag::DATASET_HEADER)?;
    Ok((
        dataset_header,
        TableRoots {
            node_table,
            block_table,
            adjacency,
            cluster_directory,
        },
        top,
    ))
}

/// A [`PageSink`] that appends pages in order (a fresh file), counting bytes per tag.
struct SeqSink<'a, 'w, W: Write> {
    out: &'a mut PageWriter<'w, W>,
    next_page: u64,
    page_size: u32,
    bytes: HashMap<[u8; 4], u64>,
}

impl<W: Write> SeqSink<'_, '_, W> {
    fn pages(&mut self, tag: [u8; 4], pages: &[Vec<u8>]) -> Result<()> {
        for page in pages {
            self.out.write(page)?;
        }
        self.next_page += pages.len() as u64;
        *self.bytes.entry(tag).or_default() += pages.len() as u64 * u64::from(self.page_size);
        Ok(())
    }

    /// Writes the leaves of a tree of `records` here and numbers its branches from
    /// `branches_at` on, leaving them in `branches` for the caller to write there.
    fn split_tree(
        &mut self,
        records: &[u8],
        spec: TreeSpec,
        branches_at: u64,
        branches: &mut Vec<([u8; 4], Vec<u8>)>,
    ) -> Result<TreeRef> {
        let mut leaves = Vec::new();
        let first = [self.next_page, branches_at];
        let root = tree::build_split::<Error>(records, spec, self.page_size, first, FIRST_TXN, &mut |page| {
            // The level sits at bytes 16..18 of the page header (format §4).
            if page.get(16..18) == Some(&[0, 0][..]) {
                leaves.push(page);
            } else {
                branches.push((spec.tag, page));
            }
            Ok(())
        })?;
        self.pages(spec.tag, &leaves)?;
        Ok(root)
    }
}

impl<W: Write> PageSink for SeqSink<'_, '_, W> {
    fn tree(&mut self, records: &[u8], spec: TreeSpec) -> Result<TreeRef> {
        let mut pages = Vec::new();
        let (first, txn) = (self.next_page, FIRST_TXN);
        let root = tree::build::<Error>(records, spec, self.page_size, first, txn, &mut |p| {
            pages.push(p);
            Ok(())
        })?;
        self.pages(spec.tag, &pages)?;
        Ok(root)
    }

    fn blob(&mut self, content: &[u8], tag: [u8; 4]) -> Result<BlobRef> {
        let (blob, pages) = encode_blob(content, tag, self.next_page, FIRST_TXN, self.page_size);
        self.pages(tag, &pages)?;
        Ok(blob)
    }
}

struct PageWriter<'w, W: Write> {
    w: &'w mut W,
    name: &'w Path,
    page_size: u64,
    written: u64,
}

impl<W: Write> PageWriter<'_, W> {
    fn write(&mut self, bytes: &[u8]) -> Result<()> {
        self.w
            .write_all(bytes)
            .map_err(|e| Error::io(self.name, e))?;
        self.written += bytes.len() as u64;
        Ok(())
    }

    fn zeros(&mut self, n: u64) -> Result<()> {
        // Padding is less than a page or an alignment step.
        self.write(&vec![0u8; usize::try_from(n).unwrap_or(0)])
    }

    fn pad_to_page(&mut self) -> Result<()> {
        let pad = self.written.next_multiple_of(self.page_size) - self.written;
        self.zeros(pad)
    }
}

/// The payloads in file order (format §2): the tree in Hilbert pre-order, each node's grid
/// (or, at the finest level, its block), and after each leaf above the finest level the
/// blocks under it in Hilbert order; except the grids of the top of the tree's levels
/// (0 to 3, [`TOP_LEVELS`]), which come last, level by level from the finest to the root.
/// So the coarse grids lie just before the metadata, in the file's last bytes that a remote
/// reader fetches at open: a coarse scene then needs no payload round of its own, and
/// others find there the ancestors their payloads are coded against.
fn payload_order(model: &Model) -> Vec<Item> {
    let d = model.domain();
    let finest = d.finest_level();
    let mut items = Vec::new();
    let mut coarse: Vec<(u8, Item)> = Vec::new();
    for (i, n) in model.tree().nodes().iter().enumerate() {
        if n.level == finest {
            items.push(Item::Block {
                x: n.x,
                y: n.y,
                node: Some(tables::node_id(i)),
            });
            continue;
        }
        let grid = Item::Grid {
            node: tables::node_id(i),
        };
        if n.level < TOP_LEVELS {
            coarse.push((n.level, grid));
        } else {
            items.push(grid);
        }
        if n.subtree_len == 1 {
            blocks_under(d, n.level, n.x, n.y, &mut items);
        }
    }
    // Stable: each level keeps its Hilbert order.
    coarse.sort_by_key(|&(level, _)| std::cmp::Reverse(level));
    items.extend(coarse.into_iter().map(|(_, item)| item));
    items
}

fn blocks_under(d: &Domain, level: u8, x: u32, y: u32, items: &mut Vec<Item>) {
    if !d.exists(level, x, y) {
        return;
    }
    if level == d.finest_level() {
        items.push(Item::Block { x, y, node: None });
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
