//! Transactions: one writer replacing samples, any number of readers on snapshots, and a
//! commit protocol that survives a crash at any instant (`format-spec/container.md` §11).
//!
//! A [`Container`] owns the device ([`Io`]). [`Container::read`] hands out a [`Snapshot`]:
//! a [`Store`] of the state committed when it was taken, which keeps reading that state
//! while later transactions commit, because a commit never writes a page that a committed
//! state still reaches, and reuses a freed page only once no snapshot can reach it.
//! [`Container::begin_write`] hands out the one [`WriteTxn`]; its replacements become
//! visible all together at [`WriteTxn::commit`], or not at all.
//!
//! **Commit.** The model is brought up to date by a [`ModelEditor`] (only the bands that
//! read a changed sample are measured again; pruning and cuts follow). Then:
//! 1. every changed payload (blocks meeting a changed sample, grids of nodes whose footprint
//!    meets one or that are new to the tree) is written to pages that are free and unreachable
//!    from any snapshot, or appended; the tables, blobs and free list are written the same way;
//! 2. if the file grew, `set_len`; then `sync`;
//! 3. the commit record (txn id + 1) goes into the slot the current state does not use; `sync`;
//! 4. if the file shrank (free pages at its end), `set_len`, after the record is durable.
//!
//! Any write, sync or length error poisons the container: every later call fails with
//! [`Error::Poisoned`] until the file is opened again, because after a failed `fsync` the
//! kernel may have dropped the dirty pages, so what is on disk is unknown.
//!
//! **Recovery.** Before its first commit a writer marks the state
//! [`COMMIT_RECOVERY_NEEDED`] (a copy of the current record, txn id + 1). Opening a file
//! whose state carries the mark, or that is longer than its state says, cuts it back to the
//! state's length and syncs; cutting is idempotent, so a crash during recovery is recovered
//! by the next open. [`Container::close`] commits an unmarked copy.

use std::borrow::Cow;
use std::collections::{BTreeMap, HashMap, HashSet};
use std::ops::Deref;
use std::path::Path;
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::{Arc, Mutex, MutexGuard, OnceLock};

use serde::Serialize;
use zerocopy::byteorder::little_endian::{U32, U64};
use zerocopy::IntoBytes;

use super::btree;
use super::io::{FileIo, Io};
use super::source::Source;
use super::write::{self, PageSink, PayloadRefs};
use super::Store;
use crate::error::{Error, Result};
use crate::format::{
    self, payload, tag, BlobRef, CommitRecord, DatasetHeader, FreeEntry, TreeRef,
    COMMIT_PAYLOAD_SLACK, COMMIT_RECORD_LEN, COMMIT_RECOVERY_NEEDED, PAGE_HEADER_LEN,
};
use crate::heightfield::Heightfield;
use crate::model::{ModelEditor, SampleRect};

/// A [`Source`] over an [`Io`], for the states a container hands out.
///
/// Opening a state reads and checks every table and blob page it reaches. The source keeps
/// those page-shaped reads (a power-of-two length from 1024 to 65536 at a multiple of it), and
/// once the state is open it [freezes](IoSource::freeze) them: lookups then borrow pages from
/// memory, zero-copy, instead of making a system call. That is sound because no page a state
/// reaches changes while anything can read that state (§11.5): what the cache serves is what
/// was checked, so the source is `stable` and lookups skip a second check. Payloads are read
/// from the device each time, and [`Store::payload`] checks every one's CRC.
pub struct IoSource<I: Io> {
    io: Arc<I>,
    len: u64,
    filling: Mutex<HashMap<u64, Box<[u8]>>>,
    frozen: OnceLock<HashMap<u64, Box<[u8]>>>,
}

impl<I: Io> IoSource<I> {
    fn new(io: Arc<I>, len: u64) -> Self {
        IoSource {
            io,
            len,
            filling: Mutex::new(HashMap::new()),
            frozen: OnceLock::new(),
        }
    }

    /// Ends the filling: from now on the pages read so far are served from memory and
    /// nothing more is kept.
    fn freeze(&self) {
        let pages = std::mem::take(&mut *lock(&self.filling));
        let _ = self.frozen.set(pages);
    }
}

fn page_shaped(offset: u64, len: usize) -> bool {
    len.is_power_of_two()
        && (format::MIN_PAGE_SIZE as usize..=format::MAX_PAGE_SIZE as usize).contains(&len)
        && offset.is_multiple_of(len as u64)
}

impl<I: Io> Source for IoSource<I> {
    fn len(&self) -> u64 {
        self.len
    }

    fn read_at(&self, offset: u64, len: usize) -> std::io::Result<Cow<'_, [u8]>> {
        if offset.checked_add(len as u64).is_none_or(|e| e > self.len) {
            return Err(std::io::Error::new(
                std::io::ErrorKind::UnexpectedEof,
                format!("{len} bytes at offset {offset} lie past the end"),
            ));
        }
        let frozen = self.frozen.get();
        if let Some(page) = frozen
            .and_then(|f| f.get(&offset))
            .filter(|p| p.len() == len)
        {
            return Ok(Cow::Borrowed(page));
        }
        let mut buf = vec![0u8; len];
        self.io.read_at(offset, &mut buf)?;
        if frozen.is_none() && page_shaped(offset, len) {
            lock(&self.filling)
                .entry(offset)
                .or_insert_with(|| buf.clone().into_boxed_slice());
        }
        Ok(Cow::Owned(buf))
    }

    fn stable(&self) -> bool {
        true
    }
}

/// A committed state as a store.
pub type SnapshotStore<I> = Store<IoSource<I>>;

struct Shared<I: Io> {
    io: Arc<I>,
    current: Mutex<Arc<SnapshotStore<I>>>,
    /// Snapshots alive, by the txn id they read.
    readers: Mutex<BTreeMap<u64, usize>>,
    writer: Mutex<WriterCache>,
    poisoned: AtomicBool,
}

#[derive(Default)]
struct WriterCache {
    /// The model of the current state, kept between transactions.
    editor: Option<ModelEditor>,
}

fn lock<T>(m: &Mutex<T>) -> MutexGuard<'_, T> {
    m.lock().unwrap_or_else(|p| p.into_inner())
}

/// A container file open for transactions (see the module docs).
pub struct Container<I: Io = FileIo> {
    shared: Arc<Shared<I>>,
}

/// What opening did to the file.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize)]
pub struct Recovery {
    /// Whether the state was marked recovery-needed.
    pub marked: bool,
    /// Bytes cut from the end (left by an unfinished transaction).
    pub truncated: u64,
    /// Whether the unused commit slot held a torn record, now zeroed.
    pub slot_cleared: bool,
}

impl Container<FileIo> {
    /// Opens `path` for reading and writing, recovering it if needed.
    pub fn open(path: &Path) -> Result<Container<FileIo>> {
        Container::open_recovering(path).map(|(c, _)| c)
    }

    /// [`Container::open`], also telling what recovery did.
    pub fn open_recovering(path: &Path) -> Result<(Container<FileIo>, Recovery)> {
        let io = FileIo::open(path).map_err(|e| Error::io(path, e))?;
        Container::open_io(io)
    }
}

fn load<I: Io>(io: &Arc<I>) -> Result<SnapshotStore<I>> {
    let len = io.len().map_err(|e| Error::io(io.name(), e))?;
    let store = Store::from_source(IoSource::new(Arc::clone(io), len))
        .map_err(|e| super::with_path(e, io.name()))?;
    store.source().freeze();
    Ok(store)
}

impl<I: Io> Container<I> {
    /// Opens the container on `io`, recovering it if needed (see the module docs).
    pub fn open_io(io: I) -> Result<(Container<I>, Recovery)> {
        let io = Arc::new(io);
        let store = load(&io)?;
        let record = *store.commit_record();
        let committed = record.file_length.get();
        let len = io.len().map_err(|e| Error::io(io.name(), e))?;
        let marked = record.flags.get() & COMMIT_RECOVERY_NEEDED != 0;
        let inactive = 1 - usize::from(store.commit_slot());
        let torn = matches!(
            super::read_slots(store.source())?[inactive],
            super::Slot::Invalid(_)
        );
        let mut recovery = Recovery {
            marked,
            truncated: 0,
            slot_cleared: torn,
        };
        let store = if marked || torn || len > committed {
            let e = |err| Error::io(io.name(), err);
            if torn {
                // An interrupted commit's record: never valid, so clearing it loses nothing.
                let p = u64::from(store.page_size());
                io.write_at(inactive as u64 * p, &[0u8; COMMIT_RECORD_LEN])
                    .map_err(e)?;
            }
            if len > committed {
                io.set_len(committed).map_err(e)?;
                recovery.truncated = len - committed;
            }
            io.sync().map_err(e)?;
            load(&io)?
        } else {
            store
        };
        Ok((
            Container {
                shared: Arc::new(Shared {
                    io,
                    current: Mutex::new(Arc::new(store)),
                    readers: Mutex::new(BTreeMap::new()),
                    writer: Mutex::new(WriterCache::default()),
                    poisoned: AtomicBool::new(false),
                }),
            },
            recovery,
        ))
    }

    fn check(&self) -> Result<()> {
        if self.shared.poisoned.load(Ordering::Acquire) {
            return Err(Error::Poisoned);
        }
        Ok(())
    }

    /// Whether an I/O error has poisoned the container.
    pub fn is_poisoned(&self) -> bool {
        self.shared.poisoned.load(Ordering::Acquire)
    }

    /// A snapshot of the latest committed state. Never blocks on the writer.
    pub fn read(&self) -> Result<Snapshot<I>> {
        self.check()?;
        // Register under the `current` lock, so that a commit cannot compute its reuse limit
        // between our reading `current` and registering.
        let current = lock(&self.shared.current);
        let store = Arc::clone(&current);
        *lock(&self.shared.readers)
            .entry(store.txn_id())
            .or_default() += 1;
        drop(current);
        Ok(Snapshot {
            store,
            shared: Arc::clone(&self.shared),
        })
    }

    /// Starts the write transaction; waits while another is open.
    pub fn begin_write(&self) -> Result<WriteTxn<'_, I>> {
        self.check()?;
        let guard = lock(&self.shared.writer);
        self.check()?;
        let base = Arc::clone(&lock(&self.shared.current));
        Ok(WriteTxn {
            container: self,
            cache: guard,
            base,
            dirty: Vec::new(),
            replacements: 0,
            done: false,
        })
    }

    /// Commits an unmarked copy of the current state (a clean close), if it is marked.
    pub fn close(self) -> Result<()> {
        self.close_ref()
    }

    fn close_ref(&self) -> Result<()> {
        self.check()?;
        let _writer = lock(&self.shared.writer);
        let base = Arc::clone(&lock(&self.shared.current));
        if base.commit_record().flags.get() & COMMIT_RECOVERY_NEEDED != 0 {
            let flags = base.commit_record().flags.get() & COMMIT_PAYLOAD_SLACK;
            self.guard(|| self.copy_record(&base, flags))?;
        }
        Ok(())
    }

    /// Runs `f`, poisoning the container if it fails.
    fn guard<T>(&self, f: impl FnOnce() -> Result<T>) -> Result<T> {
        let r = f();
        if r.is_err() {
            self.shared.poisoned.store(true, Ordering::Release);
        }
        r
    }

    /// Commits the state of `base` again under txn id + 1, with `flags`.
    fn copy_record(&self, base: &SnapshotStore<I>, flags: u32) -> Result<()> {
        let mut r = *base.commit_record();
        r.txn_id = U64::new(r.txn_id.get() + 1);
        self.publish(base, r, flags, r.file_length.get())
    }

    /// Writes `record` with `flags` into the slot `base` does not use, syncs, cuts the file
    /// to `length` if it is shorter, and makes the new state current.
    fn publish(
        &self,
        base: &SnapshotStore<I>,
        mut record: CommitRecord,
        flags: u32,
        length: u64,
    ) -> Result<()> {
        let io = &self.shared.io;
        let e = |err| Error::io(io.name(), err);
        record.flags = U32::new(flags);
        record.crc = U32::new(format::crc32(&record.as_bytes()[..252]));
        // Only the record's bytes: the rest of the slot page stays zero whatever a crash
        // does to this write.
        let p = u64::from(base.page_size());
        let slot = 1 - u64::from(base.commit_slot());
        io.write_at(slot * p, record.as_bytes()).map_err(e)?;
        io.sync().map_err(e)?;
        if length < io.len().map_err(e)? {
            io.set_len(length).map_err(e)?;
        }
        let store = load(io)?;
        *lock(&self.shared.current) = Arc::new(store);
        Ok(())
    }

    /// The smallest txn id a snapshot reads, if any.
    fn oldest_reader(&self) -> Option<u64> {
        lock(&self.shared.readers).keys().next().copied()
    }
}

impl<I: Io> Drop for Container<I> {
    fn drop(&mut self) {
        // Best effort: a failure here leaves the mark, and the next open recovers.
        if !self.is_poisoned() && Arc::strong_count(&self.shared) == 1 {
            let _ = self.close_ref();
        }
    }
}

/// A committed state that stays readable while later transactions commit.
pub struct Snapshot<I: Io> {
    store: Arc<SnapshotStore<I>>,
    shared: Arc<Shared<I>>,
}

impl<I: Io> Deref for Snapshot<I> {
    type Target = SnapshotStore<I>;

    fn deref(&self) -> &SnapshotStore<I> {
        &self.store
    }
}

impl<I: Io> Drop for Snapshot<I> {
    fn drop(&mut self) {
        let mut readers = lock(&self.shared.readers);
        let txn = self.store.txn_id();
        if let Some(n) = readers.get_mut(&txn) {
            *n -= 1;
            if *n == 0 {
                readers.remove(&txn);
            }
        }
    }
}

/// What a commit changed.
#[derive(Clone, Debug, Default, PartialEq, Eq, Serialize)]
pub struct CommitSummary {
    /// The new state's txn id.
    pub txn_id: u64,
    /// Replacements in the transaction.
    pub replacements: u64,
    /// Physical blocks rewritten.
    pub blocks: u64,
    /// Coarse grids rewritten.
    pub grids: u64,
    /// Nodes before and after.
    pub nodes_before: u64,
    /// Nodes after.
    pub nodes_after: u64,
    /// Nodes new to the tree (split), removed from it (merged), or with new statistics.
    pub nodes_added: u64,
    /// Nodes no longer in the tree.
    pub nodes_removed: u64,
    /// Nodes kept whose error, `e*`, heights or valid count changed.
    pub nodes_changed: u64,
    /// Clusters whose cut changed, by index.
    pub clusters_changed: Vec<usize>,
    /// Pages written (payloads, tables, blobs), commit slot excluded.
    pub pages_written: u64,
    /// Of those, pages reused from the free list.
    pub pages_reused: u64,
    /// Pages this commit freed.
    pub pages_freed: u64,
    /// File length after the commit.
    pub file_length: u64,
}

/// The write transaction. Dropping it without [`WriteTxn::commit`] aborts it.
pub struct WriteTxn<'c, I: Io> {
    container: &'c Container<I>,
    cache: MutexGuard<'c, WriterCache>,
    base: Arc<SnapshotStore<I>>,
    dirty: Vec<SampleRect>,
    replacements: u64,
    done: bool,
}

impl<I: Io> WriteTxn<'_, I> {
    /// The state this transaction started from.
    pub fn base(&self) -> &SnapshotStore<I> {
        &self.base
    }

    fn editor(&mut self) -> Result<&mut ModelEditor> {
        if self.cache.editor.is_none() {
            let base = &self.base;
            let hf = base.read_window(base.domain().data_rect())?;
            let thresholds: Vec<f64> = base.clusters().iter().map(|c| c.threshold).collect();
            let editor = ModelEditor::new(hf, base.domain().block_size(), &thresholds)?;
            self.cache.editor = Some(editor);
        }
        self.cache
            .editor
            .as_mut()
            .ok_or_else(|| Error::InvalidArgument("no model".into()))
    }

    /// Replaces the samples of the rectangle at `(col0, row0)` with `patch` (NaN = void).
    /// The rectangle must lie inside the data; nothing is written until commit.
    pub fn replace_region(&mut self, col0: u64, row0: u64, patch: &Heightfield) -> Result<()> {
        self.container.check()?;
        let dirty = self.editor()?.replace(col0, row0, patch)?;
        self.dirty.extend(dirty);
        self.replacements += 1;
        Ok(())
    }

    /// Drops the replacements.
    pub fn abort(mut self) {
        self.abandon();
    }

    fn abandon(&mut self) {
        if !self.done && self.replacements > 0 {
            // The cached model holds the replacements: rebuild it next time.
            self.cache.editor = None;
        }
        self.done = true;
    }

    /// Makes every replacement durable and visible, atomically.
    pub fn commit(mut self) -> Result<CommitSummary> {
        self.container.check()?;
        self.done = true;
        if self.replacements == 0 {
            return Ok(CommitSummary {
                txn_id: self.base.txn_id(),
                file_length: self.base.commit_record().file_length.get(),
                nodes_before: self.base.header().node_count,
                nodes_after: self.base.header().node_count,
                ..CommitSummary::default()
            });
        }
        let container = self.container;
        let base = Arc::clone(&self.base);
        let result = container.guard(|| {
            let marked = base.commit_record().flags.get() & COMMIT_RECOVERY_NEEDED != 0;
            let base = if marked {
                base
            } else {
                let flags = base.commit_record().flags.get() | COMMIT_RECOVERY_NEEDED;
                container.copy_record(&base, flags)?;
                Arc::clone(&lock(&container.shared.current))
            };
            let limit = container
                .oldest_reader()
                .map_or(base.txn_id(), |r| r.min(base.txn_id()));
            let editor = self
                .cache
                .editor
                .as_ref()
                .ok_or_else(|| Error::InvalidArgument("no replacement to commit".into()))?;
            let (record, length, mut summary) =
                write_state(&container.shared.io, &base, editor, &self.dirty, limit)?;
            let flags = COMMIT_RECOVERY_NEEDED | COMMIT_PAYLOAD_SLACK;
            container.publish(&base, record, flags, length)?;
            summary.replacements = self.replacements;
            Ok(summary)
        });
        if result.is_err() {
            self.cache.editor = None;
        }
        result
    }
}

impl<I: Io> Drop for WriteTxn<'_, I> {
    fn drop(&mut self) {
        self.abandon();
    }
}

/// Free pages and the end of the file, for one commit.
struct Alloc {
    /// Free pages and the txn that freed them.
    pool: BTreeMap<u64, u64>,
    /// Pages freed up to this txn id can be reused now.
    reuse_limit: u64,
    /// First page past the end.
    end: u64,
    reused: u64,
    appended: u64,
}

impl Alloc {
    /// `n` consecutive pages: the first reusable run in the pool, else appended.
    fn extent(&mut self, n: u64) -> u64 {
        if let Some(first) = self.reusable_run(n) {
            for p in first..first + n {
                self.pool.remove(&p);
            }
            self.reused += n;
            return first;
        }
        let first = self.end;
        self.end += n;
        self.appended += n;
        first
    }

    fn reusable_run(&self, n: u64) -> Option<u64> {
        let (mut start, mut len) = (0u64, 0u64);
        for (&p, &freed) in &self.pool {
            if freed > self.reuse_limit {
                len = 0;
                continue;
            }
            if len > 0 && p == start + len {
                len += 1;
            } else {
                start = p;
                len = 1;
            }
            if len == n {
                return Some(start);
            }
        }
        None
    }

    /// Drops reusable free pages at the end of the file.
    fn trim(&mut self) {
        while self.end > 2 {
            match self.pool.get(&(self.end - 1)) {
                Some(&freed) if freed <= self.reuse_limit => {
                    self.pool.remove(&(self.end - 1));
                    self.end -= 1;
                }
                _ => break,
            }
        }
    }
}

/// A [`PageSink`] that writes each tree or blob into an extent from the allocator.
struct CommitSink<'a, I: Io> {
    io: &'a I,
    alloc: &'a mut Alloc,
    page_size: u32,
    written: u64,
}

impl<I: Io> CommitSink<'_, I> {
    fn write_page(&mut self, page: u64, bytes: &[u8]) -> Result<()> {
        self.io
            .write_at(page * u64::from(self.page_size), bytes)
            .map_err(|e| Error::io(self.io.name(), e))?;
        self.written += 1;
        Ok(())
    }

    /// Builds a tree of `records` into the pages from `first` on (enough of them are
    /// reserved) and writes them.
    fn tree_at(
        &mut self,
        first: u64,
        records: &[u8],
        record_size: usize,
        keyed: bool,
        tag: [u8; 4],
    ) -> Result<TreeRef> {
        let mut next = first;
        let mut pages = Vec::new();
        let r = btree::build(
            records,
            record_size,
            keyed,
            tag,
            self.page_size,
            &mut next,
            &mut |bytes| {
                pages.push(bytes);
                Ok(())
            },
        )?;
        for (i, bytes) in pages.iter().enumerate() {
            self.write_page(first + i as u64, bytes)?;
        }
        Ok(r)
    }
}

impl<I: Io> PageSink for CommitSink<'_, I> {
    fn tree(
        &mut self,
        records: &[u8],
        record_size: usize,
        keyed: bool,
        tag: [u8; 4],
    ) -> Result<TreeRef> {
        let n = btree::pages_needed(
            (records.len() / record_size) as u64,
            record_size,
            self.page_size,
        );
        let first = self.alloc.extent(n);
        self.tree_at(first, records, record_size, keyed, tag)
    }

    fn blob(&mut self, content: &[u8], tag: [u8; 4]) -> Result<BlobRef> {
        let per_page = self.page_size as usize - PAGE_HEADER_LEN;
        let n = content.len().div_ceil(per_page) as u64;
        let first = self.alloc.extent(n);
        for (i, page) in write::blob_pages(content, tag, first, self.page_size)
            .iter()
            .enumerate()
        {
            self.write_page(first + i as u64, page)?;
        }
        Ok(BlobRef {
            first_page: U64::new(first),
            length: U64::new(content.len() as u64),
        })
    }
}

/// The pages a payload at `offset` of `len` bytes touches.
fn payload_pages(offset: u64, len: u32, p: u64) -> std::ops::Range<u64> {
    if len == 0 {
        return 0..0;
    }
    offset / p..(offset + u64::from(len)).div_ceil(p)
}

/// Writes every page of the state `editor` holds, on top of `base`; returns its commit
/// record (txn id, roots, length; flags and CRC are set when published), the file length,
/// and what changed.
fn write_state<I: Io>(
    io: &Arc<I>,
    base: &SnapshotStore<I>,
    editor: &ModelEditor,
    dirty: &[SampleRect],
    reuse_limit: u64,
) -> Result<(CommitRecord, u64, CommitSummary)> {
    let p = u64::from(base.page_size());
    let txn = base.txn_id() + 1;
    let model = editor.model();
    let d = *model.domain();
    let finest = d.finest_level();
    let tree = model.tree();

    let old_nodes = base.nodes()?;
    let old_blocks = base.block_records()?;
    let mut alloc = Alloc {
        pool: base
            .free_list()?
            .iter()
            .map(|f| (f.page.get(), f.freed_txn.get()))
            .collect(),
        reuse_limit,
        end: base.page_count(),
        reused: 0,
        appended: 0,
    };
    let mut sink = CommitSink {
        io: io.as_ref(),
        alloc: &mut alloc,
        page_size: base.page_size(),
        written: 0,
    };
    let meets = |r: &SampleRect| dirty.iter().any(|x| x.intersect(r).is_some());
    let mut summary = CommitSummary {
        txn_id: txn,
        nodes_before: old_nodes.len() as u64,
        nodes_after: tree.nodes().len() as u64,
        ..CommitSummary::default()
    };

    // Payloads: each new one in its own run of whole pages, zero-padded.
    let place = |sink: &mut CommitSink<'_, I>, bytes: Vec<u8>| -> Result<(u64, u32, u32)> {
        let n = (bytes.len() as u64).div_ceil(p).max(1);
        let first = sink.alloc.extent(n);
        let mut run = bytes;
        let len = run.len() as u32;
        let crc = format::crc32(&run);
        run.resize((n * p) as usize, 0);
        io.write_at(first * p, &run)
            .map_err(|e| Error::io(io.name(), e))?;
        sink.written += n;
        Ok((first * p, len, crc))
    };
    let shapes = write::block_shapes(model);
    let grid_voids = write::grid_void_flags(model);
    let mut kept_payloads: Vec<(u64, u32)> = Vec::new();
    let mut block_ref = Vec::with_capacity(shapes.len());
    for (i, shape) in shapes.iter().enumerate() {
        let old = old_blocks.get(i).ok_or_else(|| {
            Error::corrupt(
                format::invariant::BLOCK_TABLE,
                "block table",
                "fewer records than blocks",
            )
        })?;
        if meets(&shape.rect) {
            block_ref.push(place(&mut sink, write::encode_block(model, shape))?);
            summary.blocks += 1;
        } else {
            let r = (
                old.payload_offset.get(),
                old.payload_len.get(),
                old.payload_crc.get(),
            );
            kept_payloads.push((r.0, r.1));
            block_ref.push(r);
        }
    }
    let old_at: HashMap<(u8, u32, u32), &format::NodeRecord> = old_nodes
        .iter()
        .map(|n| ((n.level, n.x.get(), n.y.get()), n))
        .collect();
    let mut grid_ref = vec![(0u64, 0u32, 0u32); tree.nodes().len()];
    let mut seen = HashSet::with_capacity(tree.nodes().len());
    for (i, n) in tree.nodes().iter().enumerate() {
        let at = (n.level, n.x, n.y);
        seen.insert(at);
        let old = old_at.get(&at);
        match old {
            None => summary.nodes_added += 1,
            Some(o) => {
                if o.static_error.get().to_bits() != n.static_error.to_bits()
                    || o.monotone_error.get().to_bits() != n.monotone_error.to_bits()
                    || o.min_height.get().to_bits() != n.min_height.to_bits()
                    || o.max_height.get().to_bits() != n.max_height.to_bits()
                    || o.valid_samples.get() != n.valid_samples
                {
                    summary.nodes_changed += 1;
                }
            }
        }
        if n.level == finest {
            continue;
        }
        let fp = tree.footprint(i as u32);
        match old {
            Some(o) if o.level < finest && !meets(&fp) => {
                let r = (
                    o.payload_offset.get(),
                    o.payload_len.get(),
                    o.payload_crc.get(),
                );
                kept_payloads.push((r.0, r.1));
                grid_ref[i] = r;
            }
            _ => {
                let bytes = write::encode_grid(model, i as u32, grid_voids[i]);
                let (gw, gh) = payload::grid_dims(&d, n.level, n.x, n.y);
                debug_assert_eq!(bytes.len() as u64, payload::grid_len(gw, gh, grid_voids[i]));
                grid_ref[i] = place(&mut sink, bytes)?;
                summary.grids += 1;
            }
        }
    }
    summary.nodes_removed = old_nodes
        .iter()
        .filter(|n| !seen.contains(&(n.level, n.x.get(), n.y.get())))
        .count() as u64;

    // Which clusters' cuts changed.
    for (c, cluster) in model.clusters().iter().enumerate() {
        let new: Vec<(u64, u8)> = cluster
            .nodes
            .iter()
            .map(|&i| (tree.node(i).key.0, tree.node(i).level))
            .collect();
        let old: Vec<(u64, u8)> = match base.clusters().get(c) {
            Some(info) => base
                .scan_codes(c, 0..info.nodes())?
                .map(|e| e.map(|e| (e.key.0, e.level)))
                .collect::<Result<_>>()?,
            None => Vec::new(),
        };
        if new != old {
            summary.clusters_changed.push(c);
        }
    }

    // Tables and blobs.
    let header = DatasetHeader::of_model(model, &base.header().metadata).encode();
    let dataset_header = sink.blob(&header, tag::DATASET_HEADER)?;
    let refs = PayloadRefs {
        grid: grid_ref,
        block: block_ref,
        grid_voids,
        shapes,
    };
    let roots = write::write_tables(model, &refs, &mut sink)?;
    let written = sink.written;

    // What this commit frees: the old state's metadata pages, and payload pages no kept
    // payload touches.
    let mut kept_pages = HashSet::new();
    for &(off, len) in &kept_payloads {
        kept_pages.extend(payload_pages(off, len, p));
    }
    let mut freed: Vec<u64> = Vec::new();
    for page in 2..base.page_count() {
        if base.metadata_pages().contains(page) {
            freed.push(page);
        }
    }
    let mut old_payload_pages = HashSet::new();
    for n in &old_nodes {
        old_payload_pages.extend(payload_pages(
            n.payload_offset.get(),
            n.payload_len.get(),
            p,
        ));
    }
    for b in &old_blocks {
        old_payload_pages.extend(payload_pages(
            b.payload_offset.get(),
            b.payload_len.get(),
            p,
        ));
    }
    freed.extend(
        old_payload_pages
            .into_iter()
            .filter(|pg| !kept_pages.contains(pg)),
    );
    summary.pages_freed = freed.len() as u64;
    for page in freed {
        alloc.pool.insert(page, txn);
    }
    alloc.trim();

    // The free list, last: its pages come from the pool when that leaves the page count it
    // needs unchanged, else from the end.
    let entries = |pool: &BTreeMap<u64, u64>| -> Vec<u8> {
        let mut out = Vec::with_capacity(pool.len() * size_of::<FreeEntry>());
        for (&page, &freed_txn) in pool {
            out.extend_from_slice(
                FreeEntry {
                    page: U64::new(page),
                    freed_txn: U64::new(freed_txn),
                }
                .as_bytes(),
            );
        }
        out
    };
    let need = |count: usize| btree::pages_needed(count as u64, size_of::<FreeEntry>(), p as u32);
    let k = need(alloc.pool.len());
    let mut free_list = btree::empty(size_of::<FreeEntry>());
    if k > 0 {
        let first = match alloc.reusable_run(k) {
            Some(first) if need(alloc.pool.len() - k as usize) == k => {
                for pg in first..first + k {
                    alloc.pool.remove(&pg);
                }
                alloc.reused += k;
                first
            }
            _ => {
                let first = alloc.end;
                alloc.end += k;
                alloc.appended += k;
                first
            }
        };
        let records = entries(&alloc.pool);
        let mut sink = CommitSink {
            io: io.as_ref(),
            alloc: &mut alloc,
            page_size: p as u32,
            written: 0,
        };
        free_list = sink.tree_at(
            first,
            &records,
            size_of::<FreeEntry>(),
            true,
            tag::FREE_LIST,
        )?;
    }
    summary.pages_written = written + k;
    summary.pages_reused = alloc.reused;

    let length = alloc.end * p;
    summary.file_length = length;
    let record = write::commit_record(
        p as u32,
        txn,
        length,
        dataset_header,
        roots.cluster_directory,
        roots.node_table,
        roots.block_table,
        free_list,
        roots.adjacency,
    );
    // Step 2: a grown file gets its length before anything refers to it.
    let e = |err| Error::io(io.name(), err);
    if length > io.len().map_err(e)? {
        io.set_len(length).map_err(e)?;
    }
    io.sync().map_err(e)?;
    Ok((record, length, summary))
}
