//! Commit records and the choice of the state a reader opens (`format-spec/container.md` §3).
//!
//! Pages 0 and 1 are the two *commit slots*. Each holds a 256-byte record at its start (the
//! rest of the page is zero) that reaches every structure of one state. A writer publishes a
//! new state by writing the slot the current state does not use, so a reader takes the newer
//! of the two valid records.
//!
//! ```text
//!  0        8     10    12     16       24           32     36     40 ...  168       176     200   216 ... 252  256
//!  | magic  | maj | min | page | txn_id | file_length| flags| rsvd | roots | pages_txn| bundle | top | rsvd | crc |
//!  └──────── the envelope: the same in every major version ───────┘                               └─ CRC of 0..252
//! ```
//!
//! `pages_txn` (1.2; zero before) is the transaction that wrote every structured page the
//! state reaches: each of those pages carries its low 16 bits (`page::txn_tag`). `bundle`
//! (3.0; zero before) names the compressed metadata bundle, if the state has one
//! ([`super::bundle`]). `top` (6.2; zero before) names the top of the tree, a copy of the
//! coarsest levels' node records ([`super::top`]), if the state has one.
//!
//! **The envelope.** Magic, major, minor, page size, txn id and the CRC at 252 keep their
//! places in every major version, so a reader can tell that a newer writer has superseded the
//! state it understands: the newest *sealed* record (magic and CRC right) decides, and if its
//! major is not this reader's, the file is unsupported, whatever the other slot holds.

use zerocopy::byteorder::little_endian::{U16, U32, U64};
use zerocopy::{FromBytes, IntoBytes};

use super::blob::BlobRef;
use super::bundle::BundleRef;
use super::tree::TreeRef;
use super::{
    crc32, is_zero, page_size_is_valid, Invariant, Violation, FORMAT_MAJOR, FORMAT_MINOR,
    LAST_MINOR_OF_1, LAST_MINOR_OF_2, LAST_MINOR_OF_3, LAST_MINOR_OF_4, LAST_MINOR_OF_5,
    LAST_MINOR_OF_6, MAGIC,
    MAX_PAGE_SIZE, MIN_PAGE_SIZE,
};

/// Bytes of a commit record at the start of its slot page; the rest of the page is zero.
pub const COMMIT_RECORD_LEN: usize = 256;

/// The record's CRC covers bytes `0..COMMIT_CRC_SPAN`, and is stored right after them.
pub const COMMIT_CRC_SPAN: usize = COMMIT_RECORD_LEN - 4;

/// Commit record flag: a transactional writer had the file open when this state was
/// committed, and may have written past `file_length` since. The next writer to open the file
/// cuts it back to `file_length` (recovery) before anything else; readers ignore the excess.
/// A writer that closes cleanly commits a record without the flag.
pub const COMMIT_RECOVERY_NEEDED: u32 = 1;

/// Commit record flag: a transaction has replaced payloads, so bytes of dead payloads may
/// remain in payload pages that live payloads still use (a commit never writes a page the
/// previous state reaches, so it cannot zero them). Without it, those bytes are zero (I-9).
/// Once set, later commits keep it.
pub const COMMIT_PAYLOAD_SLACK: u32 = 2;

/// Every commit record flag this reader knows.
pub const COMMIT_FLAGS_KNOWN: u32 = COMMIT_RECOVERY_NEEDED | COMMIT_PAYLOAD_SLACK;

/// The largest transaction id (`2^62 - 1`, §2): a reader of state `t` locks byte `2^62 + t`
/// (§11.6), so ids stop below the writer's lock byte's distance. A record with a larger id is
/// invalid; a writer whose next id would pass it refuses to commit (at a million commits a
/// second, that takes 146,000 years).
pub const MAX_TXN_ID: u64 = (1 << 62) - 1;

/// The id of the transaction after `txn`, or `None` when `txn` is the last (`MAX_TXN_ID`).
pub fn next_txn_id(txn: u64) -> Option<u64> {
    txn.checked_add(1).filter(|&t| t <= MAX_TXN_ID)
}

on_disk! {
    /// A commit record: the first [`COMMIT_RECORD_LEN`] bytes of page 0 or page 1.
    #[derive(Eq)]
    pub struct CommitRecord {
        /// [`MAGIC`].
        pub magic: [u8; 8],
        /// [`FORMAT_MAJOR`] of the writer.
        pub major: U16,
        /// [`FORMAT_MINOR`] of the writer.
        pub minor: U16,
        /// Bytes per page.
        pub page_size: U32,
        /// Transaction id: the valid record with the higher id is the current state.
        pub txn_id: U64,
        /// The file's length in bytes when this record was written.
        pub file_length: U64,
        /// [`COMMIT_RECOVERY_NEEDED`], [`COMMIT_PAYLOAD_SLACK`].
        pub flags: U32,
        /// Zero.
        pub reserved0: U32,
        /// The roots of the state's sections (bytes 40..168).
        pub roots: StateRoots,
        /// The transaction that wrote every structured page this state reaches (1.2). Zero in
        /// older files, whose pages carry no txn tag.
        pub pages_txn: U64,
        /// The metadata bundle (3.0; zero before, and when the state has none).
        pub bundle: BundleRef,
        /// The top of the tree (6.2; zero before, and when the state has none): a copy of
        /// the coarsest levels' node records ([`super::top`]).
        pub top: BlobRef,
        /// Zero.
        pub reserved: [u8; 36],
        /// CRC-32 of bytes `0..COMMIT_CRC_SPAN` of the record.
        pub crc: U32,
    }
}

const _: () = assert!(size_of::<CommitRecord>() == COMMIT_RECORD_LEN);

on_disk! {
    /// The roots of every section of a state: what a commit record points to.
    #[derive(Default, Eq)]
    pub struct StateRoots {
        /// The dataset header blob.
        pub dataset_header: BlobRef,
        /// The cluster directory blob.
        pub cluster_directory: BlobRef,
        /// The node table.
        pub node_table: TreeRef,
        /// The block table.
        pub block_table: TreeRef,
        /// The free list; empty in a freshly built file.
        pub free_list: TreeRef,
        /// The adjacency table: every cluster's edge lists, back to back in the order the
        /// cluster directory's runs give.
        pub adjacency: TreeRef,
    }
}

const _: () = assert!(size_of::<StateRoots>() == 128);

impl CommitRecord {
    /// A sealed record of this format version for `roots`, whose structured pages transaction
    /// `txn_id` wrote.
    pub fn new(
        page_size: u32,
        txn_id: u64,
        file_length: u64,
        flags: u32,
        roots: StateRoots,
    ) -> CommitRecord {
        let mut r = CommitRecord {
            magic: MAGIC,
            major: U16::new(FORMAT_MAJOR),
            minor: U16::new(FORMAT_MINOR),
            page_size: U32::new(page_size),
            txn_id: U64::new(txn_id),
            file_length: U64::new(file_length),
            flags: U32::new(flags),
            reserved0: U32::new(0),
            roots,
            pages_txn: U64::new(txn_id),
            bundle: BundleRef::default(),
            top: BlobRef::default(),
            reserved: [0; 36],
            crc: U32::new(0),
        };
        r.seal();
        r
    }

    /// The same record with `bundle` as its metadata bundle, sealed.
    pub fn with_bundle(mut self, bundle: BundleRef) -> CommitRecord {
        self.bundle = bundle;
        self.seal();
        self
    }

    /// The same record with `top` as the top of its tree (6.2), sealed.
    pub fn with_top(mut self, top: BlobRef) -> CommitRecord {
        self.top = top;
        self.seal();
        self
    }

    /// The top of the tree (6.2), when the state has one: a record of an older version
    /// has none (the field was reserved).
    pub fn top(&self) -> Option<BlobRef> {
        (self.has_top_field() && self.top.length.get() != 0).then_some(self.top)
    }

    /// Whether the record's version has the `top` field (6.2 and later).
    fn has_top_field(&self) -> bool {
        (self.major.get(), self.minor.get()) >= (6, 2)
    }

    /// The same state under another txn id and flags, sealed: what a writer publishes to mark
    /// or unmark a state without changing it.
    pub fn copy_as(&self, txn_id: u64, flags: u32) -> CommitRecord {
        let mut r = *self;
        r.txn_id = U64::new(txn_id);
        r.flags = U32::new(flags);
        r.seal();
        r
    }

    /// Fills in the CRC.
    fn seal(&mut self) {
        self.crc = U32::new(crc32(&self.as_bytes()[..COMMIT_CRC_SPAN]));
    }

    /// Whether its pages carry txn tags and the record `pages_txn` (format 1.2 and 2.x).
    pub fn binds_pages(&self) -> bool {
        self.major.get() >= 2 || self.minor.get() >= 2
    }

    /// Whether its payloads are stored coded (format 2.x; 1.x stores them raw).
    pub fn payloads_coded(&self) -> bool {
        self.major.get() >= 2
    }

    /// Whether its blocks may be coded against their parent's grid (format 4.x): before,
    /// a block record's `against` field was reserved, zero.
    pub fn blocks_against_parents(&self) -> bool {
        self.major.get() >= 4
    }

    /// Whether its nodes' grids may be coded against their parent's grid (format 5.x):
    /// before, the node record's flag bit 1 was reserved, zero.
    pub fn grids_against_parents(&self) -> bool {
        self.major.get() >= 5
    }

    /// Whether its nodes' grids may be stored thinned by area (format 6.x): before, the node
    /// record's flag bits 3 to 6 were reserved, zero.
    pub fn grids_thinned(&self) -> bool {
        self.major.get() >= 6
    }

    /// The codes its payloads may use (format 2.x and later): from 7.0 on, encodings 9 to 15
    /// (residuals by tANS) too; before, a code's id is 0 to 8, and a larger one is a corrupt
    /// payload.
    pub fn payload_codes(&self) -> super::payload::Codes {
        super::payload::Codes::of_major(self.major.get())
    }

    /// Whether its metadata bundle is stored a frame per page, read page by page (5.x), not
    /// as one frame read whole at open.
    pub fn bundle_framed(&self) -> bool {
        self.major.get() >= 5
    }

    /// Whether `flag` is set.
    pub fn has_flag(&self, flag: u32) -> bool {
        self.flags.get() & flag != 0
    }

    /// The txn tag every structured page of this state carries: the low bits of `pages_txn`
    /// in a 1.2 file, zero (the field was reserved) before.
    pub fn page_txn_tag(&self) -> u16 {
        if self.binds_pages() {
            super::page::txn_tag(self.pages_txn.get())
        } else {
            0
        }
    }
}

/// What one commit slot holds.
#[derive(Clone, Debug, PartialEq, Eq)]
pub enum Slot {
    /// Every byte of the record area is zero.
    Empty,
    /// A valid record of this reader's major version.
    Valid(Box<CommitRecord>),
    /// A sealed record (magic and CRC right) of another major version: its envelope.
    Foreign {
        /// Its major version.
        major: u16,
        /// Its minor version.
        minor: u16,
        /// Its page size.
        page_size: u32,
        /// Its txn id.
        txn_id: u64,
    },
    /// Not a valid record: why, and whether it carries the magic.
    Invalid {
        /// What is wrong (I-1 or, for a file that ends inside the slot, I-3).
        why: Violation,
        /// Whether its first bytes are the magic.
        has_magic: bool,
    },
}

impl Slot {
    /// The slot of a file that ends before the record's end.
    pub fn missing(slot: u8) -> Slot {
        Slot::Invalid {
            why: Violation::new(
                Invariant::FileLength,
                format!("commit slot {slot}"),
                "the file ends inside it",
            ),
            has_magic: false,
        }
    }

    /// The page size this slot's envelope names, if it is sealed and names an allowed one:
    /// where slot 1 lies when this is slot 0.
    pub fn page_size(&self) -> Option<u32> {
        match *self {
            Slot::Valid(ref r) => Some(r.page_size.get()),
            Slot::Foreign { page_size, .. } => Some(page_size).filter(|&p| page_size_is_valid(p)),
            _ => None,
        }
    }
}

/// Classifies the [`COMMIT_RECORD_LEN`] bytes of commit slot `slot`, read at byte offset
/// `offset` (0 for slot 0; the page size for slot 1). A record is valid when its magic and
/// CRC are right, its major version is this reader's, its fields are in range, and its page
/// size is the offset it was read at (slot 1 only: a slot 1 that disagrees with slot 0 on
/// the page size is invalid, not a second geometry).
pub fn classify(bytes: &[u8], slot: u8, offset: u64) -> Slot {
    let Some(record) = bytes.get(..COMMIT_RECORD_LEN) else {
        return Slot::missing(slot);
    };
    if is_zero(record) {
        return Slot::Empty;
    }
    let has_magic = record[..8] == MAGIC;
    let invalid = |detail: String| Slot::Invalid {
        why: Violation::new(
            Invariant::CommitRecord,
            format!("commit slot {slot}"),
            detail,
        ),
        has_magic,
    };
    if !has_magic {
        return invalid("bad magic".into());
    }
    let Ok(r) = CommitRecord::read_from_bytes(record) else {
        return invalid("shorter than a commit record".into());
    };
    let crc = crc32(&record[..COMMIT_CRC_SPAN]);
    if crc != r.crc.get() {
        return invalid(format!(
            "CRC {:#010x} stored, {crc:#010x} computed",
            r.crc.get()
        ));
    }
    if !(1..=FORMAT_MAJOR).contains(&r.major.get()) {
        return Slot::Foreign {
            major: r.major.get(),
            minor: r.minor.get(),
            page_size: r.page_size.get(),
            txn_id: r.txn_id.get(),
        };
    }
    let p = r.page_size.get();
    if !page_size_is_valid(p) {
        return invalid(format!("page size {p}"));
    }
    if slot == 1 && u64::from(p) != offset {
        return invalid(format!(
            "page size {p}, but slot 1 lies at byte {offset}: both slots name one page size"
        ));
    }
    let len = r.file_length.get();
    if len % u64::from(p) != 0 || len < 2 * u64::from(p) {
        return invalid(format!("file length {len} is not two or more whole pages"));
    }
    if !(1..=MAX_TXN_ID).contains(&r.txn_id.get()) {
        return invalid(format!(
            "transaction id {}, not one of 1..=2^62-1",
            r.txn_id.get()
        ));
    }
    if r.binds_pages() && !(1..=r.txn_id.get()).contains(&r.pages_txn.get()) {
        return invalid(format!(
            "pages written by transaction {}, not one of 1..={}",
            r.pages_txn.get(),
            r.txn_id.get()
        ));
    }
    let newer_minor = is_newer_minor(r.major.get(), r.minor.get());
    let has_bundle = r.major.get() >= 3;
    if !newer_minor
        && (r.flags.get() & !COMMIT_FLAGS_KNOWN != 0
            || r.reserved0.get() != 0
            || (!r.binds_pages() && r.pages_txn.get() != 0)
            || (!has_bundle && !is_zero(r.bundle.as_bytes()))
            || (r.major.get() < 5 && r.bundle.head_len.get() != 0)
            || (!r.has_top_field() && !is_zero(r.top.as_bytes()))
            || !is_zero(&r.reserved))
    {
        return invalid("reserved fields are not zero".into());
    }
    if has_bundle {
        if let Err(why) = r.bundle.check(p, len, r.bundle_framed()) {
            return invalid(why);
        }
    }
    Slot::Valid(Box::new(r))
}

/// Whether `major.minor` is a minor of its major newer than this reader knows: its
/// reserved bytes may then hold fields this reader ignores (§8).
pub fn is_newer_minor(major: u16, minor: u16) -> bool {
    minor
        > match major {
            FORMAT_MAJOR => FORMAT_MINOR,
            6 => LAST_MINOR_OF_6,
            5 => LAST_MINOR_OF_5,
            4 => LAST_MINOR_OF_4,
            3 => LAST_MINOR_OF_3,
            2 => LAST_MINOR_OF_2,
            _ => LAST_MINOR_OF_1,
        }
}

/// Where to look for slot 1 when slot 0 names no page size: one page in, for every allowed
/// page size, smallest first. The first sealed record whose page size is its offset is slot 1.
pub fn candidate_page_sizes() -> impl Iterator<Item = u32> {
    (MIN_PAGE_SIZE.trailing_zeros()..=MAX_PAGE_SIZE.trailing_zeros()).map(|s| 1u32 << s)
}

/// Why no state can be opened from a file's slots.
#[derive(Clone, Debug, PartialEq, Eq)]
pub enum NoState {
    /// Neither slot carries the magic: not an fmrh container at all.
    NotAContainer,
    /// The newest sealed record is of another major version.
    Unsupported {
        /// Its major version.
        major: u16,
        /// Its minor version.
        minor: u16,
    },
    /// No valid record: the first slot's reason.
    Corrupt(Violation),
}

/// The state a reader opens (§3): the valid record with the higher txn id (slot 0 on a tie).
/// If a sealed record of another major version has a higher txn id than every valid record,
/// a newer writer has superseded them and the file is [`NoState::Unsupported`].
pub fn choose(slots: &[Slot; 2]) -> Result<(u8, CommitRecord), NoState> {
    let mut best: Option<(u8, &CommitRecord)> = None;
    for (i, s) in (0u8..).zip(slots) {
        if let Slot::Valid(r) = s {
            if best.is_none_or(|(_, b)| r.txn_id.get() > b.txn_id.get()) {
                best = Some((i, r));
            }
        }
    }
    let newest_foreign = slots
        .iter()
        .filter_map(|s| match *s {
            Slot::Foreign {
                major,
                minor,
                txn_id,
                ..
            } => Some((txn_id, major, minor)),
            _ => None,
        })
        .max();
    if let Some((txn, major, minor)) = newest_foreign {
        if best.is_none_or(|(_, b)| txn >= b.txn_id.get()) {
            return Err(NoState::Unsupported { major, minor });
        }
    }
    if let Some((i, r)) = best {
        return Ok((i, *r));
    }
    let magic = |s: &Slot| match s {
        Slot::Invalid { has_magic, .. } => *has_magic,
        Slot::Empty => false,
        _ => true,
    };
    if !slots.iter().any(magic) {
        return Err(NoState::NotAContainer);
    }
    Err(NoState::Corrupt(
        slots
            .iter()
            .find_map(|s| match s {
                Slot::Invalid { why, .. } => Some(why.clone()),
                _ => None,
            })
            .unwrap_or_else(|| {
                Violation::new(
                    Invariant::CommitRecord,
                    "commit slots",
                    "neither slot holds a valid record",
                )
            }),
    ))
}

/// Checks a chosen record's `file_length` against the file's real length (I-3). A file
/// shorter than its newest valid record says is corrupt: the other slot is *not* tried, since
/// its pages may have been reused by the newer state, and a silent fall-back would lose
/// committed data. A longer file is accepted; an interrupted transaction leaves such excess.
pub fn check_length(record: &CommitRecord, actual: u64) -> Result<(), Violation> {
    let committed = record.file_length.get();
    if actual < committed {
        return Err(Violation::new(
            Invariant::FileLength,
            "file",
            format!("{actual} bytes; the commit record says {committed} (truncated)"),
        ));
    }
    Ok(())
}
