//! The metadata bundle (format 3.0, `format-spec/container.md` §6.7): a small state's
//! structured pages, compressed together into one byte run that the commit record names.
//!
//! A small file's metadata is mostly empty page: a cluster index of 25 entries fills 400
//! bytes of a 4 KiB page, and a file of 1,201² samples had 19 such pages (76 KiB) beside 45
//! KiB of payloads. Smaller pages would risk the crash-safety argument (a page must be at
//! least a physical sector, §11), so instead the pages stay as they are and are *stored*
//! compressed:
//!
//! ```text
//!  commit record (bytes 176..200)          the file
//!  ┌──────────┬──────┬──────┬───────┐       ┌────────────────────────────────────┐
//!  │ offset   │ len  │ crc  │ pages │ ────▶ │ … payloads … │ zstd frame (len B)  │
//!  └──────────┴──────┴──────┴───────┘       └────────────────────────────────────┘
//!                                                 │ decompresses to exactly pages·P bytes
//!                                                 ▼
//!                 bundle page i = page number BUNDLE_FIRST_PAGE + i, a structured page
//!                 exactly as §4 (tag, CRC, own number, txn tag), reached by the same
//!                 BlobRefs, TreeRefs and branch entries as any page
//! ```
//!
//! The run is bound like a payload: by the CRC in the (sealed) commit record. A reader reads
//! it whole when it opens the state (one read), checks every page once, and from then on
//! serves lookups from memory. Page numbers at and above [`BUNDLE_FIRST_PAGE`] name bundle
//! pages and never a file page, so every tree, blob and check works unchanged on both.

use zerocopy::byteorder::little_endian::{U32, U64};
use zerocopy::IntoBytes;

use super::page::PageHeader;
use super::{crc32, tag, Invariant, Violation};

/// The page number of a bundle's first page: 2^40. A file has fewer pages than this (§10),
/// so a page number tells by itself whether it names a file page or a bundle page.
pub const BUNDLE_FIRST_PAGE: u64 = 1 << 40;

/// The most bytes a bundle decompresses to: a reader allocates no more, whatever the record
/// says.
pub const MAX_BUNDLE_BYTES: u64 = 16 << 20;

/// The default most stored bytes a writer gives a bundle: a state whose compressed
/// metadata is larger keeps it in file pages, read page by page as lookups reach them. Since
/// 5.0 a reader reads a bundle page by page too (opening reads only its head), so the limit
/// no longer bounds opening; it bounds what a build compresses at level 19. Commits have
/// their own, larger limit ([`COMMIT_BUNDLE_LIMIT`]).
pub const DEFAULT_BUNDLE_LIMIT: u64 = 32 << 10;

/// The default most stored bytes a *commit* gives a bundle (`Container::set_bundle_limit`
/// changes it): larger than a build's, because a commit writes every table again, bundled or
/// paged, and the bundle is the smaller by far (Puget Sound 4k: 220 pages of tables, 76
/// of bundle), so it is what a commit writes and what the file must hold twice while the
/// old state is still reachable (issue 39: the tables alone kept an edited Puget Sound 4k at
/// 1.25x a fresh build).
pub const COMMIT_BUNDLE_LIMIT: u64 = 1 << 20;

/// The zstd level a writer compresses a bundle with.
pub const BUNDLE_ZSTD_LEVEL: i32 = 19;

on_disk! {
    /// Where a state's bundle lies (commit record bytes 176..200; all zero for no bundle).
    #[derive(Default, Eq)]
    pub struct BundleRef {
        /// Absolute byte offset of the stored (compressed) bytes.
        pub offset: U64,
        /// Stored bytes; 0 for no bundle.
        pub stored_len: U32,
        /// CRC of the stored bytes.
        pub crc: U32,
        /// Pages the bundle decompresses to.
        pub pages: U32,
        /// 5.0: bytes of the stored run's *head*, the frame table and the frames stored first,
        /// which a reader reads when it opens the state. Zero (reserved) before 5.0.
        pub head_len: U32,
    }
}

const _: () = assert!(size_of::<BundleRef>() == 24);

impl BundleRef {
    /// Whether the state has a bundle.
    pub fn is_present(&self) -> bool {
        self.stored_len.get() != 0
    }

    /// The stored bytes as a payload reference (their place and CRC).
    pub fn payload(&self) -> super::PayloadRef {
        super::PayloadRef {
            offset: self.offset.get(),
            len: self.stored_len.get(),
            crc: self.crc.get(),
        }
    }

    /// Checks the reference against the record it sits in: absent means all zero; present
    /// means past the commit slots, inside `file_length`, at least one page and at most
    /// [`MAX_BUNDLE_BYTES`] decompressed, and (`framed`, 5.0) a head that holds the frame
    /// table and lies within the run. (`head_len` before 5.0 is the record's to check.)
    pub fn check(&self, page_size: u32, file_length: u64, framed: bool) -> Result<(), String> {
        if !self.is_present() {
            if self.as_bytes().iter().any(|&b| b != 0) {
                return Err("a bundle of 0 bytes with other fields set".into());
            }
            return Ok(());
        }
        let (offset, len) = (self.offset.get(), u64::from(self.stored_len.get()));
        let pages = u64::from(self.pages.get());
        if offset < 2 * u64::from(page_size) || offset.saturating_add(len) > file_length {
            return Err(format!(
                "bundle of {len} bytes at byte {offset} lies outside {}..{file_length}",
                2 * page_size
            ));
        }
        if pages == 0 || pages * u64::from(page_size) > MAX_BUNDLE_BYTES {
            return Err(format!(
                "bundle of {pages} pages: 1 to {} allowed at this page size",
                MAX_BUNDLE_BYTES / u64::from(page_size)
            ));
        }
        let head = u64::from(self.head_len.get());
        if framed && (head < pages * FRAME_ENTRY_LEN as u64 || head > len) {
            return Err(format!(
                "a head of {head} bytes: the frame table of {pages} pages to the run's {len}"
            ));
        }
        Ok(())
    }
}

/// Whether `page` names a bundle page rather than a file page.
#[inline]
pub fn is_bundle_page(page: u64) -> bool {
    page >= BUNDLE_FIRST_PAGE
}

/// The tags a bundle page may carry: every structured page but the free list's, which
/// names file pages and stays in the file (§6.7).
const BUNDLE_TAGS: [[u8; 4]; 6] = [
    tag::DATASET_HEADER,
    tag::CLUSTER_DIRECTORY,
    tag::NODE_TABLE,
    tag::BLOCK_TABLE,
    tag::CLUSTER_INDEX,
    tag::ADJACENCY,
];

/// Compresses `pages` (each `page_size` bytes, numbered from [`BUNDLE_FIRST_PAGE`]) into
/// the stored form of 3.x and 4.x: one zstd frame.
pub fn compress(pages: &[Vec<u8>], level: i32) -> std::io::Result<Vec<u8>> {
    let raw: Vec<u8> = pages.concat();
    zstd::bulk::compress(&raw, level)
}

/// Decompresses and checks a bundle's stored bytes (whose CRC the caller has checked): it
/// must be one zstd frame of exactly `pages · page_size` bytes, and every page must be a
/// sealed structured page carrying its own bundle page number, a bundle tag and
/// `txn_tag`. Never allocates more than `pages · page_size` bytes.
pub fn decompress(
    stored: &[u8],
    pages: u32,
    page_size: u32,
    txn_tag: u16,
) -> Result<Vec<u8>, Violation> {
    let want = u64::from(pages) * u64::from(page_size);
    let bad = |detail: String| Violation::new(Invariant::Page, "metadata bundle", detail);
    if want > MAX_BUNDLE_BYTES || want == 0 {
        return Err(bad(format!("{pages} pages")));
    }
    let cap = usize::try_from(want).map_err(|_| bad(format!("{pages} pages")))?;
    // The frame's declared size is checked against the capacity before any output.
    let raw = zstd::bulk::decompress(stored, cap)
        .map_err(|e| bad(format!("does not decompress within {want} bytes: {e}")))?;
    if raw.len() != cap {
        return Err(bad(format!(
            "decompresses to {} bytes; the record says {pages} pages of {page_size}",
            raw.len()
        )));
    }
    for (i, page) in raw.chunks_exact(page_size as usize).enumerate() {
        check_bundle_page(page, BUNDLE_FIRST_PAGE + i as u64, txn_tag)?;
    }
    Ok(raw)
}

/// Bytes of a frame table entry (5.0): the frame's offset from the start of the stored run,
/// its length and the CRC of its stored bytes, each `u32`. The record's CRC covers the table,
/// and the table's CRCs the frames: every stored byte is bound, as a payload's are.
pub const FRAME_ENTRY_LEN: usize = 12;

/// Compresses `pages` into the stored form of 5.0: a frame table, then one zstd frame per
/// page. The frames of the pages `head` lists (those opening reads: the dataset header and
/// the cluster directory) come first, in page order, then the others in page order. Returns
/// the stored run and the length of its head: the table and the head's frames, which a
/// reader reads in one call when it opens the state.
pub fn compress_framed(
    pages: &[Vec<u8>],
    head: &[usize],
    level: i32,
) -> std::io::Result<(Vec<u8>, u32)> {
    // One context for every page: making one costs about as much as compressing a page.
    let mut z = zstd::bulk::Compressor::new(level)?;
    let frames: Vec<Vec<u8>> = pages
        .iter()
        .map(|p| z.compress(p))
        .collect::<std::io::Result<_>>()?;
    let too_long = || std::io::Error::other("a metadata bundle past 4 GiB");
    let table_len = pages.len() * FRAME_ENTRY_LEN;
    let order: Vec<usize> = head
        .iter()
        .copied()
        .filter(|&i| i < pages.len())
        .chain((0..pages.len()).filter(|i| !head.contains(i)))
        .collect();
    let mut table = vec![0u8; table_len];
    let mut body = Vec::new();
    let mut head_len = table_len;
    for (k, &i) in order.iter().enumerate() {
        let at = u32::try_from(table_len + body.len()).map_err(|_| too_long())?;
        let len = u32::try_from(frames[i].len()).map_err(|_| too_long())?;
        let e = &mut table[i * FRAME_ENTRY_LEN..(i + 1) * FRAME_ENTRY_LEN];
        e[..4].copy_from_slice(&at.to_le_bytes());
        e[4..8].copy_from_slice(&len.to_le_bytes());
        e[8..].copy_from_slice(&crc32(&frames[i]).to_le_bytes());
        body.extend_from_slice(&frames[i]);
        if k < head.len() {
            head_len = table_len + body.len();
        }
    }
    table.extend_from_slice(&body);
    Ok((table, u32::try_from(head_len).map_err(|_| too_long())?))
}

/// A page's frame in a 5.0 stored run.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Frame {
    /// Offset from the run's start.
    pub offset: u32,
    /// Stored bytes.
    pub len: u32,
    /// CRC of the stored bytes.
    pub crc: u32,
}

/// Where each page's frame lies in a 5.0 stored run, by page. Checked to tile the run after
/// the table exactly, each frame non-empty, and the head (`head_len` bytes) to end on a
/// frame's end.
pub fn frame_table(
    table: &[u8],
    pages: u32,
    stored_len: u32,
    head_len: u32,
) -> Result<Vec<Frame>, Violation> {
    let bad = |detail: String| Violation::new(Invariant::Page, "metadata bundle", detail);
    let n = pages as usize;
    let table_len = n
        .checked_mul(FRAME_ENTRY_LEN)
        .filter(|&l| l == table.len())
        .ok_or_else(|| {
            bad(format!(
                "a frame table of {} bytes for {pages} pages",
                table.len()
            ))
        })?;
    let frames: Vec<Frame> = table
        .chunks_exact(FRAME_ENTRY_LEN)
        .map(|e| Frame {
            offset: u32::from_le_bytes([e[0], e[1], e[2], e[3]]),
            len: u32::from_le_bytes([e[4], e[5], e[6], e[7]]),
            crc: u32::from_le_bytes([e[8], e[9], e[10], e[11]]),
        })
        .collect();
    let mut sorted: Vec<(u32, u32)> = frames.iter().map(|f| (f.offset, f.len)).collect();
    sorted.sort_unstable();
    let mut at = u64::try_from(table_len).unwrap_or(u64::MAX);
    let mut head_on_boundary = u64::from(head_len) == at;
    for &(offset, len) in &sorted {
        if u64::from(offset) != at || len == 0 {
            return Err(bad(format!(
                "a frame of {len} bytes at {offset}, where the frames before it end at {at}"
            )));
        }
        at += u64::from(len);
        head_on_boundary |= u64::from(head_len) == at;
    }
    if at != u64::from(stored_len) {
        return Err(bad(format!(
            "frames end at {at}; the run is {stored_len} bytes"
        )));
    }
    if !head_on_boundary {
        return Err(bad(format!(
            "a head of {head_len} bytes does not end where a frame does"
        )));
    }
    Ok(frames)
}

/// Checks one frame of a 5.0 bundle against the CRC its table entry holds (`crc`), then
/// decompresses it: exactly one sealed structured page carrying bundle page number
/// `page_no`, a bundle tag and `txn_tag`. Never allocates more than a page.
pub fn decompress_page(
    frame: &[u8],
    crc: u32,
    page_no: u64,
    page_size: u32,
    txn_tag: u16,
) -> Result<Vec<u8>, Violation> {
    thread_local! {
        // One decompression context a thread: making one per page cost as much as the page.
        static DCTX: std::cell::RefCell<Option<zstd::bulk::Decompressor<'static>>> =
            const { std::cell::RefCell::new(None) };
    }
    let at = || format!("page {page_no}");
    let computed = crc32(frame);
    if computed != crc {
        return Err(Violation::new(
            Invariant::Page,
            at(),
            format!("its frame's CRC is {computed:#010x}; the frame table says {crc:#010x}"),
        ));
    }
    let page = DCTX
        .with(|d| {
            let mut d = d.borrow_mut();
            if d.is_none() {
                *d = Some(zstd::bulk::Decompressor::new()?);
            }
            match d.as_mut() {
                Some(d) => d.decompress(frame, page_size as usize),
                None => Err(std::io::Error::other("no zstd context")),
            }
        })
        .map_err(|e| {
            Violation::new(
                Invariant::Page,
                at(),
                format!("its frame does not decompress within {page_size} bytes: {e}"),
            )
        })?;
    if page.len() != page_size as usize {
        return Err(Violation::new(
            Invariant::Page,
            at(),
            format!("its frame decompresses to {} bytes", page.len()),
        ));
    }
    check_bundle_page(&page, page_no, txn_tag)?;
    Ok(page)
}

/// Checks a page of a bundle: a sealed structured page with its own bundle page number, a
/// bundle tag and the state's `txn_tag`.
fn check_bundle_page(page: &[u8], page_no: u64, txn_tag: u16) -> Result<(), Violation> {
    let Some(h) = PageHeader::read(page) else {
        return Err(Violation::new(
            Invariant::Page,
            format!("page {page_no}"),
            "short",
        ));
    };
    if !BUNDLE_TAGS.contains(&h.tag) {
        return Err(Violation::new(
            Invariant::Page,
            format!("page {page_no}"),
            format!(
                "tag {:?} in the metadata bundle",
                String::from_utf8_lossy(&h.tag)
            ),
        ));
    }
    let h = super::page::check_page(page, page_no, h.tag)?;
    if h.txn_tag.get() != txn_tag {
        return Err(Violation::new(
            Invariant::Page,
            format!("page {page_no}"),
            format!(
                "carries txn tag {:#06x}; the state's pages carry {txn_tag:#06x}",
                h.txn_tag.get()
            ),
        ));
    }
    Ok(())
}

/// The CRC a [`BundleRef`] holds for `stored`.
pub fn stored_crc(stored: &[u8]) -> u32 {
    crc32(stored)
}

/// Pages in a decompressed bundle of `raw` bytes.
#[inline]
pub fn page_count(raw: &[u8], page_size: u32) -> u64 {
    (raw.len() / page_size as usize) as u64
}

/// Page `page` (a bundle page number) of a decompressed bundle, if it has it.
#[inline]
pub fn page_of(raw: &[u8], page: u64, page_size: u32) -> Option<&[u8]> {
    let i = usize::try_from(page.checked_sub(BUNDLE_FIRST_PAGE)?).ok()?;
    let p = page_size as usize;
    raw.get(i.checked_mul(p)?..i.checked_mul(p)?.checked_add(p)?)
}

#[cfg(test)]
#[allow(clippy::cast_possible_truncation)] // small test sizes
mod tests {
    use super::*;
    use crate::format::blob::encode_blob;

    fn pages(n: usize) -> Vec<Vec<u8>> {
        let content: Vec<u8> = (0..n * 4000).map(|i| (i % 7) as u8).collect();
        encode_blob(&content, tag::DATASET_HEADER, BUNDLE_FIRST_PAGE, 3, 4096).1
    }

    #[test]
    fn a_bundle_round_trips_and_checks_its_pages() {
        let p = pages(3);
        let stored = compress(&p, 3).unwrap();
        assert!(stored.len() < 1000, "{}", stored.len());
        let raw = decompress(&stored, p.len() as u32, 4096, 3).unwrap();
        assert_eq!(raw, p.concat());
        assert_eq!(page_of(&raw, BUNDLE_FIRST_PAGE + 1, 4096), Some(&p[1][..]));
        assert_eq!(page_of(&raw, BUNDLE_FIRST_PAGE + 3, 4096), None);
        assert_eq!(page_of(&raw, 5, 4096), None);
        // Wrong txn tag, wrong page count (either way), garbage.
        assert!(decompress(&stored, p.len() as u32, 4096, 4).is_err());
        assert!(decompress(&stored, p.len() as u32 + 1, 4096, 3).is_err());
        assert!(decompress(&stored, p.len() as u32 - 1, 4096, 3).is_err());
        assert!(decompress(b"not zstd at all", 1, 4096, 3).is_err());
    }

    #[test]
    fn a_framed_bundle_reads_page_by_page_and_checks_each() {
        let p = pages(4);
        let (stored, head) = compress_framed(&p, &[2], 3).unwrap();
        let table_len = 4 * FRAME_ENTRY_LEN;
        let frames = frame_table(&stored[..table_len], 4, stored.len() as u32, head).unwrap();
        // Page 2's frame is stored first, and the head ends with it.
        assert_eq!(frames[2].offset as usize, table_len);
        assert_eq!(head as usize, table_len + frames[2].len as usize);
        for (i, f) in frames.iter().enumerate() {
            let frame = &stored[f.offset as usize..(f.offset + f.len) as usize];
            let no = BUNDLE_FIRST_PAGE + i as u64;
            let page = decompress_page(frame, f.crc, no, 4096, 3).unwrap();
            assert_eq!(page, p[i]);
            // Another page's number, another state's tag, or another CRC is refused.
            assert!(decompress_page(frame, f.crc, no + 1, 4096, 3).is_err());
            assert!(decompress_page(frame, f.crc, no, 4096, 4).is_err());
            assert!(decompress_page(frame, f.crc ^ 1, no, 4096, 3).is_err());
        }
        // A table whose frames overlap, leave a gap, run past the run, or whose head ends
        // inside a frame is refused.
        let mut overlap = stored[..table_len].to_vec();
        overlap[FRAME_ENTRY_LEN..FRAME_ENTRY_LEN + 4]
            .copy_from_slice(&frames[0].offset.to_le_bytes());
        assert!(frame_table(&overlap, 4, stored.len() as u32, head).is_err());
        assert!(frame_table(&stored[..table_len], 4, stored.len() as u32 + 1, head).is_err());
        assert!(frame_table(&stored[..table_len], 4, stored.len() as u32, head + 1).is_err());
        assert!(frame_table(&stored[..table_len - 1], 4, stored.len() as u32, head).is_err());
        let bomb = zstd::bulk::compress(&vec![0u8; 64 << 20], 1).unwrap();
        assert!(decompress_page(&bomb, crc32(&bomb), BUNDLE_FIRST_PAGE, 4096, 3).is_err());
    }

    #[test]
    fn a_frame_larger_than_its_pages_is_refused_without_allocating_it() {
        // 64 MiB of zeros compresses to a few KiB: a bomb a reader must not inflate.
        let bomb = zstd::bulk::compress(&vec![0u8; 64 << 20], 1).unwrap();
        let e = decompress(&bomb, 1, 4096, 1).unwrap_err();
        assert_eq!(e.invariant, Invariant::Page);
        assert!(decompress(&bomb, u32::MAX, 65536, 1).is_err());
    }

    #[test]
    fn references_are_checked_against_the_record() {
        let r = BundleRef {
            offset: U64::new(8192),
            stored_len: U32::new(100),
            crc: U32::new(1),
            pages: U32::new(2),
            head_len: U32::new(0),
        };
        assert!(r.check(4096, 12288, false).is_ok());
        assert!(r.check(4096, 8200, false).is_err());
        // Framed (5.0): the head holds the frame table and lies within the run.
        assert!(r.check(4096, 12288, true).is_err());
        let framed = BundleRef {
            head_len: U32::new(40),
            ..r
        };
        assert!(framed.check(4096, 12288, true).is_ok());
        for head in [15, 101] {
            let bad = BundleRef {
                head_len: U32::new(head),
                ..r
            };
            assert!(bad.check(4096, 12288, true).is_err(), "{head}");
        }
        let early = BundleRef {
            offset: U64::new(4096),
            ..r
        };
        assert!(early.check(4096, 12288, false).is_err());
        let huge = BundleRef {
            pages: U32::new(u32::MAX),
            ..r
        };
        assert!(huge.check(4096, 12288, false).is_err());
        let stray = BundleRef {
            stored_len: U32::new(0),
            ..r
        };
        assert!(stray.check(4096, 12288, false).is_err());
        assert!(BundleRef::default().check(4096, 8192, false).is_ok());
    }
}
