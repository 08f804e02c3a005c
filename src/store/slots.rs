//! The commit slots as a source holds them *now*: reading and classifying both (format §3),
//! which state is the latest, and, from that, the triage of bytes that fail their check.
//!
//! **Triage.** Bytes a state names that do not hold what the state says are one of two
//! things: the state was superseded and a later commit reused them (the file is sound, the
//! reader's view is gone: [`Error::Superseded`], open again), or the file is damaged
//! ([`Error::Corrupt`]). Only the slots tell which: a newer latest state means superseded.
//! Containers ask through [`superseded_or_corrupt`]; a dataset's manifest, whose slots are
//! its own, through [`triage`] with its own latest state. One rule, one home.

use std::path::Path;

use super::source::Source;
use crate::error::{Error, Result};
use crate::format::commit::{self, NoState, Slot};
use crate::format::manifest::StatePin;
use crate::format::{Invariant, Violation, COMMIT_RECORD_LEN, FORMAT_MAJOR};

/// The record bytes of a slot at `offset`, or `None` when the file ends first. A failed read
/// that is not the end of the file is an I/O error.
fn slot_bytes<S: Source + ?Sized>(src: &S, offset: u64, fresh: bool) -> Result<Option<Vec<u8>>> {
    if offset.saturating_add(COMMIT_RECORD_LEN as u64) > src.len() {
        return Ok(None);
    }
    let read = if fresh {
        src.read_fresh(offset, COMMIT_RECORD_LEN)
    } else {
        src.read_at(offset, COMMIT_RECORD_LEN)
    };
    match read {
        Ok(bytes) => Ok(Some(bytes.into_owned())),
        Err(e) if e.kind() == std::io::ErrorKind::UnexpectedEof => Ok(None),
        Err(e) => Err(Error::io(src.name(), e)),
    }
}

/// Reads and classifies both commit slots. Slot 1 lies one page in, at the page size slot 0
/// names; when slot 0 names none, every allowed page size is tried, and the first sealed
/// record whose page size is its offset is slot 1.
pub(crate) fn read_slots<S: Source + ?Sized>(src: &S) -> Result<[Slot; 2]> {
    read_slots_from(src, false)
}

/// [`read_slots`], reading past what the source keeps in memory when `fresh`.
fn read_slots_from<S: Source + ?Sized>(src: &S, fresh: bool) -> Result<[Slot; 2]> {
    let first = slot_bytes(src, 0, fresh)?;
    let slot0 = match &first {
        None => Slot::missing(0),
        Some(b) => commit::classify(b, 0, 0),
    };
    let at = |p: u32| -> Result<Slot> {
        Ok(match slot_bytes(src, u64::from(p), fresh)? {
            None => Slot::missing(1),
            Some(b) => commit::classify(&b, 1, u64::from(p)),
        })
    };
    let named = slot0.page_size();
    let slot1 = match named {
        Some(p) => at(p)?,
        None => {
            let mut found = None;
            for p in commit::candidate_page_sizes() {
                let s = at(p)?;
                if matches!(s, Slot::Valid(_) | Slot::Foreign { .. }) {
                    found = Some(s);
                    break;
                }
            }
            found.unwrap_or(Slot::Invalid {
                why: Violation::new(
                    Invariant::CommitRecord,
                    "commit slot 1",
                    "no valid record at any page size",
                ),
                has_magic: false,
            })
        }
    };
    Ok([slot0, slot1])
}

/// The error for a file whose slots give no state, about the file `src` names.
pub(crate) fn no_state<S: Source + ?Sized>(src: &S, why: NoState) -> Error {
    match why {
        NoState::NotAContainer => Error::input(
            src.name(),
            "not an fmrh container (no commit record with the FMRH magic)",
        ),
        NoState::Unsupported { major, minor } => Error::unsupported(
            src.name(),
            format!(
                "format version {major}.{minor} (a newer writer's state); this reader reads \
                 1.x and {FORMAT_MAJOR}.x"
            ),
        ),
        NoState::Corrupt(v) => v.in_file(src.name()),
    }
}

/// The txn id of the state a reader would open from `src` now, if any.
pub(crate) fn latest_txn<S: Source + ?Sized>(src: &S) -> Result<Option<u64>> {
    let slots = read_slots(src)?;
    Ok(commit::choose(&slots).ok().map(|(_, r)| r.txn_id.get()))
}

/// Which committed state a reader holds: its txn id and its commit record's CRC. The id
/// alone does not name a state: another file (a re-upload, a copy over it) has states with
/// the same ids.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(crate) struct StateId {
    /// The record's `txn_id`.
    pub txn: u64,
    /// The record's CRC (its last four bytes).
    pub record_crc: u32,
}

/// What the slots of a file say now about a state a reader holds (see [`triage`]).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(crate) enum SlotsNow {
    /// The slots could not be read or hold no state.
    Unknown,
    /// The latest state's txn id, and whether a valid slot still publishes the reader's state.
    Latest { txn: u64, still_published: bool },
}

/// What the slots of `src` say now about the state `held`.
pub(crate) fn slots_now<S: Source + ?Sized>(src: &S, held: StateId) -> SlotsNow {
    let Ok(slots) = read_slots_from(src, true) else {
        return SlotsNow::Unknown;
    };
    let Ok((_, latest)) = commit::choose(&slots) else {
        return SlotsNow::Unknown;
    };
    let still_published = slots.iter().any(|s| {
        matches!(s, Slot::Valid(r) if r.txn_id.get() == held.txn && r.crc.get() == held.record_crc)
    });
    SlotsNow::Latest {
        txn: latest.txn_id.get(),
        still_published,
    }
}

/// The error for bytes of the state `held` that do not hold what the state says (`v`): the
/// state was superseded and its pages reused when the file's latest state is newer; the file
/// was replaced underneath when no slot publishes the state any more and none newer does;
/// else corruption.
pub(crate) fn superseded_or_corrupt<S: Source + ?Sized>(
    src: &S,
    held: StateId,
    v: Violation,
) -> Error {
    triage(src.name(), held.txn, slots_now(src, held), v)
}

/// The error for bytes of the state `txn` of the file `path` that do not hold what the state
/// says (`v`), given what the file's slots say now: superseded when the latest state is
/// newer; changed underneath when the state is no longer published and no newer one
/// replaced it (commits only ever publish higher ids, so only another file does that); else
/// corruption.
pub(crate) fn triage(path: &Path, txn: u64, now: SlotsNow, v: Violation) -> Error {
    match now {
        SlotsNow::Latest { txn: latest, .. } if latest > txn => Error::Superseded {
            path: path.to_path_buf(),
            txn,
            latest,
            detail: format!("{}: {}", v.location, v.detail),
        },
        SlotsNow::Latest {
            still_published: false,
            ..
        } => Error::Changed {
            path: path.to_path_buf(),
            detail: format!(
                "its slots no longer publish the state this reader opened (txn {txn}), and no \
                 newer state does; found {}: {}",
                v.location, v.detail
            ),
        },
        _ => v.in_file(path),
    }
}

/// The error for a file neither of whose slots publishes the pinned state.
pub(crate) fn pinned_missing<S: Source + ?Sized>(src: &S, pin: StatePin) -> Error {
    Violation::new(
        Invariant::TilePins,
        "commit slots",
        format!(
            "neither slot publishes the state the dataset pins (pages_txn {}, state CRC \
             {:#010x})",
            pin.pages_txn, pin.state_crc
        ),
    )
    .in_file(src.name())
}
