//! A dataset's `MANIFEST` (`format-spec/dataset.md`): where each tile lies, which state of
//! each tile file belongs to the dataset, and the commit records that switch the dataset from
//! one state to the next. Byte layouts and checks only; `src/dataset/` reads and writes.
//!
//! ```text
//!  page 0: slot 0 (256-byte record)     page 1: slot 1           pages 2..: bodies
//!  ┌──────────────────────────────┐     ┌──────────┐    ┌───────────────────────────────┐
//!  │ magic maj min P txn len      │     │  ...     │    │ tile page 0 │ ... │ head        │
//!  │ head(off,len,crc) tiles ...  │     │          │    │ 32 records  │     │ fixed, N×64 │
//!  │ ... crc                      │     │          │    └───────────────────────────────┘
//!  └──────────────────────────────┘     └──────────┘
//! ```
//!
//! A record names its *head* by offset, length and CRC. The head names each *tile page* by
//! offset, length and CRC, with the rectangle its tiles span, so a reader opens a dataset
//! with one read of the slots and one of the head, and reads a tile page only when a window
//! meets its rectangle. A new state's body is written where the active state's is not, then
//! its record into the other slot: the container's copy-on-write commit, on a smaller file.

use zerocopy::byteorder::little_endian::{F32, F64, U16, U32, U64};
use zerocopy::{FromBytes, IntoBytes};

use super::{crc32, is_zero, CommitRecord, Invariant, Violation, COMMIT_RECORD_LEN};
use crate::model::SampleRect;

/// `FMDS\r\n\x1a\n`: the first bytes of a manifest commit record.
pub const MANIFEST_MAGIC: [u8; 8] = *b"FMDS\r\n\x1a\n";

/// The manifest's major version: a reader refuses another.
pub const MANIFEST_MAJOR: u16 = 1;

/// The manifest's minor version. Minors add fields in bytes that older minors keep zero:
/// 1 records the tiles' vertical datum in the head (byte 20).
pub const MANIFEST_MINOR: u16 = 1;

/// The manifest's page size: slots, tile pages and the head are aligned to it.
pub const MANIFEST_PAGE: u32 = 4096;

/// Bytes of a manifest commit record at the start of its slot page.
pub const MANIFEST_RECORD_LEN: usize = 256;

/// The record's CRC covers bytes `0..252`.
pub const MANIFEST_CRC_SPAN: usize = MANIFEST_RECORD_LEN - 4;

/// `FMDH`: the first bytes of a head.
pub const HEAD_MAGIC: [u8; 4] = *b"FMDH";

/// Bytes of the head's fixed part, before its page entries.
pub const HEAD_FIXED_LEN: usize = 256;

/// Bytes of one page entry of the head.
pub const PAGE_ENTRY_LEN: usize = 64;

/// Bytes of one tile record.
pub const TILE_RECORD_LEN: usize = 128;

/// Tile records in a full tile page (`MANIFEST_PAGE / TILE_RECORD_LEN`).
pub const TILES_PER_PAGE: usize = 32;

/// The most tiles a manifest holds: its head is then 2 MiB.
pub const MAX_TILES: u64 = 1 << 20;

/// The most bytes of adjacent-cluster tables a manifest holds (4 GiB).
pub const MAX_ADJACENCY_LEN: u64 = 1 << 32;

/// Bytes of a tile's file name, zero-padded.
pub const TILE_NAME_LEN: usize = 56;

/// Bytes of the CRS name in the head, zero-padded.
pub const CRS_LEN: usize = 128;

/// Head flag: the dataset's grid has a georeference.
pub const HEAD_HAS_GEOREFERENCE: u32 = 1;

/// How shared edges were settled when the tiles were placed (the record's `seam` byte).
pub const SEAM_STRICT: u8 = 0;
/// The tile listed first keeps its samples.
pub const SEAM_FIRST: u8 = 1;
/// Both tiles take the mean.
pub const SEAM_MEAN: u8 = 2;

on_disk! {
    /// A manifest commit record: the first [`MANIFEST_RECORD_LEN`] bytes of page 0 or page 1.
    #[derive(Eq)]
    pub struct ManifestRecord {
        /// [`MANIFEST_MAGIC`].
        pub magic: [u8; 8],
        /// [`MANIFEST_MAJOR`].
        pub major: U16,
        /// [`MANIFEST_MINOR`].
        pub minor: U16,
        /// [`MANIFEST_PAGE`].
        pub page_size: U32,
        /// Transaction id (≥ 1): the valid record with the higher one is the dataset's state.
        pub txn_id: U64,
        /// Bytes of the file this state needs: the end of its body.
        pub file_length: U64,
        /// Byte offset of the head: a multiple of the page size, ≥ two pages.
        pub head_offset: U64,
        /// Bytes of the head.
        pub head_len: U32,
        /// CRC-32 of the head.
        pub head_crc: U32,
        /// Tiles.
        pub tile_count: U64,
        /// Columns of the dataset grid: one past the easternmost tile's last column.
        pub columns: U64,
        /// Rows of the dataset grid.
        pub rows: U64,
        /// Metres from one column to the next (east), 0 when unknown.
        pub spacing_x: F64,
        /// Metres from one row to the next (south), 0 when unknown.
        pub spacing_y: F64,
        /// How shared edges were settled: [`SEAM_STRICT`], [`SEAM_FIRST`], [`SEAM_MEAN`].
        pub seam: u8,
        /// Zero.
        pub reserved0: [u8; 7],
        /// Bytes of the adjacency area between the tile pages and the head: a multiple of the
        /// page size.
        pub adjacency_len: U64,
        /// Zero.
        pub reserved: [u8; 148],
        /// CRC-32 of bytes `0..252`.
        pub crc: U32,
    }
}

const _: () = assert!(size_of::<ManifestRecord>() == MANIFEST_RECORD_LEN);

/// What a slot holds.
#[derive(Clone, Debug, PartialEq)]
pub enum ManifestSlot {
    /// All zero (never written).
    Empty,
    /// A record this reader understands.
    Valid(ManifestRecord),
    /// A sealed record (magic and CRC right) of another major version.
    Foreign {
        /// Its major.
        major: u16,
        /// Its txn id.
        txn_id: u64,
    },
    /// Anything else: torn, garbled, or the file ends first.
    Invalid(Violation),
}

impl ManifestRecord {
    /// A record of this writer's version with the CRC computed.
    #[allow(clippy::too_many_arguments)]
    pub fn new(
        txn_id: u64,
        file_length: u64,
        head: (u64, u32, u32),
        adjacency_len: u64,
        tile_count: u64,
        columns: u64,
        rows: u64,
        spacing_m: Option<[f64; 2]>,
        seam: u8,
    ) -> ManifestRecord {
        let [sx, sy] = spacing_m.unwrap_or([0.0, 0.0]);
        let mut r = ManifestRecord {
            magic: MANIFEST_MAGIC,
            major: MANIFEST_MAJOR.into(),
            minor: MANIFEST_MINOR.into(),
            page_size: MANIFEST_PAGE.into(),
            txn_id: txn_id.into(),
            file_length: file_length.into(),
            head_offset: head.0.into(),
            head_len: head.1.into(),
            head_crc: head.2.into(),
            tile_count: tile_count.into(),
            columns: columns.into(),
            rows: rows.into(),
            spacing_x: sx.into(),
            spacing_y: sy.into(),
            seam,
            reserved0: [0; 7],
            adjacency_len: adjacency_len.into(),
            reserved: [0; 148],
            crc: 0.into(),
        };
        r.crc = crc32(&r.as_bytes()[..MANIFEST_CRC_SPAN]).into();
        r
    }

    /// The spacing, when known.
    pub fn spacing_m(&self) -> Option<[f64; 2]> {
        let (x, y) = (self.spacing_x.get(), self.spacing_y.get());
        (x > 0.0 && y > 0.0).then_some([x, y])
    }

    /// The byte range of the body: the tile pages, the adjacency area, then the head.
    pub fn body(&self) -> std::ops::Range<u64> {
        let start = self.head_offset.get() - self.adjacency_len.get() - self.pages_len();
        start..self.head_offset.get() + u64::from(self.head_len.get())
    }

    /// Bytes of the tile pages.
    fn pages_len(&self) -> u64 {
        self.tile_count.get().div_ceil(TILES_PER_PAGE as u64) * u64::from(MANIFEST_PAGE)
    }

    /// The byte range of the adjacency area.
    pub fn adjacency_area(&self) -> std::ops::Range<u64> {
        let end = self.head_offset.get();
        end - self.adjacency_len.get()..end
    }

    /// Classifies the bytes of slot `index` (the whole record, or fewer when the file ends).
    pub fn classify(bytes: &[u8], index: u8) -> ManifestSlot {
        let at = format!("manifest slot {index}");
        let bad = |detail: String| {
            ManifestSlot::Invalid(Violation::new(Invariant::ManifestRecord, &at, detail))
        };
        if bytes.len() < MANIFEST_RECORD_LEN {
            let n = bytes.len().min(MANIFEST_MAGIC.len());
            return if is_zero(bytes) {
                ManifestSlot::Empty
            } else if bytes[..n] != MANIFEST_MAGIC[..n] {
                bad("no manifest magic".into())
            } else {
                bad("the file ends inside the record".into())
            };
        }
        let Ok((r, _)) = ManifestRecord::read_from_prefix(bytes) else {
            return bad("short record".into());
        };
        if is_zero(r.as_bytes()) {
            return ManifestSlot::Empty;
        }
        if r.magic != MANIFEST_MAGIC {
            return bad("no manifest magic".into());
        }
        if crc32(&r.as_bytes()[..MANIFEST_CRC_SPAN]) != r.crc.get() {
            return bad("CRC mismatch (a torn or damaged record)".into());
        }
        if r.major.get() != MANIFEST_MAJOR {
            return ManifestSlot::Foreign {
                major: r.major.get(),
                txn_id: r.txn_id.get(),
            };
        }
        if let Err(detail) = r.check_fields() {
            return bad(detail);
        }
        ManifestSlot::Valid(r)
    }

    fn check_fields(&self) -> Result<(), String> {
        let page = u64::from(MANIFEST_PAGE);
        if self.page_size.get() != MANIFEST_PAGE {
            return Err(format!(
                "page size {}, not {MANIFEST_PAGE}",
                self.page_size.get()
            ));
        }
        if self.txn_id.get() == 0 {
            return Err("txn id 0".into());
        }
        let tiles = self.tile_count.get();
        if tiles > MAX_TILES {
            return Err(format!("{tiles} tiles, more than {MAX_TILES}"));
        }
        let head = self.head_offset.get();
        let head_len = u64::from(self.head_len.get());
        let pages = tiles.div_ceil(TILES_PER_PAGE as u64);
        let adjacency = self.adjacency_len.get();
        if !adjacency.is_multiple_of(page) || adjacency > MAX_ADJACENCY_LEN {
            return Err(format!(
                "adjacency area of {adjacency} bytes: not whole pages, or more than {MAX_ADJACENCY_LEN}"
            ));
        }
        if !head.is_multiple_of(page) || head < 2 * page + pages * page + adjacency {
            return Err(format!(
                "head offset {head}: not a page boundary after the slots, {pages} tile pages and \
                 {adjacency} bytes of adjacency tables"
            ));
        }
        if head_len != head_len_for(pages) {
            return Err(format!(
                "head of {head_len} bytes, where {pages} tile pages need {}",
                head_len_for(pages)
            ));
        }
        if head + head_len > self.file_length.get() {
            return Err(format!(
                "head ends at {}, past the state's length {}",
                head + head_len,
                self.file_length.get()
            ));
        }
        if tiles > 0 && (self.columns.get() == 0 || self.rows.get() == 0) {
            return Err("tiles in a grid of no samples".into());
        }
        let (sx, sy) = (self.spacing_x.get(), self.spacing_y.get());
        let unknown = sx == 0.0 && sy == 0.0;
        let known = sx.is_finite() && sy.is_finite() && sx > 0.0 && sy > 0.0;
        if !(unknown || known) {
            return Err(format!("spacing {sx}, {sy}: both 0 or both finite and > 0"));
        }
        if self.seam > SEAM_MEAN {
            return Err(format!("seam policy {}", self.seam));
        }
        if knows_minor(self.minor.get()) && !(is_zero(&self.reserved0) && is_zero(&self.reserved)) {
            return Err("reserved bytes not zero".into());
        }
        Ok(())
    }
}

/// Whether this reader knows every field of minor version `minor` (and so checks that
/// reserved bytes are zero).
#[allow(clippy::absurd_extreme_comparisons)]
pub fn knows_minor(minor: u16) -> bool {
    minor <= MANIFEST_MINOR
}

/// Why no dataset state can be chosen from the two slots.
#[derive(Clone, Debug, PartialEq)]
pub enum NoManifest {
    /// Neither slot has the magic.
    NotAManifest,
    /// The newest sealed record is of another major.
    Unsupported(u16),
    /// Magic, but no valid record.
    Corrupt(Violation),
}

/// The state a reader takes: the valid record with the higher txn id, unless a newer sealed
/// record of another major supersedes it.
pub fn choose(slots: &[ManifestSlot; 2]) -> Result<(u8, ManifestRecord), NoManifest> {
    let mut best: Option<(u8, ManifestRecord)> = None;
    let mut foreign: Option<(u64, u16)> = None;
    for (i, s) in (0u8..).zip(slots) {
        match s {
            ManifestSlot::Valid(r) if best.is_none_or(|(_, b)| r.txn_id.get() > b.txn_id.get()) => {
                best = Some((i, *r));
            }
            ManifestSlot::Foreign { major, txn_id } if foreign.is_none_or(|(t, _)| *txn_id > t) => {
                foreign = Some((*txn_id, *major));
            }
            _ => {}
        }
    }
    if let Some((txn, major)) = foreign {
        if best.is_none_or(|(_, b)| txn >= b.txn_id.get()) {
            return Err(NoManifest::Unsupported(major));
        }
    }
    if let Some(b) = best {
        return Ok(b);
    }
    match slots.iter().find_map(|s| match s {
        ManifestSlot::Invalid(v) if v.detail != "no manifest magic" => Some(v.clone()),
        _ => None,
    }) {
        Some(v) => Err(NoManifest::Corrupt(v)),
        None => Err(NoManifest::NotAManifest),
    }
}

/// Bytes of the head of a manifest with `pages` tile pages.
pub fn head_len_for(pages: u64) -> u64 {
    HEAD_FIXED_LEN as u64 + pages * PAGE_ENTRY_LEN as u64
}

on_disk! {
    /// The head's fixed part.
    #[derive(Eq)]
    pub struct HeadFixed {
        /// [`HEAD_MAGIC`].
        pub magic: [u8; 4],
        /// Tile pages.
        pub page_count: U32,
        /// Tiles (the record's count).
        pub tile_count: U64,
        /// [`HEAD_HAS_GEOREFERENCE`].
        pub flags: U32,
        /// Minor 1: what every tile's heights are above, as a container records it
        /// (`container.md` §5: 1 unknown, 2 ellipsoid, 3 EGM96, 4 EGM2008); 0 not recorded.
        pub vertical_datum: u8,
        /// Zero.
        pub reserved0: [u8; 3],
        /// CRS coordinates of the centre of dataset sample (0, 0).
        pub origin: [F64; 2],
        /// CRS units from one column to the next and one row to the next.
        pub step: [F64; 2],
        /// The CRS's name, UTF-8, zero-padded (all zero: none).
        pub crs: [u8; CRS_LEN],
        /// Zero.
        pub reserved: [u8; 72],
    }
}

const _: () = assert!(size_of::<HeadFixed>() == HEAD_FIXED_LEN);

on_disk! {
    /// One tile page, as the head names it.
    #[derive(Eq)]
    pub struct PageEntry {
        /// Byte offset of the page.
        pub offset: U64,
        /// Bytes of its records (`count × 128`).
        pub length: U32,
        /// CRC-32 of those bytes.
        pub crc: U32,
        /// Index of its first tile.
        pub first_tile: U32,
        /// Its tiles (32, fewer in the last page).
        pub count: U32,
        /// The rectangle its tiles span: first column, first row, last column, last row.
        pub bounds: [U64; 4],
        /// The least height of its tiles (+inf when every one is void).
        pub min_height: F32,
        /// The greatest height of its tiles (-inf when every one is void).
        pub max_height: F32,
    }
}

const _: () = assert!(size_of::<PageEntry>() == PAGE_ENTRY_LEN);

impl PageEntry {
    /// The rectangle its tiles span.
    pub fn rect(&self) -> SampleRect {
        let [col0, row0, col1, row1] = self.bounds.map(|b| b.get());
        SampleRect {
            col0,
            row0,
            col1,
            row1,
        }
    }
}

/// A decoded head.
#[derive(Clone, Debug, PartialEq)]
pub struct Head {
    /// The fixed part.
    pub fixed: HeadFixed,
    /// The tile pages, in tile order.
    pub pages: Vec<PageEntry>,
}

impl Head {
    /// Encodes the head.
    pub fn encode(&self) -> Vec<u8> {
        let mut out = self.fixed.as_bytes().to_vec();
        for p in &self.pages {
            out.extend_from_slice(p.as_bytes());
        }
        out
    }

    /// Decodes and checks the head `record` names (its CRC already checked by the caller
    /// against `record.head_crc`).
    pub fn decode(bytes: &[u8], record: &ManifestRecord) -> Result<Head, Violation> {
        let bad = |at: String, detail: String| Violation::new(Invariant::ManifestPages, at, detail);
        let (fixed, rest) = HeadFixed::read_from_prefix(bytes)
            .map_err(|_| bad("manifest head".into(), "shorter than its fixed part".into()))?;
        if fixed.magic != HEAD_MAGIC {
            return Err(bad("manifest head".into(), "no head magic".into()));
        }
        let tiles = record.tile_count.get();
        let pages = tiles.div_ceil(TILES_PER_PAGE as u64);
        if fixed.tile_count.get() != tiles || u64::from(fixed.page_count.get()) != pages {
            return Err(bad(
                "manifest head".into(),
                format!(
                    "{} tiles in {} pages, where the record says {tiles} tiles",
                    fixed.tile_count.get(),
                    fixed.page_count.get()
                ),
            ));
        }
        let known = knows_minor(record.minor.get());
        if fixed.flags.get() & !HEAD_HAS_GEOREFERENCE != 0 && known {
            return Err(bad(
                "manifest head".into(),
                format!("unknown flags {:#x}", fixed.flags.get()),
            ));
        }
        if known && !(is_zero(&fixed.reserved0) && is_zero(&fixed.reserved)) {
            return Err(bad(
                "manifest head".into(),
                "reserved bytes not zero".into(),
            ));
        }
        let datum = fixed.vertical_datum;
        if known
            && datum != 0
            && (record.minor.get() < 1 || crate::geoid::VerticalDatum::from_code(datum).is_none())
        {
            return Err(bad(
                "manifest head".into(),
                format!(
                    "vertical datum code {datum} in a {MANIFEST_MAJOR}.{} manifest",
                    record.minor.get()
                ),
            ));
        }
        if crs_name(&fixed).is_none() {
            return Err(bad(
                "manifest head".into(),
                "CRS name is not zero-padded UTF-8".into(),
            ));
        }
        if fixed.flags.get() & HEAD_HAS_GEOREFERENCE != 0 {
            let ok = fixed.origin.iter().all(|v| v.get().is_finite())
                && fixed
                    .step
                    .iter()
                    .all(|v| v.get().is_finite() && v.get() != 0.0);
            if !ok {
                return Err(bad(
                    "manifest head".into(),
                    "georeference not finite, or a zero step".into(),
                ));
            }
        } else if known
            && fixed
                .origin
                .iter()
                .chain(&fixed.step)
                .any(|v| v.get().to_bits() != 0)
        {
            // Without the flag the fields mean nothing, so they must say nothing (§3.1): a
            // writer that left values there wrote something no reader would show.
            return Err(bad(
                "manifest head".into(),
                "no georeference flag, but the origin or the step is not zero".into(),
            ));
        }
        let body = record.body();
        let mut out = Vec::with_capacity(usize::try_from(pages).unwrap_or(0));
        for (i, chunk) in rest.chunks_exact(PAGE_ENTRY_LEN).enumerate() {
            let at = format!("manifest tile page {i}");
            let Ok(p) = PageEntry::read_from_bytes(chunk) else {
                return Err(bad(at, "short entry".into()));
            };
            let first = i as u64 * TILES_PER_PAGE as u64;
            let count = (tiles - first).min(TILES_PER_PAGE as u64);
            let expect_offset = body.start + i as u64 * u64::from(MANIFEST_PAGE);
            if u64::from(p.first_tile.get()) != first
                || u64::from(p.count.get()) != count
                || u64::from(p.length.get()) != count * TILE_RECORD_LEN as u64
                || p.offset.get() != expect_offset
            {
                return Err(bad(
                    at,
                    format!(
                        "tiles {}+{} at {} ({} bytes), where tiles {first}+{count} at \
                         {expect_offset} were expected",
                        p.first_tile.get(),
                        p.count.get(),
                        p.offset.get(),
                        p.length.get()
                    ),
                ));
            }
            let r = p.rect();
            if r.col0 > r.col1
                || r.row0 > r.row1
                || r.col1 >= record.columns.get()
                || r.row1 >= record.rows.get()
            {
                return Err(bad(
                    at,
                    format!(
                        "bounds {:?} outside the dataset grid",
                        p.bounds.map(|b| b.get())
                    ),
                ));
            }
            out.push(p);
        }
        if out.len() as u64 != pages || rest.len() % PAGE_ENTRY_LEN != 0 {
            return Err(bad(
                "manifest head".into(),
                format!("{} bytes of page entries for {pages} pages", rest.len()),
            ));
        }
        Ok(Head { fixed, pages: out })
    }
}

/// The CRS name a head holds, if any.
/// `None` inside when the head names none; `None` outside when the field is not
/// zero-padded UTF-8.
pub fn crs_name(fixed: &HeadFixed) -> Option<Option<String>> {
    let end = fixed.crs.iter().position(|&b| b == 0).unwrap_or(CRS_LEN);
    if !is_zero(&fixed.crs[end..]) {
        return None;
    }
    if end == 0 {
        return Some(None);
    }
    std::str::from_utf8(&fixed.crs[..end])
        .ok()
        .map(|s| Some(s.to_string()))
}

/// Which committed state of a tile file belongs to a dataset state: the transaction that
/// wrote its pages, and the CRC of its record's bytes 40..200 (roots, `pages_txn`, bundle).
/// A record that republishes a state (a container's mark, a clean close, a dataset's
/// recovery) copies those bytes, so the pin names the state, whichever copy holds it.
#[derive(Clone, Copy, Debug, PartialEq, Eq, serde::Serialize)]
pub struct StatePin {
    /// The record's `pages_txn`.
    pub pages_txn: u64,
    /// CRC-32 of the record's bytes 40..200.
    pub state_crc: u32,
}

/// The bytes of a commit record a pin covers.
pub const PIN_SPAN: std::ops::Range<usize> = 40..200;

const _: () = assert!(PIN_SPAN.end <= COMMIT_RECORD_LEN);

impl StatePin {
    /// The pin of the state `record` publishes.
    pub fn of(record: &CommitRecord) -> StatePin {
        StatePin {
            pages_txn: record.pages_txn.get(),
            state_crc: crc32(&record.as_bytes()[PIN_SPAN]),
        }
    }

    /// Whether `record` publishes the pinned state.
    pub fn matches(&self, record: &CommitRecord) -> bool {
        *self == StatePin::of(record)
    }
}

on_disk! {
    /// A tile record: where a tile lies, its file, and its pinned state.
    #[derive(Eq)]
    pub struct TileRecord {
        /// First column in dataset samples.
        pub col0: U64,
        /// First row.
        pub row0: U64,
        /// Columns.
        pub width: U32,
        /// Rows.
        pub height: U32,
        /// The pin's `pages_txn`.
        pub pages_txn: U64,
        /// The pin's CRC.
        pub state_crc: U32,
        /// Zero.
        pub flags: U32,
        /// The least height of the tile (its root node's), for culling without opening it.
        pub min_height: F32,
        /// The greatest height.
        pub max_height: F32,
        /// Byte offset of the tile's adjacent-cluster tables in the adjacency area (0 with a
        /// length of 0: none).
        pub adjacency_offset: U64,
        /// Their bytes.
        pub adjacency_len: U32,
        /// Their CRC-32.
        pub adjacency_crc: U32,
        /// Zero.
        pub reserved: [u8; 8],
        /// The tile's file name in the dataset's directory, UTF-8, zero-padded.
        pub name: [u8; TILE_NAME_LEN],
    }
}

const _: () = assert!(size_of::<TileRecord>() == TILE_RECORD_LEN);

/// Whether `name` may name a tile file: 1 to 56 bytes of ASCII letters, digits, `.`, `_`
/// and `-`, not starting with `.`, ending in `.fmrh` (so it stays inside the directory and
/// means the same on every system).
pub fn tile_name_is_valid(name: &str) -> bool {
    !name.is_empty()
        && name.len() <= TILE_NAME_LEN
        && !name.starts_with('.')
        && name.ends_with(".fmrh")
        && name
            .bytes()
            .all(|b| b.is_ascii_alphanumeric() || b"._-".contains(&b))
}

impl TileRecord {
    /// A record (`name` must be valid: [`tile_name_is_valid`]).
    pub fn new(name: &str, rect: SampleRect, pin: StatePin, heights: (f32, f32)) -> TileRecord {
        let mut n = [0u8; TILE_NAME_LEN];
        let len = name.len().min(TILE_NAME_LEN);
        n[..len].copy_from_slice(&name.as_bytes()[..len]);
        TileRecord {
            col0: rect.col0.into(),
            row0: rect.row0.into(),
            width: u32::try_from(rect.col1 - rect.col0 + 1)
                .unwrap_or(u32::MAX)
                .into(),
            height: u32::try_from(rect.row1 - rect.row0 + 1)
                .unwrap_or(u32::MAX)
                .into(),
            pages_txn: pin.pages_txn.into(),
            state_crc: pin.state_crc.into(),
            flags: 0.into(),
            min_height: heights.0.into(),
            max_height: heights.1.into(),
            adjacency_offset: 0.into(),
            adjacency_len: 0.into(),
            adjacency_crc: 0.into(),
            reserved: [0; 8],
            name: n,
        }
    }

    /// The file name.
    pub fn name(&self) -> &str {
        let end = self
            .name
            .iter()
            .position(|&b| b == 0)
            .unwrap_or(TILE_NAME_LEN);
        std::str::from_utf8(&self.name[..end]).unwrap_or("")
    }

    /// The samples it covers, in dataset coordinates.
    pub fn rect(&self) -> SampleRect {
        SampleRect {
            col0: self.col0.get(),
            row0: self.row0.get(),
            col1: self.col0.get() + u64::from(self.width.get()) - 1,
            row1: self.row0.get() + u64::from(self.height.get()) - 1,
        }
    }

    /// Its pinned state.
    pub fn pin(&self) -> StatePin {
        StatePin {
            pages_txn: self.pages_txn.get(),
            state_crc: self.state_crc.get(),
        }
    }

    /// Checks the record's own fields against the dataset grid (`columns × rows`) and an
    /// adjacency area of `adjacency_len` bytes.
    pub fn check(
        &self,
        index: u64,
        columns: u64,
        rows: u64,
        adjacency_len: u64,
        known_minor: bool,
    ) -> Result<(), Violation> {
        let bad = |detail: String| {
            Violation::new(Invariant::TileRecords, format!("tile {index}"), detail)
        };
        let end = self
            .name
            .iter()
            .position(|&b| b == 0)
            .unwrap_or(TILE_NAME_LEN);
        let name_ok = is_zero(&self.name[end..])
            && std::str::from_utf8(&self.name[..end]).is_ok_and(tile_name_is_valid);
        if !name_ok {
            return Err(bad(
                "file name is not 1-56 bytes of [A-Za-z0-9._-] ending in .fmrh".into(),
            ));
        }
        if self.width.get() == 0 || self.height.get() == 0 {
            return Err(bad(format!(
                "{} x {} samples",
                self.width.get(),
                self.height.get()
            )));
        }
        let r = self.col0.get().checked_add(u64::from(self.width.get()));
        let c = self.row0.get().checked_add(u64::from(self.height.get()));
        if r.is_none_or(|e| e > columns) || c.is_none_or(|e| e > rows) {
            return Err(bad(format!(
                "{} x {} samples at column {}, row {}: outside the {columns} x {rows} grid",
                self.width.get(),
                self.height.get(),
                self.col0.get(),
                self.row0.get()
            )));
        }
        if self.pages_txn.get() == 0 {
            return Err(bad("pinned pages_txn 0".into()));
        }
        let (lo, hi) = (self.min_height.get(), self.max_height.get());
        // An all-void tile's range is empty: +inf .. -inf, as its root's.
        let empty = lo == f32::INFINITY && hi == f32::NEG_INFINITY;
        if !(lo.is_finite() && hi.is_finite() && lo <= hi || empty) {
            return Err(bad(format!("height range {lo} .. {hi}")));
        }
        let (at, len) = (
            self.adjacency_offset.get(),
            u64::from(self.adjacency_len.get()),
        );
        if (len == 0 && at != 0) || at.checked_add(len).is_none_or(|end| end > adjacency_len) {
            return Err(bad(format!(
                "adjacent-cluster tables of {len} bytes at {at}: outside the {adjacency_len}-byte \
                 adjacency area"
            )));
        }
        if known_minor && (self.flags.get() != 0 || !is_zero(&self.reserved)) {
            return Err(bad("reserved bytes not zero".into()));
        }
        Ok(())
    }
}

/// Decodes the records of tile page `entry` (its bytes' CRC already checked), checking each
/// record and that the page's bounds are the union of its tiles' rectangles.
pub fn decode_tile_page(
    bytes: &[u8],
    entry: &PageEntry,
    record: &ManifestRecord,
) -> Result<Vec<TileRecord>, Violation> {
    let at = format!("manifest tile page at {}", entry.offset.get());
    let mut out = Vec::with_capacity(TILES_PER_PAGE);
    let mut bounds: Option<SampleRect> = None;
    let (mut lo, mut hi) = (f32::INFINITY, f32::NEG_INFINITY);
    for (i, chunk) in bytes.chunks_exact(TILE_RECORD_LEN).enumerate() {
        let index = u64::from(entry.first_tile.get()) + i as u64;
        let t = TileRecord::read_from_bytes(chunk)
            .map_err(|_| Violation::new(Invariant::ManifestPages, &at, "short record"))?;
        t.check(
            index,
            record.columns.get(),
            record.rows.get(),
            record.adjacency_len.get(),
            knows_minor(record.minor.get()),
        )?;
        lo = lo.min(t.min_height.get());
        hi = hi.max(t.max_height.get());
        let r = t.rect();
        bounds = Some(match bounds {
            None => r,
            Some(b) => SampleRect {
                col0: b.col0.min(r.col0),
                row0: b.row0.min(r.row0),
                col1: b.col1.max(r.col1),
                row1: b.row1.max(r.row1),
            },
        });
        out.push(t);
    }
    if bytes.len() != usize::try_from(entry.length.get()).unwrap_or(0)
        || out.len() != entry.count.get() as usize
    {
        return Err(Violation::new(
            Invariant::ManifestPages,
            at,
            "length is not its records'",
        ));
    }
    if lo.to_bits() != entry.min_height.get().to_bits()
        || hi.to_bits() != entry.max_height.get().to_bits()
    {
        return Err(Violation::new(
            Invariant::ManifestPages,
            at,
            format!(
                "heights {} .. {} are not its tiles' {lo} .. {hi}",
                entry.min_height.get(),
                entry.max_height.get()
            ),
        ));
    }
    if bounds != Some(entry.rect()) {
        return Err(Violation::new(
            Invariant::ManifestPages,
            at,
            format!("bounds {:?} are not its tiles' {:?}", entry.rect(), bounds),
        ));
    }
    Ok(out)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn record(txn: u64) -> ManifestRecord {
        let head = 3 * u64::from(MANIFEST_PAGE);
        ManifestRecord::new(
            txn,
            head + 320,
            (head, 320, 0),
            0,
            1,
            10,
            10,
            None,
            SEAM_STRICT,
        )
    }

    #[test]
    fn slots_classify_as_empty_valid_foreign_or_invalid() {
        let r = record(3);
        assert!(matches!(
            ManifestRecord::classify(r.as_bytes(), 0),
            ManifestSlot::Valid(_)
        ));
        assert_eq!(ManifestRecord::classify(&[0; 256], 0), ManifestSlot::Empty);
        assert_eq!(ManifestRecord::classify(&[0; 10], 1), ManifestSlot::Empty);
        // Torn: the CRC no longer matches.
        let mut torn = r.as_bytes().to_vec();
        torn[20] ^= 1;
        assert!(matches!(
            ManifestRecord::classify(&torn, 0),
            ManifestSlot::Invalid(_)
        ));
        // A sealed record of another major.
        let mut other = r;
        other.major = 2.into();
        other.crc = crc32(&other.as_bytes()[..MANIFEST_CRC_SPAN]).into();
        assert_eq!(
            ManifestRecord::classify(other.as_bytes(), 0),
            ManifestSlot::Foreign {
                major: 2,
                txn_id: 3
            }
        );
        // Sealed, but a field out of range: a head before the tile pages it needs.
        let mut bad = ManifestRecord::new(4, 1 << 20, (8192, 320, 0), 0, 40, 10, 10, None, 0);
        assert!(matches!(
            ManifestRecord::classify(bad.as_bytes(), 0),
            ManifestSlot::Invalid(_)
        ));
        bad = ManifestRecord::new(
            4,
            1 << 20,
            (3 * 4096, 320, 0),
            0,
            1,
            10,
            10,
            Some([1.0, f64::NAN]),
            0,
        );
        assert!(matches!(
            ManifestRecord::classify(bad.as_bytes(), 0),
            ManifestSlot::Invalid(_)
        ));
    }

    #[test]
    fn the_newest_valid_record_wins_unless_a_newer_major_supersedes_it() {
        let (a, b) = (record(3), record(4));
        let slots = [ManifestSlot::Valid(a), ManifestSlot::Valid(b)];
        assert_eq!(choose(&slots).map(|(s, r)| (s, r.txn_id.get())), Ok((1, 4)));
        let slots = [
            ManifestSlot::Valid(b),
            ManifestSlot::Foreign {
                major: 2,
                txn_id: 9,
            },
        ];
        assert_eq!(choose(&slots), Err(NoManifest::Unsupported(2)));
        let slots = [
            ManifestSlot::Valid(b),
            ManifestSlot::Foreign {
                major: 2,
                txn_id: 1,
            },
        ];
        assert_eq!(choose(&slots).map(|(s, _)| s), Ok(0));
        assert_eq!(
            choose(&[ManifestSlot::Empty, ManifestSlot::Empty]),
            Err(NoManifest::NotAManifest)
        );
        let torn = ManifestSlot::Invalid(Violation::new(
            Invariant::ManifestRecord,
            "slot 0",
            "CRC mismatch",
        ));
        assert!(matches!(
            choose(&[torn, ManifestSlot::Empty]),
            Err(NoManifest::Corrupt(_))
        ));
    }

    #[test]
    fn tile_records_are_checked_against_the_grid_and_the_area() {
        let rect = SampleRect {
            col0: 2,
            row0: 3,
            col1: 11,
            row1: 7,
        };
        let pin = StatePin {
            pages_txn: 1,
            state_crc: 7,
        };
        let t = TileRecord::new("a.fmrh", rect, pin, (0.0, 1.0));
        assert_eq!((t.rect(), t.name(), t.pin()), (rect, "a.fmrh", pin));
        assert!(t.check(0, 12, 8, 0, true).is_ok());
        assert!(
            t.check(0, 11, 8, 0, true).is_err(),
            "past the grid's last column"
        );
        let mut r = t;
        r.adjacency_offset = 8.into();
        r.adjacency_len = 16.into();
        assert!(r.check(0, 12, 8, 4096, true).is_ok());
        assert!(r.check(0, 12, 8, 20, true).is_err(), "tables past the area");
        r.adjacency_len = 0.into();
        assert!(
            r.check(0, 12, 8, 4096, true).is_err(),
            "an offset without a length"
        );
        let mut r = t;
        r.min_height = 5.0.into();
        assert!(r.check(0, 12, 8, 0, true).is_err(), "min above max");
        r.min_height = f32::INFINITY.into();
        r.max_height = f32::NEG_INFINITY.into();
        assert!(
            r.check(0, 12, 8, 0, true).is_ok(),
            "an all-void tile's empty range"
        );
        for name in ["", ".a.fmrh", "a.tif", "a/b.fmrh", "../a.fmrh", "é.fmrh"] {
            assert!(!tile_name_is_valid(name), "{name:?}");
        }
        assert!(tile_name_is_valid("N43E006-2.fmrh"));
        assert!(!tile_name_is_valid(&format!("{}.fmrh", "a".repeat(52))));
    }

    #[test]
    fn a_pin_names_the_state_not_the_slot() {
        use crate::format::{CommitRecord, StateRoots, COMMIT_RECOVERY_NEEDED};
        let r = CommitRecord::new(4096, 5, 1 << 20, 0, StateRoots::default());
        let pin = StatePin::of(&r);
        // A mark or a clean close: another txn id and flags, the same state.
        assert!(pin.matches(&r.copy_as(9, COMMIT_RECOVERY_NEEDED)));
        // Another state: other roots, or pages another transaction wrote.
        let mut roots = StateRoots::default();
        roots.node_table.records = 3.into();
        assert!(!pin.matches(&CommitRecord::new(4096, 5, 1 << 20, 0, roots)));
        assert!(!pin.matches(&CommitRecord::new(
            4096,
            6,
            1 << 20,
            0,
            StateRoots::default()
        )));
    }
}
