//! The life cycle of a container open for transactions: open and recover, hand out snapshots
//! and the one write transaction, publish commit records, close cleanly.

use std::collections::BTreeMap;
use std::ops::Deref;
use std::path::Path;
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::{Arc, Mutex, MutexGuard};

use serde::Serialize;

use super::cache::IoSource;
use super::commit::{write_state, CommitSummary};
use super::{lock, SnapshotStore};
use crate::error::{Error, Result};
use crate::format::commit::Slot;
use crate::format::{
    CommitRecord, COMMIT_PAYLOAD_SLACK, COMMIT_RECORD_LEN, COMMIT_RECOVERY_NEEDED,
};
use crate::heightfield::Heightfield;
use crate::model::{ModelEditor, SampleRect};
use crate::store::io::{FileIo, Io};
use crate::store::{slots, Store};

struct Shared<I: Io> {
    io: Arc<I>,
    /// The latest state readers may snapshot.
    current: Mutex<Arc<SnapshotStore<I>>>,
    /// Snapshots alive, by the txn id they read.
    readers: Mutex<BTreeMap<u64, usize>>,
    writer: Mutex<WriterCache>,
    poisoned: AtomicBool,
    /// The most stored bytes a commit gives its metadata bundle (format §6.7).
    bundle_limit: std::sync::atomic::AtomicU64,
    /// Commits keep the file at least this many bytes long ([`Container::set_min_length`]).
    min_length: std::sync::atomic::AtomicU64,
}

#[derive(Default)]
struct WriterCache {
    /// The model of the current state, kept between transactions.
    editor: Option<ModelEditor>,
}

/// A container file open for transactions: one writer, any number of snapshot readers.
///
/// ```
/// # fn main() -> fmrh::Result<()> {
/// # let dir = tempfile::tempdir().unwrap();
/// # let path = dir.path().join("t.fmrh");
/// # let ramp = fmrh::Heightfield::from_fn(130, 130, |x, _| x as f32)?;
/// # fmrh::create(&path, ramp, &fmrh::CreateOptions::default())?;
/// let container = fmrh::raw::Container::open(&path)?;
/// let before = container.read()?; // a snapshot: it keeps reading this state
/// let mut txn = container.begin_write()?;
/// let pit = fmrh::Heightfield::from_fn(10, 10, |_, _| -5.0)?;
/// txn.replace_region(60, 60, &pit)?;
/// let summary = txn.commit()?; // durable and visible, all at once
/// assert!(summary.blocks > 0);
/// let after = container.read()?;
/// assert_eq!(after.read_window(fmrh::types::SampleRect { col0: 60, row0: 60, col1: 60, row1: 60 })?.samples(), &[-5.0]);
/// assert_eq!(before.read_window(fmrh::types::SampleRect { col0: 60, row0: 60, col1: 60, row1: 60 })?.samples(), &[60.0]);
/// drop((before, after));
/// container.close()?;
/// # Ok(()) }
/// ```
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
    /// Opens `path` for reading and writing, recovering it if needed. Takes an exclusive
    /// lock: a second writer, in any process, is refused until this one is dropped.
    pub fn open(path: &Path) -> Result<Container<FileIo>> {
        Container::open_recovering(path).map(|(c, _)| c)
    }

    /// [`Container::open`], also telling what recovery did.
    pub fn open_recovering(path: &Path) -> Result<(Container<FileIo>, Recovery)> {
        let io = FileIo::open(path).map_err(|e| Error::io(path, e))?;
        Container::open_io(io)
    }
}

/// Opens the durable state of `io`, its metadata pages cached.
fn load<I: Io>(io: &Arc<I>) -> Result<SnapshotStore<I>> {
    let len = io.len().map_err(|e| Error::io(io.name(), e))?;
    let store = Store::from_source_walked(IoSource::new(Arc::clone(io), len))?;
    store.source().freeze();
    Ok(store)
}

impl<I: Io> Container<I> {
    /// Opens the container on `io`, recovering it if needed (format §11.4).
    pub fn open_io(io: I) -> Result<(Container<I>, Recovery)> {
        let io = Arc::new(io);
        let store = load(&io)?;
        let record = *store.commit_record();
        if !record.payloads_coded() {
            // Before anything is written, recovery included: a 2.x writer's coded payloads
            // beside a 1.x file's raw ones would be misread by either reader.
            return Err(Error::unsupported(
                io.name(),
                format!(
                    "format {}.{} is read-only for this fmrh (it writes format {}): rebuild \
                     it to change it, e.g. `fmrh extract FILE -o all.f32` then `fmrh build \
                     all.json -o NEW.fmrh`",
                    record.major.get(),
                    record.minor.get(),
                    crate::format::FORMAT_MAJOR
                ),
            ));
        }
        let committed = record.file_length.get();
        let len = io.len().map_err(|e| Error::io(io.name(), e))?;
        let marked = record.has_flag(COMMIT_RECOVERY_NEEDED);
        let inactive = 1 - usize::from(store.commit_slot());
        let torn = matches!(
            slots::read_slots(store.source())?[inactive],
            Slot::Invalid { .. }
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
                    bundle_limit: std::sync::atomic::AtomicU64::new(
                        crate::format::bundle::COMMIT_BUNDLE_LIMIT,
                    ),
                    min_length: std::sync::atomic::AtomicU64::new(0),
                }),
            },
            recovery,
        ))
    }

    fn check(&self) -> Result<()> {
        if self.shared.poisoned.load(Ordering::Acquire) {
            return Err(Error::Poisoned {
                path: self.shared.io.name().to_path_buf(),
            });
        }
        Ok(())
    }

    /// Sets the most stored bytes later commits give the metadata bundle (format §6.7;
    /// 1 MiB unless set: larger than a build's 32 KiB, because a commit writes every table
    /// again, and the bundle is much the smaller). Larger metadata, or any
    /// with 0, is written in pages of its own. Either way the commit is the same
    /// copy-on-write protocol: this changes bytes, not atomicity or durability.
    pub fn set_bundle_limit(&self, bytes: u64) {
        self.shared.bundle_limit.store(bytes, Ordering::Relaxed);
    }

    /// Makes later commits keep the file at least `bytes` long: free pages at its end stay
    /// in the free list instead of being cut off. A dataset (`format-spec/dataset.md` §4)
    /// sets it to the length of the tile state its manifest pins, so that state stays whole
    /// (a state needs the file to be as long as its record says) until the manifest moves.
    pub fn set_min_length(&self, bytes: u64) {
        self.shared.min_length.store(bytes, Ordering::Relaxed);
    }

    /// Drops the container **without** the clean close: the current state keeps its
    /// recovery mark (format §11.2), and the state the mark's commit was based on stays in
    /// the other slot. A dataset whose manifest commit failed abandons the tiles it committed,
    /// so that the state its manifest still pins is not overwritten by a clean copy of the
    /// orphaned new one. The next writer's open recovers the file as after a crash.
    pub fn abandon(self) {
        self.shared.poisoned.store(true, Ordering::Release);
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

    /// Closes the container cleanly: if the current state is marked recovery-needed (any
    /// commit marks it, format §11.2), commits an unmarked copy of it, which takes the next txn
    /// id. Returns the txn id of the state the file holds afterwards: what `fmrh info` shows.
    pub fn close(self) -> Result<u64> {
        self.close_ref()
    }

    fn close_ref(&self) -> Result<u64> {
        self.check()?;
        let _writer = lock(&self.shared.writer);
        let base = Arc::clone(&lock(&self.shared.current));
        let record = base.commit_record();
        if !record.has_flag(COMMIT_RECOVERY_NEEDED) {
            return Ok(base.txn_id());
        }
        let flags = record.flags.get() & COMMIT_PAYLOAD_SLACK;
        let copy = record.copy_as(base.next_txn_id()?, flags);
        let store = self.guard(|| self.publish(&base, &copy))?;
        let txn = store.txn_id();
        *lock(&self.shared.current) = Arc::new(store);
        Ok(txn)
    }

    /// Runs `f`, poisoning the container if it fails.
    fn guard<T>(&self, f: impl FnOnce() -> Result<T>) -> Result<T> {
        let r = f();
        if r.is_err() {
            self.shared.poisoned.store(true, Ordering::Release);
        }
        r
    }

    /// Writes `record` into the slot `base` does not use, syncs, cuts the file to the
    /// record's length if it is shorter, and opens the new state. The caller decides whether
    /// readers see it.
    fn publish(&self, base: &SnapshotStore<I>, record: &CommitRecord) -> Result<SnapshotStore<I>> {
        let io = &self.shared.io;
        let e = |err| Error::io(io.name(), err);
        // Only the record's bytes: the rest of the slot page stays zero whatever a crash
        // does to this write.
        let p = u64::from(base.page_size());
        let slot = 1 - u64::from(base.commit_slot());
        io.write_at(slot * p, zerocopy::IntoBytes::as_bytes(record))
            .map_err(e)?;
        io.sync().map_err(e)?;
        let length = record.file_length.get();
        if length < io.len().map_err(e)? {
            io.set_len(length).map_err(e)?;
        }
        load(io)
    }

    /// The smallest txn id a snapshot reads, if any.
    fn oldest_reader(&self) -> Option<u64> {
        lock(&self.shared.readers).keys().next().copied()
    }

    /// `L` of format §11.3 for a commit on the durable state `base`: the oldest state that a
    /// snapshot of this container or a registered reader in another process holds, or `base`.
    /// Asked after `base` is durable, so a reader that registers later and finds `base` still
    /// the latest is counted, and one that finds a newer state does not read `base`.
    fn reuse_limit(&self, base: u64) -> Result<u64> {
        let io = &self.shared.io;
        let outside = io
            .oldest_reader(base)
            .map_err(|e| Error::io(io.name(), e))?;
        Ok([Some(base), self.oldest_reader(), outside]
            .into_iter()
            .flatten()
            .min()
            .unwrap_or(base))
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
            let samples = base.read_window(base.domain().data_rect())?;
            self.cache.editor = Some(editor_of(base, samples)?);
        }
        self.cache
            .editor
            .as_mut()
            .ok_or_else(|| Error::Internal("the model editor was not kept".into()))
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
            // Step 0: mark the durable state. Readers keep snapshotting `base` itself (same
            // pages, lower txn id) until the commit below is published.
            let base = if base.commit_record().has_flag(COMMIT_RECOVERY_NEEDED) {
                base
            } else {
                let r = base.commit_record();
                let marked = r.copy_as(base.next_txn_id()?, r.flags.get() | COMMIT_RECOVERY_NEEDED);
                Arc::new(container.publish(&base, &marked)?)
            };
            let limit = container.reuse_limit(base.txn_id())?;
            let editor = self
                .cache
                .editor
                .as_ref()
                .ok_or_else(|| Error::Internal("a commit without its model".into()))?;
            let (record, mut summary) = write_state(
                &container.shared.io,
                &base,
                editor,
                &self.dirty,
                limit,
                container.shared.bundle_limit.load(Ordering::Relaxed),
                container
                    .shared
                    .min_length
                    .load(Ordering::Relaxed)
                    .div_ceil(u64::from(base.page_size())),
            )?;
            let store = container.publish(&base, &record)?;
            *lock(&container.shared.current) = Arc::new(store);
            summary.replacements = self.replacements;
            summary.reuse_limit = limit;
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

/// The model of the state `store` holds, ready for edits: its samples `hf` (read whole from
/// it), rebuilt with the file's block size, thresholds, precision and thinning, which is the
/// model a fresh build of the same samples with the same options makes (the editor's
/// invariant).
pub(crate) fn editor_of<S: crate::store::Source>(
    store: &Store<S>,
    hf: crate::heightfield::Heightfield,
) -> Result<ModelEditor> {
    let thresholds: Vec<f64> = store.clusters().iter().map(|c| c.threshold).collect();
    ModelEditor::new(
        hf,
        store.domain().block_size(),
        &thresholds,
        store.header().precision,
        store.header().thinning(),
    )
}
