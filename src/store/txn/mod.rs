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
//! **Commit.** The model is brought up to date by a [`crate::model::ModelEditor`] (only the
//! bands that read a changed sample are measured again; pruning and cuts follow). Then:
//! 1. every changed payload (blocks meeting a changed sample, grids of nodes whose footprint
//!    meets one or that are new to the tree) is written to pages that are free and unreachable
//!    from any snapshot, or appended; the tables, blobs and free list are written the same way;
//! 2. if the file grew, `set_len`; then `sync`;
//! 3. the commit record (txn id + 1) goes into the slot the current state does not use; `sync`;
//! 4. if the file shrank (free pages at its end), `set_len`, after the record is durable.
//!
//! Any write, sync or length error poisons the container: every later call fails with
//! [`crate::Error::Poisoned`] until the file is opened again, because after a failed `fsync`
//! the kernel may have dropped the dirty pages, so what is on disk is unknown.
//!
//! **Recovery.** Before its first commit a writer marks the durable state
//! `RECOVERY_NEEDED` (a copy of the current record, txn id + 1). The mark changes no
//! content, and readers never see it as a state of its own: snapshots keep reading the state
//! it copies until the commit that follows it is published, so every txn id a snapshot reads
//! is one a commit returned (or the one the container opened). Opening a file whose state
//! carries the mark, or that is longer than its state says, cuts it back to the state's
//! length and syncs; cutting is idempotent, so a crash during recovery is recovered by the
//! next open. [`Container::close`] commits an unmarked copy.
//!
//! Rooms: `cache` (the page cache a state is read through), `alloc` (which pages a commit may
//! write), `clean` (which kept payloads a commit moves off sparse pages), `commit` (one
//! commit's pages), `container` (the life cycle: open, recover, snapshots, transactions,
//! publish, close).

mod alloc;
mod cache;
mod clean;
mod commit;
mod compact;
mod container;

use std::sync::{Mutex, MutexGuard};

pub use cache::IoSource;
pub use commit::CommitSummary;
pub use compact::{compact, CompactOptions, Compacted};
pub(crate) use compact::rewrite;
pub use container::{Container, Recovery, Snapshot, WriteTxn};

#[allow(unused_imports)]
use super::{io::Io, Store};

/// A committed state as a store.
pub type SnapshotStore<I> = Store<IoSource<I>>;

/// Locks `m`; a poisoned lock is still usable (every holder leaves consistent state).
fn lock<T>(m: &Mutex<T>) -> MutexGuard<'_, T> {
    m.lock().unwrap_or_else(|p| p.into_inner())
}
