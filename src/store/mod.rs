//! The store: a container opened for reading, with range scans over its clusters.
//!
//! # Opening, and what it costs
//!
//! Opening reads the commit slots, takes the valid record with the higher transaction id,
//! and then checks *every metadata page* the record reaches: the dataset header, the cluster
//! directory and every page of every table (tag, page number, CRC, tree shape, key order; no
//! page reached twice). That work is proportional to the metadata, about 2% of the file.
//! After it, lookups and scans from a stable source (a mapping, or memory) parse pages without
//! checking them again. A [`FileSource`] checks each page again on every read, because
//! another process may have rewritten it. Payloads (blocks and grids) are checked against
//! their CRC on every read, whatever the source.
//!
//! # The API contract, LMDB style
//!
//! * [`Store::open`] maps the file. It is `unsafe` because a mapping turns someone else's
//!   writes into undefined behaviour: while the store lives, no process may modify or
//!   truncate the file (truncation raises `SIGBUS`). fmrh itself never writes to a file in
//!   place: builds go to a new file that is renamed over the old one, so the old mapping stays
//!   valid.
//! * [`Store::open_read`] reads with positioned reads. It is safe under any concurrent
//!   activity: a page changed under it fails its checksum and reports corruption.
//! * [`Store::from_bytes`] reads a container in memory (tests, fuzzing, network buffers).
//!
//! All three give the same API, because everything above the [`Source`] works on `&[u8]`.

pub mod btree;
pub mod io;
pub mod source;
pub mod txn;
pub mod verify;
pub mod write;

use std::borrow::Cow;
use std::fs::File;
use std::ops::{Range, RangeInclusive};
use std::path::Path;

use zerocopy::FromBytes;

pub use source::{Bytes, FileSource, MmapSource, Source};
pub use txn::{CommitSummary, Container, Recovery, Snapshot, WriteTxn};
pub use verify::{verify, CheckReport, CheckStatus, VerifyReport};
pub use write::{write_atomically, write_file, write_to, SectionBytes, WriteOptions, WriteSummary};

use crate::curve::HilbertKey;
use crate::error::{Error, Result};
use crate::format::payload::{self, BlockView, GridView};
use crate::format::{
    self, invariant, is_zero, tag, AdjacencyEntry, BlobRef, BlockRecord, ClusterRecord,
    CommitRecord, DatasetHeader, EdgeRange, FreeEntry, IndexEntry, NodeRecord, TreeRef,
    CLUSTER_DIRECTORY_PREFIX, COMMIT_RECORD_LEN, FORMAT_MAJOR, FORMAT_MINOR, MAGIC, MAX_PAGE_SIZE,
    MAX_STRING_LEN, MIN_PAGE_SIZE, NODE_GRID_HAS_VOIDS, PAGE_HEADER_LEN,
};
use crate::heightfield::Heightfield;
use crate::model::{Domain, SampleRect, MAX_CLUSTERS};
use btree::{PageSet, Pages, Seek, TreeSpec};

/// What the specs of the tables are.
pub(crate) mod specs {
    use super::*;
    pub const NODES: TreeSpec = TreeSpec {
        tag: tag::NODE_TABLE,
        record_size: size_of::<NodeRecord>(),
        keyed: false,
        name: "node table",
    };
    pub const BLOCKS: TreeSpec = TreeSpec {
        tag: tag::BLOCK_TABLE,
        record_size: size_of::<BlockRecord>(),
        keyed: false,
        name: "block table",
    };
    pub const FREE: TreeSpec = TreeSpec {
        tag: tag::FREE_LIST,
        record_size: size_of::<FreeEntry>(),
        keyed: true,
        name: "free list",
    };
    pub const INDEX: TreeSpec = TreeSpec {
        tag: tag::CLUSTER_INDEX,
        record_size: size_of::<IndexEntry>(),
        keyed: true,
        name: "cluster index",
    };
    pub const ADJACENCY: TreeSpec = TreeSpec {
        tag: tag::ADJACENCY,
        record_size: size_of::<AdjacencyEntry>(),
        keyed: false,
        name: "adjacency list",
    };
}

/// Where a file's bytes go, section by section.
#[derive(Clone, Debug, PartialEq, Eq, serde::Serialize)]
pub struct Layout {
    /// Bytes per page.
    pub page_size: u32,
    /// Bytes in the committed file.
    pub file_length: u64,
    /// The two commit slots.
    pub commit_pages: u64,
    /// Dataset header pages.
    pub dataset_header_pages: u64,
    /// Cluster directory pages.
    pub cluster_directory_pages: u64,
    /// Node table pages.
    pub node_table_pages: u64,
    /// Block table pages.
    pub block_table_pages: u64,
    /// Free list pages.
    pub free_list_pages: u64,
    /// Free pages (the free list's entries): space transactions left for reuse.
    pub free_pages: u64,
    /// Adjacency table pages.
    pub adjacency_pages: u64,
    /// Index pages of each cluster.
    pub cluster_index_pages: Vec<u64>,
    /// Payload bytes of the physical blocks.
    pub block_bytes: u64,
    /// Payload bytes of the coarse grids.
    pub grid_bytes: u64,
}

/// One cluster as the directory describes it.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ClusterInfo {
    /// δ: every node of the cut has `e* <= δ`.
    pub threshold: f64,
    /// The largest `e*` in the cut.
    pub max_error: f64,
    /// The index tree (its `records` is the cut's size).
    pub index: TreeRef,
    /// Where its edge lists (north, east, south, west) lie in the adjacency table.
    pub adjacency: [EdgeRange; 4],
}

impl ClusterInfo {
    /// Nodes in the cut.
    pub fn nodes(&self) -> u64 {
        self.index.records.get()
    }
}

/// An entry of a cluster scan.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, PartialOrd, Ord)]
pub struct ScanEntry {
    /// The node's Hilbert key.
    pub key: HilbertKey,
    /// The node's level.
    pub level: u8,
    /// The node's index in the node table ([`Store::node`]).
    pub node: u32,
}

/// An open container (see the module docs for the contract of each constructor).
#[derive(Debug)]
pub struct Store<S: Source = MmapSource> {
    src: S,
    page_size: u32,
    page_count: u64,
    slot: u8,
    commit: CommitRecord,
    header: DatasetHeader,
    clusters: Vec<ClusterInfo>,
    metadata_pages: PageSet,
}

impl Store<MmapSource> {
    /// Opens the container at `path` through a read-only memory map.
    ///
    /// # Safety
    /// While the returned store (or anything borrowed from it) lives, the file must not be
    /// modified or truncated, by this process or any other. A write would change bytes the
    /// store has already checked (undefined behaviour for the zero-copy views). A truncation
    /// raises `SIGBUS` on the next access. `fmrh build` never modifies a container in place,
    /// but a [`Container`] does (its transactions reuse free pages and cut the file's end):
    /// never map a file that a container has open; take [`Container::read`] snapshots
    /// instead. Use [`Store::open_read`] when this cannot be promised.
    pub unsafe fn open(path: &Path) -> Result<Self> {
        let file = File::open(path).map_err(|e| Error::io(path, e))?;
        // SAFETY: our caller upholds the no-modification contract stated above.
        let src = unsafe { MmapSource::new(&file, path) }?;
        Store::from_source(src).map_err(|e| with_path(e, path))
    }
}

impl Store<FileSource> {
    /// Opens the container at `path` for positioned reads (safe; see the module docs).
    pub fn open_read(path: &Path) -> Result<Self> {
        let file = File::open(path).map_err(|e| Error::io(path, e))?;
        let src = FileSource::new(file, path)?;
        Store::from_source(src).map_err(|e| with_path(e, path))
    }
}

impl<T: AsRef<[u8]> + Send + Sync> Store<Bytes<T>> {
    /// Opens a container held in memory.
    pub fn from_bytes(bytes: T) -> Result<Self> {
        Store::from_source(Bytes(bytes))
    }
}

/// Puts `path` into errors that name no file.
pub(crate) fn with_path(e: Error, path: &Path) -> Error {
    match e {
        Error::Corrupt {
            invariant,
            location,
            detail,
        } => Error::Corrupt {
            invariant,
            location: format!("{}: {location}", path.display()),
            detail,
        },
        Error::Input { path: p, reason } if p.as_os_str() == CONTAINER => {
            Error::input(path, reason)
        }
        Error::Unsupported { path: p, reason } if p.as_os_str() == CONTAINER => {
            Error::unsupported(path, reason)
        }
        other => other,
    }
}

/// The placeholder path of errors raised below the file level.
const CONTAINER: &str = "<container>";

/// The outcome of reading one commit slot.
#[derive(Debug)]
pub(crate) enum Slot {
    /// Every byte of the slot's record area is zero.
    Empty,
    /// A valid record.
    Valid(Box<CommitRecord>),
    /// Not a valid record; why.
    Invalid(Error),
}

/// Parses the commit record in `bytes` (at least [`COMMIT_RECORD_LEN`] of them), checking
/// I-1 and I-2. An unknown major version is [`Error::Unsupported`].
pub(crate) fn parse_commit(bytes: &[u8], slot: u8) -> Result<CommitRecord> {
    let at = format!("commit slot {slot}");
    let bad = |d: String| Error::corrupt(invariant::COMMIT_RECORD, at.clone(), d);
    let r = CommitRecord::read_from_prefix(bytes)
        .map(|(r, _)| r)
        .map_err(|_| bad("shorter than a commit record".into()))?;
    if r.magic != MAGIC {
        return Err(bad("bad magic".into()));
    }
    let crc = format::crc32(&bytes[..252]);
    if crc != r.crc.get() {
        return Err(bad(format!(
            "CRC {:#010x} stored, {crc:#010x} computed",
            r.crc.get()
        )));
    }
    if r.major.get() != FORMAT_MAJOR {
        return Err(Error::unsupported(
            CONTAINER,
            format!(
                "format version {}.{}; this reader reads {FORMAT_MAJOR}.x",
                r.major.get(),
                r.minor.get()
            ),
        ));
    }
    let p = r.page_size.get();
    if !format::page_size_is_valid(p) {
        return Err(bad(format!("page size {p}")));
    }
    let len = r.file_length.get();
    if len % u64::from(p) != 0 || len < 2 * u64::from(p) {
        return Err(bad(format!(
            "file length {len} is not two or more whole pages"
        )));
    }
    if r.txn_id.get() == 0 {
        return Err(bad("transaction id 0".into()));
    }
    if !newer_minor(r.minor.get())
        && (r.flags.get() & !format::COMMIT_FLAGS_KNOWN != 0
            || r.reserved0.get() != 0
            || !is_zero(&r.reserved))
    {
        return Err(bad("reserved fields are not zero".into()));
    }
    Ok(r)
}

/// Whether a file's minor version is newer than this reader's: then reserved fields may hold
/// additions this reader does not know (see the versioning policy).
fn newer_minor(minor: u16) -> bool {
    minor > FORMAT_MINOR
}

/// Reads both commit slots. Slot 1 sits one page in; when slot 0 cannot say the page size,
/// every allowed size is tried.
pub(crate) fn read_slots<S: Source + ?Sized>(src: &S) -> Result<[Slot; 2]> {
    let read = |offset: u64| -> Option<Vec<u8>> {
        src.read_at(offset, COMMIT_RECORD_LEN)
            .ok()
            .map(|c| c.into_owned())
    };
    let classify = |bytes: Option<Vec<u8>>, slot: u8| match bytes {
        None => Slot::Invalid(Error::corrupt(
            invariant::FILE_LENGTH,
            format!("commit slot {slot}"),
            "the file ends inside it",
        )),
        Some(b) if is_zero(&b) => Slot::Empty,
        Some(b) => match parse_commit(&b, slot) {
            Ok(r) => Slot::Valid(Box::new(r)),
            Err(e) => Slot::Invalid(e),
        },
    };
    let first = read(0);
    if first.as_ref().is_none_or(|b| b[..4] != MAGIC[..4]) {
        // Not even slot 0's magic: is there a slot 1 anywhere?
        let found = candidate_page_sizes().find_map(|p| {
            let b = read(u64::from(p))?;
            let r = parse_commit(&b, 1).ok()?;
            (r.page_size.get() == p).then_some(r)
        });
        return match found {
            Some(r) => Ok([classify(first, 0), Slot::Valid(Box::new(r))]),
            None => Err(Error::input(
                CONTAINER,
                "not an fmrh container (no commit record with the FMRH magic)",
            )),
        };
    }
    let slot0 = classify(first, 0);
    let slot1 = match &slot0 {
        Slot::Valid(r) => classify(read(u64::from(r.page_size.get())), 1),
        _ => candidate_page_sizes()
            .map(|p| (p, read(u64::from(p))))
            .find_map(|(p, b)| {
                let r = parse_commit(b.as_deref()?, 1).ok()?;
                (r.page_size.get() == p).then_some(Slot::Valid(Box::new(r)))
            })
            .unwrap_or(Slot::Invalid(Error::corrupt(
                invariant::COMMIT_RECORD,
                "commit slot 1",
                "no valid record at any page size",
            ))),
    };
    Ok([slot0, slot1])
}

fn candidate_page_sizes() -> impl Iterator<Item = u32> {
    (MIN_PAGE_SIZE.trailing_zeros()..=MAX_PAGE_SIZE.trailing_zeros()).map(|s| 1u32 << s)
}

/// The slot a reader opens: the valid one with the higher transaction id (slot 0 on a tie).
pub(crate) fn choose_slot(slots: &[Slot; 2]) -> Result<(u8, CommitRecord)> {
    let txn = |s: &Slot| match s {
        Slot::Valid(r) => Some(r.txn_id.get()),
        _ => None,
    };
    let pick = match (txn(&slots[0]), txn(&slots[1])) {
        (Some(a), Some(b)) => Some(if b > a { 1 } else { 0 }),
        (Some(_), None) => Some(0),
        (None, Some(_)) => Some(1),
        (None, None) => None,
    };
    match pick {
        Some(i) => match &slots[i] {
            Slot::Valid(r) => Ok((i as u8, **r)),
            _ => unreachable!("picked a valid slot"),
        },
        None => Err(match &slots[0] {
            Slot::Invalid(e) if !matches!(e, Error::Unsupported { .. }) => match &slots[1] {
                Slot::Invalid(Error::Unsupported { path, reason }) => {
                    Error::unsupported(path.clone(), reason.clone())
                }
                _ => clone_error(e),
            },
            Slot::Invalid(e) => clone_error(e),
            _ => Error::corrupt(
                invariant::COMMIT_RECORD,
                "commit slots",
                "neither slot holds a valid record",
            ),
        }),
    }
}

fn clone_error(e: &Error) -> Error {
    match e {
        Error::Corrupt {
            invariant,
            location,
            detail,
        } => Error::corrupt(invariant, location.clone(), detail.clone()),
        Error::Unsupported { path, reason } => Error::unsupported(path.clone(), reason.clone()),
        Error::Input { path, reason } => Error::input(path.clone(), reason.clone()),
        other => Error::corrupt(invariant::COMMIT_RECORD, "commit slots", other.to_string()),
    }
}

impl<S: Source> Store<S> {
    /// Opens a container from any source (see the module docs for what is checked).
    pub fn from_source(src: S) -> Result<Self> {
        let slots = read_slots(&src)?;
        let (slot, commit) = choose_slot(&slots)?;
        let page_size = commit.page_size.get();
        let committed = commit.file_length.get();
        if src.len() < committed {
            return Err(Error::corrupt(
                invariant::FILE_LENGTH,
                "file",
                format!(
                    "{} bytes; the commit record says {committed} (truncated)",
                    src.len()
                ),
            ));
        }
        let page_count = committed / u64::from(page_size);
        let mut store = Store {
            src,
            page_size,
            page_count,
            slot,
            commit,
            header: placeholder_header(),
            clusters: Vec::new(),
            metadata_pages: PageSet::new(page_count),
        };
        let mut seen = PageSet::new(page_count);
        let header_bytes = store.read_blob(
            &commit.dataset_header,
            tag::DATASET_HEADER,
            160 + 3 * MAX_STRING_LEN as u64,
            "dataset header",
            &mut seen,
        )?;
        store.header = DatasetHeader::decode(&header_bytes)?;
        let dir = store.read_blob(
            &commit.cluster_directory,
            tag::CLUSTER_DIRECTORY,
            (CLUSTER_DIRECTORY_PREFIX + MAX_CLUSTERS * size_of::<ClusterRecord>()) as u64,
            "cluster directory",
            &mut seen,
        )?;
        store.clusters = parse_directory(&dir, &store.header, &commit.adjacency)?;
        let pages = store.pages_checked();
        let expect = |tree: &TreeRef, n: u64, what: &str| -> Result<()> {
            if tree.records.get() != n {
                return Err(Error::corrupt(
                    invariant::TREE_SHAPE,
                    what.to_owned(),
                    format!("{} records, expected {n}", tree.records.get()),
                ));
            }
            Ok(())
        };
        expect(&commit.node_table, store.header.node_count, "node table")?;
        expect(&commit.block_table, store.header.block_count, "block table")?;
        let mut ignore = |_: u64, _: &[u8]| Ok(());
        btree::walk(
            &pages,
            &commit.node_table,
            specs::NODES,
            &mut seen,
            &mut ignore,
        )?;
        btree::walk(
            &pages,
            &commit.block_table,
            specs::BLOCKS,
            &mut seen,
            &mut ignore,
        )?;
        btree::walk(
            &pages,
            &commit.free_list,
            specs::FREE,
            &mut seen,
            &mut ignore,
        )?;
        for c in &store.clusters {
            if c.index.records.get() == 0 {
                return Err(Error::corrupt(
                    invariant::CLUSTER_INDEX,
                    "cluster directory",
                    "a cluster with no nodes",
                ));
            }
            btree::walk(&pages, &c.index, specs::INDEX, &mut seen, &mut ignore)?;
        }
        btree::walk(
            &pages,
            &commit.adjacency,
            specs::ADJACENCY,
            &mut seen,
            &mut ignore,
        )?;
        store.metadata_pages = seen;
        Ok(store)
    }

    /// Page access that checks every page (used while opening).
    fn pages_checked(&self) -> Pages<'_, S> {
        Pages {
            src: &self.src,
            page_size: self.page_size,
            page_count: self.page_count,
            check: true,
        }
    }

    /// Page access for lookups: checks again only when the source is not stable.
    fn pages(&self) -> Pages<'_, S> {
        Pages {
            check: !self.src.stable(),
            ..self.pages_checked()
        }
    }

    /// Reads and checks a blob of at most `max_len` bytes.
    fn read_blob(
        &self,
        blob: &BlobRef,
        tag: [u8; 4],
        max_len: u64,
        name: &str,
        seen: &mut PageSet,
    ) -> Result<Vec<u8>> {
        let len = blob.length.get();
        let per_page = (self.page_size as usize - PAGE_HEADER_LEN) as u64;
        let first = blob.first_page.get();
        let pages = len.div_ceil(per_page);
        if len == 0 || len > max_len || first < 2 || first.saturating_add(pages) > self.page_count {
            return Err(Error::corrupt(
                invariant::DATASET_HEADER,
                name.to_owned(),
                format!("blob of {len} bytes at page {first} does not fit the file"),
            ));
        }
        let mut out = Vec::with_capacity(len as usize);
        let p = self.pages_checked();
        for i in 0..pages {
            let page_no = first + i;
            if !seen.insert(page_no) {
                return Err(Error::corrupt(
                    invariant::PAGE_OWNERSHIP,
                    format!("{name} page {page_no}"),
                    "page reached twice",
                ));
            }
            let page = p.get(page_no, tag)?;
            let h = format::PageHeader::read(&page).ok_or_else(|| {
                Error::corrupt(invariant::PAGE, format!("page {page_no}"), "short page")
            })?;
            let want = (len - i * per_page).min(per_page) as usize;
            if h.count.get() as usize != want || h.level.get() != 0 || h.reserved.get() != 0 {
                return Err(Error::corrupt(
                    invariant::PAGE,
                    format!("{name} page {page_no}"),
                    format!("holds {} bytes, expected {want}", h.count.get()),
                ));
            }
            let end = PAGE_HEADER_LEN + want;
            if !is_zero(&page[end..]) {
                return Err(Error::corrupt(
                    invariant::PAGE,
                    format!("{name} page {page_no}"),
                    "bytes after the content are not zero",
                ));
            }
            out.extend_from_slice(&page[PAGE_HEADER_LEN..end]);
        }
        Ok(out)
    }

    /// Pages and bytes of each section (walks every table once).
    pub fn layout(&self) -> Result<Layout> {
        let pages = self.pages();
        let count = |tree: &TreeRef, spec: TreeSpec| -> Result<u64> {
            let mut seen = PageSet::new(self.page_count);
            btree::walk(&pages, tree, spec, &mut seen, &mut |_, _| Ok(()))?;
            Ok(seen.len())
        };
        let per_page = (self.page_size as usize - PAGE_HEADER_LEN) as u64;
        let blob = |b: &BlobRef| b.length.get().div_ceil(per_page);
        let mut cluster_index_pages = Vec::with_capacity(self.clusters.len());
        for c in &self.clusters {
            cluster_index_pages.push(count(&c.index, specs::INDEX)?);
        }
        let finest = self.domain().finest_level();
        let grid_bytes = self
            .nodes()?
            .iter()
            .filter(|n| n.level < finest)
            .map(|n| u64::from(n.payload_len.get()))
            .sum();
        let block_bytes = self
            .block_records()?
            .iter()
            .map(|b| u64::from(b.payload_len.get()))
            .sum();
        Ok(Layout {
            page_size: self.page_size,
            file_length: self.commit.file_length.get(),
            commit_pages: 2,
            dataset_header_pages: blob(&self.commit.dataset_header),
            cluster_directory_pages: blob(&self.commit.cluster_directory),
            node_table_pages: count(&self.commit.node_table, specs::NODES)?,
            block_table_pages: count(&self.commit.block_table, specs::BLOCKS)?,
            free_list_pages: count(&self.commit.free_list, specs::FREE)?,
            free_pages: self.commit.free_list.records.get(),
            adjacency_pages: count(&self.commit.adjacency, specs::ADJACENCY)?,
            cluster_index_pages,
            block_bytes,
            grid_bytes,
        })
    }

    /// The dataset header.
    pub fn header(&self) -> &DatasetHeader {
        &self.header
    }

    /// The block geometry.
    pub fn domain(&self) -> &Domain {
        &self.header.domain
    }

    /// The commit record in use.
    pub fn commit_record(&self) -> &CommitRecord {
        &self.commit
    }

    /// Which slot (0 or 1) holds the commit record in use.
    pub fn commit_slot(&self) -> u8 {
        self.slot
    }

    /// The transaction id of the state this store reads.
    pub fn txn_id(&self) -> u64 {
        self.commit.txn_id.get()
    }

    /// Bytes per page.
    pub fn page_size(&self) -> u32 {
        self.page_size
    }

    /// Pages of the committed file.
    pub fn page_count(&self) -> u64 {
        self.page_count
    }

    /// The clusters, ascending by threshold.
    pub fn clusters(&self) -> &[ClusterInfo] {
        &self.clusters
    }

    /// The metadata pages found while opening (blobs and every table page).
    pub fn metadata_pages(&self) -> &PageSet {
        &self.metadata_pages
    }

    /// The source.
    pub fn source(&self) -> &S {
        &self.src
    }

    fn cluster(&self, cluster: usize) -> Result<&ClusterInfo> {
        self.clusters.get(cluster).ok_or_else(|| {
            Error::InvalidArgument(format!(
                "cluster {cluster}: the store has {} (0..{})",
                self.clusters.len(),
                self.clusters.len()
            ))
        })
    }

    fn record<R: FromBytes>(&self, tree: &TreeRef, spec: TreeSpec, ordinal: u64) -> Result<R> {
        btree::get_ordinal(&self.pages(), tree, spec, ordinal)?.ok_or_else(|| {
            Error::InvalidArgument(format!(
                "{} has {} records; no record {ordinal}",
                spec.name,
                tree.records.get()
            ))
        })
    }

    /// Every record of `tree`, in order.
    fn all_records<R: FromBytes>(&self, tree: &TreeRef, spec: TreeSpec) -> Result<Vec<R>> {
        let pages = self.pages();
        let mut c = btree::seek(&pages, tree, spec, Seek::Ordinal(0))?;
        let mut out = Vec::with_capacity(tree.records.get() as usize);
        while let Some(r) = c.next_record(&pages, spec.tag)? {
            out.push(r);
        }
        Ok(out)
    }

    /// Node `index` of the node table (Hilbert pre-order; 0 is the root).
    pub fn node(&self, index: u32) -> Result<NodeRecord> {
        self.record(&self.commit.node_table, specs::NODES, u64::from(index))
    }

    /// Every node, in Hilbert pre-order.
    pub fn nodes(&self) -> Result<Vec<NodeRecord>> {
        self.all_records(&self.commit.node_table, specs::NODES)
    }

    /// The record of physical block `(x, y)` (finest-level column and row).
    pub fn block_record(&self, x: u32, y: u32) -> Result<BlockRecord> {
        let d = self.domain();
        let (cols, rows) = d.nodes_across(d.finest_level());
        if x >= cols || y >= rows {
            return Err(Error::InvalidArgument(format!(
                "block ({x}, {y}) is outside the {cols} x {rows} blocks"
            )));
        }
        self.record(
            &self.commit.block_table,
            specs::BLOCKS,
            u64::from(y) * u64::from(cols) + u64::from(x),
        )
    }

    /// Every block record, row-major.
    pub fn block_records(&self) -> Result<Vec<BlockRecord>> {
        self.all_records(&self.commit.block_table, specs::BLOCKS)
    }

    /// The free list (empty in a freshly built file).
    pub fn free_list(&self) -> Result<Vec<FreeEntry>> {
        self.all_records(&self.commit.free_list, specs::FREE)
    }

    /// Reads a payload and checks its CRC (I-9).
    pub fn payload(&self, offset: u64, len: u32, crc: u32) -> Result<Cow<'_, [u8]>> {
        let start = 2 * u64::from(self.page_size);
        let end = offset.checked_add(u64::from(len));
        if offset < start || end.is_none_or(|e| e > self.commit.file_length.get()) {
            return Err(Error::corrupt(
                invariant::PAYLOAD,
                format!("payload at byte {offset}"),
                format!("{len} bytes do not lie within the file's pages"),
            ));
        }
        let bytes = self.src.read_at(offset, len as usize).map_err(|e| {
            Error::corrupt(
                invariant::FILE_LENGTH,
                format!("byte {offset}"),
                e.to_string(),
            )
        })?;
        let actual = format::crc32(&bytes);
        if actual != crc {
            return Err(Error::corrupt(
                invariant::PAYLOAD,
                format!("payload at byte {offset}"),
                format!("CRC {crc:#010x} recorded, {actual:#010x} computed"),
            ));
        }
        Ok(bytes)
    }

    /// Physical block `(x, y)`: its full-resolution samples, checked against their CRC and
    /// read zero-copy from a mapping.
    pub fn block(&self, x: u32, y: u32) -> Result<Block<'_>> {
        let record = self.block_record(x, y)?;
        let bytes = self.payload(
            record.payload_offset.get(),
            record.payload_len.get(),
            record.payload_crc.get(),
        )?;
        let d = self.domain();
        let rect = d
            .footprint(d.finest_level(), x, y)
            .intersect(&d.data_rect())
            .ok_or_else(|| {
                Error::corrupt(
                    invariant::BLOCK_TABLE,
                    format!("block ({x}, {y})"),
                    "outside the data",
                )
            })?;
        let (w, h) = (record.width.get(), record.height.get());
        if u64::from(w) != rect.col1 - rect.col0 + 1 || u64::from(h) != rect.row1 - rect.row0 + 1 {
            return Err(Error::corrupt(
                invariant::BLOCK_TABLE,
                format!("block ({x}, {y})"),
                format!("{w} x {h} samples; its footprint within the data is {rect:?}"),
            ));
        }
        if BlockView::new(&bytes, w, h, record.void_count.get()).is_none() {
            return Err(Error::corrupt(
                invariant::PAYLOAD,
                format!("block ({x}, {y})"),
                format!("{} payload bytes for {w} x {h} samples", bytes.len()),
            ));
        }
        Ok(Block {
            rect,
            record,
            bytes,
        })
    }

    /// The coarse grid of `node` (a node above the finest level), checked against its CRC.
    pub fn grid(&self, node: &NodeRecord) -> Result<Grid<'_>> {
        if node.level >= self.domain().finest_level() {
            return Err(Error::InvalidArgument(
                "finest-level nodes have physical blocks, not grids".into(),
            ));
        }
        let bytes = self.payload(
            node.payload_offset.get(),
            node.payload_len.get(),
            node.payload_crc.get(),
        )?;
        let has_voids = node.flags.get() & NODE_GRID_HAS_VOIDS != 0;
        let size = self.domain().block_size();
        let d = self.domain();
        if !d.exists(node.level, node.x.get(), node.y.get()) {
            return Err(Error::corrupt(
                invariant::NODE_TABLE,
                format!(
                    "node at level {} ({}, {})",
                    node.level,
                    node.x.get(),
                    node.y.get()
                ),
                "not a node of the domain",
            ));
        }
        let dims = payload::grid_dims(d, node.level, node.x.get(), node.y.get());
        if GridView::new(&bytes, size, dims, has_voids).is_none() {
            return Err(Error::corrupt(
                invariant::PAYLOAD,
                format!("grid at byte {}", node.payload_offset.get()),
                format!("{} bytes for a {size} x {size} grid", bytes.len()),
            ));
        }
        Ok(Grid {
            size,
            dims,
            has_voids,
            bytes,
        })
    }

    /// The nodes of `cluster` whose footprint meets the Hilbert range `range` (keys of
    /// finest-level cells), in Hilbert order: one seek, then a contiguous scan.
    pub fn scan_hilbert(
        &self,
        cluster: usize,
        range: RangeInclusive<u64>,
    ) -> Result<HilbertScan<'_, S>> {
        let c = *self.cluster(cluster)?;
        let pages = self.pages();
        let cursor = btree::seek(&pages, &c.index, specs::INDEX, Seek::Key(*range.start()))?;
        Ok(HilbertScan {
            pages,
            cursor,
            lo: *range.start(),
            hi: *range.end(),
            finest: self.domain().finest_level(),
            done: range.is_empty(),
        })
    }

    /// The nodes of `cluster` at ordinal positions `range` (the paper's "codes a to b").
    pub fn scan_codes(&self, cluster: usize, range: Range<u64>) -> Result<CodeScan<'_, S>> {
        let c = *self.cluster(cluster)?;
        let pages = self.pages();
        let cursor = btree::seek(&pages, &c.index, specs::INDEX, Seek::Ordinal(range.start))?;
        Ok(CodeScan {
            pages,
            cursor,
            left: range.end.saturating_sub(range.start),
        })
    }

    /// The adjacency list of `cluster` along `edge` (0 north, 1 east, 2 south, 3 west): the
    /// cut's nodes touching that edge of the data, in order along it.
    pub fn adjacency(&self, cluster: usize, edge: usize) -> Result<Vec<u32>> {
        let c = *self.cluster(cluster)?;
        let range = c.adjacency.get(edge).ok_or_else(|| {
            Error::InvalidArgument(format!("edge {edge}: edges are 0..4 (N, E, S, W)"))
        })?;
        let pages = self.pages();
        let spec = specs::ADJACENCY;
        let tree = &self.commit.adjacency;
        let mut cursor = btree::seek(&pages, tree, spec, Seek::Ordinal(range.first.get()))?;
        let mut out = Vec::new();
        for _ in 0..range.count.get() {
            match cursor.next_record::<S, AdjacencyEntry>(&pages, spec.tag)? {
                Some(e) => out.push(e.node.get()),
                None => break,
            }
        }
        Ok(out)
    }

    /// The samples of `window` (inclusive, inside the data) exactly as stored: voids NaN.
    pub fn read_window(&self, window: SampleRect) -> Result<Heightfield> {
        let d = *self.domain();
        let data = d.data_rect();
        if window.col0 > window.col1
            || window.row0 > window.row1
            || window.intersect(&data) != Some(window)
        {
            return Err(Error::InvalidArgument(format!(
                "window {},{},{},{} is not inside the data 0,0,{},{}",
                window.col0, window.row0, window.col1, window.row1, data.col1, data.row1
            )));
        }
        // Honest files hold at least four bytes per data sample; refuse to allocate more
        // than the file could back.
        if window.samples().saturating_mul(4) > self.commit.file_length.get() {
            return Err(Error::corrupt(
                invariant::DATASET_HEADER,
                "dataset header",
                "the data size exceeds what the file can hold",
            ));
        }
        let (w, h) = (window.col1 - window.col0 + 1, window.row1 - window.row0 + 1);
        let mut samples = vec![f32::NAN; (w * h) as usize];
        let cells = u64::from(d.block_size() - 1);
        let (cols, rows) = d.nodes_across(d.finest_level());
        let bx = |c: u64| ((c / cells) as u32).min(cols - 1);
        let by = |r: u64| ((r / cells) as u32).min(rows - 1);
        for y in by(window.row0)..=by(window.row1) {
            for x in bx(window.col0)..=bx(window.col1) {
                let block = self.block(x, y)?;
                let view = block.view();
                // The samples this block is the first (by x, y) to hold.
                let own = SampleRect {
                    col0: if x == bx(window.col0) {
                        window.col0
                    } else {
                        block.rect.col0 + 1
                    },
                    row0: if y == by(window.row0) {
                        window.row0
                    } else {
                        block.rect.row0 + 1
                    },
                    col1: window.col1.min(block.rect.col1),
                    row1: window.row1.min(block.rect.row1),
                };
                for row in own.row0..=own.row1 {
                    let src_row = (row - block.rect.row0) as usize * view.width as usize;
                    let dst_row = (row - window.row0) as usize * w as usize;
                    for col in own.col0..=own.col1 {
                        let v = view.samples()[src_row + (col - block.rect.col0) as usize].get();
                        samples[dst_row + (col - window.col0) as usize] = v;
                    }
                }
            }
        }
        let mut metadata = self.header.metadata.clone();
        if let Some(g) = metadata.georeference.as_mut() {
            g.origin = [
                g.origin[0] + window.col0 as f64 * g.step[0],
                g.origin[1] + window.row0 as f64 * g.step[1],
            ];
        }
        metadata.source_format = "fmrh".into();
        let hf = Heightfield::new(w as u32, h as u32, samples).map_err(|e| {
            Error::corrupt(invariant::PAYLOAD, "window", format!("stored samples: {e}"))
        })?;
        Ok(hf.with_metadata(metadata))
    }
}

fn placeholder_header() -> DatasetHeader {
    DatasetHeader {
        domain: Domain::new(1, 1, crate::model::DEFAULT_BLOCK_SIZE)
            .unwrap_or_else(|_| unreachable!("1 x 1 is a valid domain")),
        valid_samples: 0,
        void_samples: 0,
        delta_min: 0.0,
        max_error: 0.0,
        node_count: 0,
        block_count: 0,
        cluster_count: 0,
        metadata: Default::default(),
    }
}

/// Parses the cluster directory blob (I-12).
fn parse_directory(
    bytes: &[u8],
    header: &DatasetHeader,
    adjacency: &TreeRef,
) -> Result<Vec<ClusterInfo>> {
    let bad = |d: String| Error::corrupt(invariant::CLUSTER_DIRECTORY, "cluster directory", d);
    if bytes.len() < CLUSTER_DIRECTORY_PREFIX {
        return Err(bad("too short".into()));
    }
    let count = u32::from_le_bytes([bytes[0], bytes[1], bytes[2], bytes[3]]);
    if !is_zero(&bytes[4..8]) {
        return Err(bad("reserved field is not zero".into()));
    }
    if count != header.cluster_count {
        return Err(bad(format!(
            "{count} clusters; the dataset header says {}",
            header.cluster_count
        )));
    }
    let want = CLUSTER_DIRECTORY_PREFIX + count as usize * size_of::<ClusterRecord>();
    if bytes.len() != want {
        return Err(bad(format!("{} bytes for {count} clusters", bytes.len())));
    }
    let mut out = Vec::with_capacity(count as usize);
    let mut next_edge = 0u64;
    for (i, chunk) in bytes[CLUSTER_DIRECTORY_PREFIX..]
        .chunks_exact(size_of::<ClusterRecord>())
        .enumerate()
    {
        let r = ClusterRecord::read_from_bytes(chunk)
            .map_err(|_| bad(format!("cluster {i}: short record")))?;
        let (t, m) = (r.threshold.get(), r.max_error.get());
        if !(t.is_finite() && t >= 0.0 && m.is_finite() && (0.0..=t).contains(&m)) {
            return Err(bad(format!("cluster {i}: threshold {t}, max error {m}")));
        }
        if let Some(prev) = out.last().map(|c: &ClusterInfo| c.threshold) {
            if t <= prev {
                return Err(bad(format!("cluster {i}: threshold {t} after {prev}")));
            }
        } else if t != header.delta_min {
            return Err(bad(format!(
                "the lowest threshold {t} is not delta_min {}",
                header.delta_min
            )));
        }
        for (e, range) in r.adjacency.iter().enumerate() {
            if range.first.get() != next_edge || range.count.get() == 0 {
                return Err(bad(format!(
                    "cluster {i} edge {e}: adjacency run {}+{}, expected to start at {next_edge} and hold a node",
                    range.first.get(),
                    range.count.get()
                )));
            }
            next_edge = next_edge.saturating_add(range.count.get());
        }
        out.push(ClusterInfo {
            threshold: t,
            max_error: m,
            index: r.index,
            adjacency: r.adjacency,
        });
    }
    if next_edge != adjacency.records.get() {
        return Err(bad(format!(
            "the edge lists hold {next_edge} records, the adjacency table {}",
            adjacency.records.get()
        )));
    }
    Ok(out)
}

/// A physical block read from a store.
#[derive(Clone, Debug)]
pub struct Block<'a> {
    /// The samples it holds: its footprint clipped to the data.
    pub rect: SampleRect,
    /// Its record.
    pub record: BlockRecord,
    bytes: Cow<'a, [u8]>,
}

impl Block<'_> {
    /// The samples and stand-ins, in place.
    pub fn view(&self) -> BlockView<'_> {
        let r = &self.record;
        BlockView::new(
            &self.bytes,
            r.width.get(),
            r.height.get(),
            r.void_count.get(),
        )
        .unwrap_or_else(|| unreachable!("the length was checked when the block was read"))
    }

    /// The payload bytes.
    pub fn bytes(&self) -> &[u8] {
        &self.bytes
    }
}

/// A coarse grid read from a store.
#[derive(Clone, Debug)]
pub struct Grid<'a> {
    size: u32,
    dims: (u32, u32),
    has_voids: bool,
    bytes: Cow<'a, [u8]>,
}

impl Grid<'_> {
    /// The heights and void flags, in place.
    pub fn view(&self) -> GridView<'_> {
        GridView::new(&self.bytes, self.size, self.dims, self.has_voids)
            .unwrap_or_else(|| unreachable!("the length was checked when the grid was read"))
    }

    /// The payload bytes.
    pub fn bytes(&self) -> &[u8] {
        &self.bytes
    }
}

/// The iterator of [`Store::scan_hilbert`].
pub struct HilbertScan<'a, S: Source> {
    pages: Pages<'a, S>,
    cursor: btree::Cursor<'a>,
    lo: u64,
    hi: u64,
    finest: u8,
    done: bool,
}

impl<S: Source> HilbertScan<'_, S> {
    /// Index pages read so far, the seek's descent included.
    pub fn pages_read(&self) -> u32 {
        self.cursor.pages_read
    }
}

impl<S: Source> Iterator for HilbertScan<'_, S> {
    type Item = Result<ScanEntry>;

    fn next(&mut self) -> Option<Self::Item> {
        while !self.done {
            let e: IndexEntry = match self.cursor.next_record(&self.pages, specs::INDEX.tag) {
                Ok(Some(e)) => e,
                Ok(None) => break,
                Err(err) => {
                    self.done = true;
                    return Some(Err(err));
                }
            };
            let key = e.key.get();
            if key > self.hi {
                break;
            }
            let level = e.level.min(self.finest);
            let span = HilbertKey::span(self.finest, level);
            if key.saturating_add(span - 1) < self.lo {
                continue; // the entry the seek landed on ends before the range
            }
            return Some(Ok(ScanEntry {
                key: HilbertKey(key),
                level: e.level,
                node: e.node.get(),
            }));
        }
        self.done = true;
        None
    }
}

/// The iterator of [`Store::scan_codes`].
pub struct CodeScan<'a, S: Source> {
    pages: Pages<'a, S>,
    cursor: btree::Cursor<'a>,
    left: u64,
}

impl<S: Source> Iterator for CodeScan<'_, S> {
    type Item = Result<ScanEntry>;

    fn next(&mut self) -> Option<Self::Item> {
        if self.left == 0 {
            return None;
        }
        self.left -= 1;
        match self
            .cursor
            .next_record::<S, IndexEntry>(&self.pages, specs::INDEX.tag)
        {
            Ok(Some(e)) => Some(Ok(ScanEntry {
                key: HilbertKey(e.key.get()),
                level: e.level,
                node: e.node.get(),
            })),
            Ok(None) => {
                self.left = 0;
                None
            }
            Err(err) => {
                self.left = 0;
                Some(Err(err))
            }
        }
    }
}
