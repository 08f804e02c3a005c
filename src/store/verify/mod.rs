//! The validator: every numbered invariant of `format-spec/container.md`, checked by name.
//!
//! Verification is an explicit, typed operation. [`verify`] returns a [`VerifyReport`] with
//! one [`CheckReport`] per [`Invariant`]: passed, failed (with located messages), or skipped
//! because a check it depends on failed. [`VerifyMode::Fast`] checks the commit slots, every
//! page, the shape of every table, page ownership, every payload's CRC and zero gaps, and the
//! records' own consistency (`structure`, `payloads`). [`VerifyMode::Full`] adds the
//! semantics (`full`): every cluster is the cut it claims to be (cover, bound, minimality),
//! the adjacency lists are right, and the whole model (errors, ranges, grids, void stand-ins)
//! equals a fresh build from the physical blocks.
//!
//! Only a file that cannot be recognised at all (no commit record with the magic, a newer
//! major version) or that the operating system fails to read is an `Err`: the CLI's exit
//! code 2 or 1. Anything else is a report. The validator never panics and never hangs (every
//! page is visited at most once). It never allocates from a stored size it has not first
//! checked against the file's real length.

mod full;
mod payloads;
mod structure;

use serde::Serialize;

use super::slots::{latest_txn, no_state, read_slots};
use super::{Source, Store};
use crate::error::{Error, Result};
use crate::format::commit::{self, Slot};
use crate::format::{
    tables, BlockRecord, FreePage, IndexEntry, Invariant, NodeRecord, COMMIT_RECORD_LEN,
};

/// At most this many messages are kept per check (all are counted).
const MAX_MESSAGES: usize = 20;

/// How much [`verify`] checks.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize)]
#[serde(rename_all = "lowercase")]
pub enum VerifyMode {
    /// Structure: slots, pages, tables, ownership, payload checksums, records.
    Fast,
    /// Structure and semantics: cuts, adjacency, every error recomputed from the blocks.
    Full,
}

/// The outcome of one check.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize)]
#[serde(rename_all = "lowercase")]
pub enum CheckStatus {
    /// The invariant holds.
    Passed,
    /// The invariant is broken; see the messages.
    Failed,
    /// Not checked: a check it depends on failed, or the mode does not include it.
    Skipped,
    /// Not decided: it is about the file around the state (its length, the other commit
    /// slot), and a writer had the file open or committed while it was checked, so what was
    /// read may be a commit in progress. Run the validator again.
    Busy,
}

/// One invariant's result.
#[derive(Clone, Debug, Serialize)]
pub struct CheckReport {
    /// The invariant (`I-1`, `I-2`, ... in JSON).
    pub id: Invariant,
    /// What the invariant is about.
    pub name: &'static str,
    /// Passed, failed or skipped.
    pub status: CheckStatus,
    /// How many failures were found.
    pub failure_count: u64,
    /// The first failures, each located.
    pub failures: Vec<String>,
}

/// The result of [`verify`].
#[derive(Clone, Debug, Serialize)]
pub struct VerifyReport {
    /// Fast or full.
    pub mode: VerifyMode,
    /// Whether every check that ran passed and none was skipped for a failure.
    pub valid: bool,
    /// The transaction id of the commit record in use, if one was valid.
    pub txn_id: Option<u64>,
    /// Whether some check could not be decided because a writer was committing (see
    /// [`CheckStatus::Busy`]): the state itself was checked, run again for the rest.
    pub busy: bool,
    /// Whether the validator registered the state it read, so that no writer in another
    /// process could reuse its pages meanwhile (format §11.6).
    pub registered: bool,
    /// Bytes in the file.
    pub file_length: u64,
    /// One entry per invariant, in id order.
    pub checks: Vec<CheckReport>,
}

/// The reports being filled in, one per invariant (a container's, or a dataset's).
pub(crate) struct Checks {
    reports: Vec<CheckReport>,
}

impl Checks {
    fn new() -> Checks {
        Checks::of(&Invariant::ALL)
    }

    /// One report per invariant of `ids`, each skipped until checked.
    pub(crate) fn of(ids: &[Invariant]) -> Checks {
        Checks {
            reports: ids
                .iter()
                .map(|&id| CheckReport {
                    id,
                    name: id.name(),
                    status: CheckStatus::Skipped,
                    failure_count: 0,
                    failures: Vec::new(),
                })
                .collect(),
        }
    }

    /// Whether `id` is one of the invariants these checks report.
    pub(crate) fn knows(&self, id: Invariant) -> bool {
        self.reports.iter().any(|r| r.id == id)
    }

    fn report(&mut self, id: Invariant) -> &mut CheckReport {
        let at = match self.reports.iter().position(|r| r.id == id) {
            Some(at) => at,
            // Never lose a finding: an invariant outside the list gets a report of its own.
            None => {
                self.reports.push(CheckReport {
                    id,
                    name: id.name(),
                    status: CheckStatus::Skipped,
                    failure_count: 0,
                    failures: Vec::new(),
                });
                self.reports.len() - 1
            }
        };
        &mut self.reports[at]
    }

    /// The reports, in the order of the list they were made from.
    pub(crate) fn into_reports(self) -> Vec<CheckReport> {
        self.reports
    }

    /// Marks `id` passed, unless it already failed.
    pub(crate) fn pass(&mut self, id: Invariant) {
        let r = self.report(id);
        if r.status == CheckStatus::Skipped {
            r.status = CheckStatus::Passed;
        }
    }

    /// Records a failure of `id`.
    pub(crate) fn fail(&mut self, id: Invariant, message: String) {
        let r = self.report(id);
        r.status = CheckStatus::Failed;
        r.failure_count += 1;
        if r.failures.len() < MAX_MESSAGES {
            r.failures.push(message);
        }
    }

    /// Takes in the file-level checks `other` made: as they are, or, when `busy`, with every
    /// failure turned into [`CheckStatus::Busy`].
    fn merge(&mut self, other: Checks, busy: bool) {
        for theirs in other.reports {
            let mine = self.report(theirs.id);
            match theirs.status {
                CheckStatus::Failed if busy => {
                    if mine.status != CheckStatus::Failed {
                        mine.status = CheckStatus::Busy;
                    }
                    // The messages would blame damage or an interrupted transaction; neither
                    // is known while a writer runs.
                    mine.failures.push(format!(
                        "not decided: {} while a writer had the file open or committed; run \
                         again",
                        match theirs.id {
                            Invariant::FileLength => "the file's length changed",
                            _ => "the other commit slot was being written",
                        }
                    ));
                }
                CheckStatus::Failed => {
                    mine.status = CheckStatus::Failed;
                    mine.failure_count += theirs.failure_count;
                    mine.failures.extend(theirs.failures);
                }
                CheckStatus::Passed if mine.status == CheckStatus::Skipped => {
                    mine.status = CheckStatus::Passed;
                }
                _ => {}
            }
            mine.failures.truncate(MAX_MESSAGES);
        }
    }

    /// Whether any check has failed so far.
    pub(crate) fn any_failed(&self) -> bool {
        self.reports.iter().any(|r| r.status == CheckStatus::Failed)
    }

    /// Takes `result` in: a corruption becomes a failure of its invariant (`Ok(None)`);
    /// any other error (I/O, a bug) stops the verification.
    pub(crate) fn absorb<T>(&mut self, result: Result<T>) -> Result<Option<T>> {
        match result {
            Ok(v) => Ok(Some(v)),
            // A dataset's invariant (a tile's pin) is the dataset validator's to report.
            Err(Error::Corrupt {
                invariant,
                location,
                detail,
                ..
            }) if self.knows(invariant) => {
                self.fail(invariant, format!("{location}: {detail}"));
                Ok(None)
            }
            Err(e) => Err(e),
        }
    }

    fn finish(self, mode: VerifyMode, txn_id: Option<u64>, file_length: u64) -> VerifyReport {
        let busy = self.reports.iter().any(|r| r.status == CheckStatus::Busy);
        let valid = !self.any_failed()
            && !busy
            && self.reports.iter().any(|r| r.status == CheckStatus::Passed);
        VerifyReport {
            mode,
            valid,
            txn_id,
            busy,
            registered: false,
            file_length,
            checks: self.reports,
        }
    }
}

/// Verifies the container in `src` (see the module docs). `Err` only for a file that is not
/// a recognisable fmrh container, one of a newer major version, or a failed read.
///
/// **While a writer commits.** The store registers the state it verifies (format §11.6), so
/// the state's own checks read one consistent state whatever a writer in another process
/// does. What lies around the state (the file's length, the other commit slot, I-3 and I-4)
/// is the writer's to change while it commits: if such a check fails while a writer has the
/// file open, or after a newer state was published, it is reported [`CheckStatus::Busy`]
/// rather than failed, and the report is not valid.
pub fn verify<S: Source>(src: S, mode: VerifyMode) -> Result<VerifyReport> {
    verify_with_progress(src, mode, &crate::progress::Silent)
}

/// As [`verify`], telling `progress` how its long phases advance (payload bytes checked;
/// with [`VerifyMode::Full`], blocks assembled and levels re-measured).
pub fn verify_with_progress<S: Source>(
    src: S,
    mode: VerifyMode,
    progress: &dyn crate::progress::Progress,
) -> Result<VerifyReport> {
    verify_at(src, None, mode, progress)
}

/// As [`verify_with_progress`], of the state `pin` names (a dataset's tile,
/// `format-spec/dataset.md` §4). When a newer state of the file exists (a dataset commit
/// that was interrupted, or is running), the checks around the state (I-3, I-4) are left
/// out: the other slot is the newer state's.
pub fn verify_pinned<S: Source>(
    src: S,
    pin: crate::format::manifest::StatePin,
    mode: VerifyMode,
    progress: &dyn crate::progress::Progress,
) -> Result<VerifyReport> {
    verify_at(src, Some(pin), mode, progress)
}

fn verify_at<S: Source>(
    src: S,
    pin: Option<crate::format::manifest::StatePin>,
    mode: VerifyMode,
    progress: &dyn crate::progress::Progress,
) -> Result<VerifyReport> {
    let file_length = src.len();
    let mut checks = Checks::new();
    let slots = read_slots(&src)?;
    let chosen = match pin {
        None => commit::choose(&slots),
        Some(pin) => {
            let found = (0u8..)
                .zip(&slots)
                .filter_map(|(i, s)| match s {
                    commit::Slot::Valid(r) if pin.matches(r) => Some((i, **r)),
                    _ => None,
                })
                .max_by_key(|(_, r)| r.txn_id.get());
            match found {
                Some(x) => Ok(x),
                None => return Err(super::slots::pinned_missing(&src, pin)),
            }
        }
    };
    let (slot, record) = match chosen {
        Ok(x) => x,
        Err(commit::NoState::Corrupt(v)) => {
            checks.fail(v.invariant, format!("{}: {}", v.location, v.detail));
            return Ok(checks.finish(mode, None, file_length));
        }
        Err(why) => return Err(no_state(&src, why)),
    };
    checks.pass(Invariant::CommitRecord);
    checks.pass(Invariant::Version);
    let opened = if file_length < record.file_length.get() {
        None
    } else {
        checks.absorb(super::open::open_at(&src, super::open::Walk::Full, pin))?
    };
    // The state the store registered (a writer may have published a newer one meanwhile).
    let (slot, record, slots) = match &opened {
        Some(store) if store.txn_id() != record.txn_id.get() => (
            store.commit_slot(),
            *store.commit_record(),
            read_slots(&src)?,
        ),
        _ => (slot, record, slots),
    };
    let txn = record.txn_id.get();
    let mut around = Checks::new();
    let newer = pin.is_some() && latest_txn(&src)? != Some(txn);
    if !newer {
        check_slots(&src, &slots, slot, &record, &mut around)?;
    }
    if let Some(store) = &opened {
        verify_state(store, mode, &mut checks, progress)?;
    }
    // Were the checks around the state reading a commit in progress?
    let busy = around.any_failed()
        && (src.writer_present().map_err(|e| Error::io(src.name(), e))? == Some(true)
            || latest_txn(&src)? != Some(txn));
    checks.merge(around, busy);
    let mut report = checks.finish(mode, Some(txn), file_length);
    report.registered = opened.as_ref().is_some_and(|s| s.is_registered());
    Ok(report)
}

/// Every check of the state `store` holds.
fn verify_state<S: Source>(
    store: &Store<S>,
    mode: VerifyMode,
    checks: &mut Checks,
    progress: &dyn crate::progress::Progress,
) -> Result<()> {
    for id in [
        Invariant::Page,
        Invariant::DatasetHeader,
        Invariant::TreeShape,
        Invariant::ClusterDirectory,
    ] {
        checks.pass(id);
    }
    let Some(loaded) = checks.absorb(Loaded::read(store))? else {
        return Ok(());
    };
    structure::check_free_list(store, &loaded, checks);
    structure::check_nodes(store, &loaded, checks);
    structure::check_top(store, &loaded, checks);
    structure::check_blocks(store, &loaded, checks);
    let payload_pages = payloads::check_payloads(store, &loaded, checks, progress)?;
    structure::check_ownership(store, &loaded, &payload_pages, checks);
    structure::check_index_entries(store, &loaded, checks);
    if mode == VerifyMode::Full && !checks.any_failed() {
        full::check_cuts(store, &loaded, checks);
        full::check_adjacency(store, &loaded, checks);
        full::check_measured(store, &loaded, checks, progress)?;
    }
    Ok(())
}

/// I-3 and I-4, and the zero tails of both slot pages (I-1, I-4).
fn check_slots<S: Source>(
    src: &S,
    slots: &[Slot; 2],
    slot: u8,
    record: &crate::format::CommitRecord,
    checks: &mut Checks,
) -> Result<()> {
    let txn = record.txn_id.get();
    let file_length = src.len();
    if file_length == record.file_length.get() {
        checks.pass(Invariant::FileLength);
    } else {
        checks.fail(
            Invariant::FileLength,
            format!(
                "file: {file_length} bytes; the commit record says {}{}",
                record.file_length.get(),
                if file_length < record.file_length.get() {
                    " (truncated)"
                } else {
                    " (an interrupted transaction left pages past the end; `fmrh recover` cuts \
                     them)"
                }
            ),
        );
    }
    let other = 1 - slot;
    match &slots[usize::from(other)] {
        Slot::Empty => checks.pass(Invariant::InactiveSlot),
        Slot::Valid(r) if r.txn_id.get() < txn => checks.pass(Invariant::InactiveSlot),
        Slot::Valid(r) => checks.fail(
            Invariant::InactiveSlot,
            format!(
                "commit slot {other}: transaction {} is not older than the active {txn}",
                r.txn_id.get()
            ),
        ),
        Slot::Foreign { major, minor, .. } => checks.fail(
            Invariant::InactiveSlot,
            format!("commit slot {other}: an older record of format version {major}.{minor}"),
        ),
        Slot::Invalid { why, .. } => checks.fail(
            Invariant::InactiveSlot,
            format!(
                "commit slot {other}: neither zero nor a valid record ({why}); an interrupted \
                 commit leaves a torn record, which `fmrh recover` clears"
            ),
        ),
    }
    // The rest of each slot page, after the record, is zero.
    let p = u64::from(record.page_size.get());
    let tail = usize::try_from(p).unwrap_or(0) - COMMIT_RECORD_LEN;
    for s in 0..2u8 {
        let at = u64::from(s) * p + COMMIT_RECORD_LEN as u64;
        let zero = match src.read_at(at, tail) {
            Ok(b) => crate::format::is_zero(&b),
            Err(e) if e.kind() == std::io::ErrorKind::UnexpectedEof => false,
            Err(e) => return Err(Error::io(src.name(), e)),
        };
        if !zero {
            checks.fail(
                if s == slot {
                    Invariant::CommitRecord
                } else {
                    Invariant::InactiveSlot
                },
                format!("commit slot {s}: the page after the record is not zero"),
            );
        }
    }
    Ok(())
}

/// Block `i` of the row-major block table, with `cols` blocks a row (fewer than 2^20 each
/// way, so both fit a `u32`).
fn block_xy(i: usize, cols: u32) -> (u32, u32) {
    let cols = cols as usize;
    let at = |v: usize| u32::try_from(v).unwrap_or(u32::MAX);
    (at(i % cols), at(i / cols))
}

/// The tables, read once.
pub(super) struct Loaded {
    nodes: Vec<NodeRecord>,
    blocks: Vec<BlockRecord>,
    free: Vec<FreePage>,
    indexes: Vec<Vec<IndexEntry>>,
    adjacency: Vec<[Vec<u32>; 4]>,
}

impl Loaded {
    fn read<S: Source>(store: &Store<S>) -> Result<Loaded> {
        let nodes = store.node_records()?;
        let blocks = store.block_records()?;
        let free = store.free_pages()?;
        let mut indexes = Vec::new();
        let mut adjacency = Vec::new();
        for (c, cl) in store.clusters().iter().enumerate() {
            indexes.push(store.all_records(cl.index(), tables::INDEX)?);
            let mut lists: [Vec<u32>; 4] = Default::default();
            for (edge, list) in lists.iter_mut().enumerate() {
                *list = store.adjacency(c, edge)?;
            }
            adjacency.push(lists);
        }
        Ok(Loaded {
            nodes,
            blocks,
            free,
            indexes,
            adjacency,
        })
    }
}
