//! The state's metadata bundle as a reader holds it (format §6.7): every page decompressed
//! at open (3.x and 4.x, one frame), or each page read and checked the first time a lookup
//! reaches it (5.0, a frame per page).
//!
//! A 5.0 bundle lets a scene that needs a few pages of metadata read those pages, not the
//! whole bundle: on a mostly-sea SRTM tile a coarse scene reads the root's node page and one
//! cluster index page, where a whole bundle was 6 KB, more than a COG reader's whole scene.
//! Opening reads the *head* (the frame table, and the dataset header's and cluster
//! directory's frames, stored first) in one call; the other frames wait. Each page loaded is
//! kept for the life of the store (at most the bundle's decompressed size, 16 MiB).

use std::sync::{Arc, OnceLock};

use super::source::{self, Source};
use crate::error::{Error, Result};
use crate::format::bundle::{self, BUNDLE_FIRST_PAGE, FRAME_ENTRY_LEN};
use crate::format::{CommitRecord, Invariant, Violation};

/// A state's metadata bundle.
#[derive(Debug)]
pub(crate) enum Bundle {
    /// 3.x, 4.x: every page, decompressed and checked at open.
    Whole(Arc<[u8]>),
    /// 5.x: a frame per page, each read when first reached.
    Framed(Framed),
}

/// A 5.0 bundle: where each page's frame lies, and the pages read so far.
#[derive(Debug)]
pub(crate) struct Framed {
    /// File offset of the stored run.
    offset: u64,
    /// Per page: where its frame lies, and the frame's CRC.
    frames: Vec<bundle::Frame>,
    pages: Vec<OnceLock<Arc<[u8]>>>,
    page_size: u32,
    txn_tag: u16,
}

/// Why a bundle page could not be had.
pub(crate) enum PageError {
    /// Not a page of the bundle.
    Outside,
    /// The frame could not be read.
    Read(Error),
    /// The frame does not hold the page the state says (corrupt, or a superseded state's
    /// bytes reused).
    Bad(Violation),
}

impl Bundle {
    /// Pages it holds.
    pub fn page_count(&self, page_size: u32) -> u64 {
        match self {
            Bundle::Whole(raw) => bundle::page_count(raw, page_size),
            Bundle::Framed(f) => f.pages.len() as u64,
        }
    }

    /// Bundle page `page`: from memory, or (5.0) read from `src`, decompressed and checked
    /// the first time. `read` is told the bytes of each frame read.
    pub fn page<S: Source + ?Sized>(
        &self,
        src: &S,
        page: u64,
        page_size: u32,
        read: &dyn Fn(usize),
    ) -> std::result::Result<PageRef<'_>, PageError> {
        match self {
            Bundle::Whole(raw) => bundle::page_of(raw, page, page_size)
                .map(PageRef::Borrowed)
                .ok_or(PageError::Outside),
            Bundle::Framed(f) => f.page(src, page, read).map(PageRef::Shared),
        }
    }
}

/// A bundle page's bytes.
pub(crate) enum PageRef<'a> {
    Borrowed(&'a [u8]),
    Shared(Arc<[u8]>),
}

impl Framed {
    fn page<S: Source + ?Sized>(
        &self,
        src: &S,
        page: u64,
        read: &dyn Fn(usize),
    ) -> std::result::Result<Arc<[u8]>, PageError> {
        let i = page
            .checked_sub(BUNDLE_FIRST_PAGE)
            .and_then(|i| usize::try_from(i).ok())
            .filter(|&i| i < self.pages.len())
            .ok_or(PageError::Outside)?;
        if let Some(p) = self.pages[i].get() {
            return Ok(Arc::clone(p));
        }
        let f = self.frames[i];
        let (offset, len) = (self.offset + u64::from(f.offset), f.len);
        let frame = src.read_at(offset, len as usize).map_err(|e| {
            PageError::Read(source::read_error(src.name(), offset, len as usize, e))
        })?;
        read(frame.len());
        let bytes = bundle::decompress_page(&frame, f.crc, page, self.page_size, self.txn_tag)
            .map_err(PageError::Bad)?;
        Ok(Arc::clone(self.pages[i].get_or_init(|| Arc::from(bytes))))
    }
}

/// Reads, checks and holds the state's metadata bundle, if it has one (format §6.7). 3.x and
/// 4.x: one read of the stored bytes, their CRC against the record (a mismatch is a
/// superseded state or corruption, as for a page), then every page. 5.0: one read of the
/// head, the frame table's CRC and shape, and the head's pages.
pub(crate) fn read<S: Source + ?Sized>(src: &S, commit: &CommitRecord) -> Result<Option<Bundle>> {
    let b = commit.bundle;
    if !b.is_present() {
        return Ok(None);
    }
    let r = b.payload();
    let framed = commit.bundle_framed();
    let len = if framed {
        b.head_len.get() as usize
    } else {
        r.len as usize
    };
    let stored = src
        .read_at(r.offset, len)
        .map_err(|e| source::read_error(src.name(), r.offset, len, e))?;
    let table_len = (b.pages.get() as usize).saturating_mul(FRAME_ENTRY_LEN);
    let covered = if framed {
        stored.get(..table_len).unwrap_or(&stored)
    } else {
        &stored
    };
    let crc = bundle::stored_crc(covered);
    if crc != r.crc {
        let v = Violation::new(
            Invariant::Payload,
            format!("metadata bundle at byte {}", r.offset),
            format!("CRC {:#010x} stored, {crc:#010x} computed", r.crc),
        );
        return Err(super::slots::superseded_or_corrupt(
            src,
            super::slots::StateId {
                txn: commit.txn_id.get(),
                record_crc: commit.crc.get(),
            },
            v,
        ));
    }
    let page_size = commit.page_size.get();
    if !framed {
        let raw = bundle::decompress(&stored, b.pages.get(), page_size, commit.page_txn_tag())
            .map_err(|v| v.in_file(src.name()))?;
        return Ok(Some(Bundle::Whole(Arc::from(raw))));
    }
    let frames = bundle::frame_table(&stored[..table_len], b.pages.get(), r.len, b.head_len.get())
        .map_err(|v| v.in_file(src.name()))?;
    let f = Framed {
        offset: r.offset,
        pages: (0..frames.len()).map(|_| OnceLock::new()).collect(),
        frames,
        page_size,
        txn_tag: commit.page_txn_tag(),
    };
    // The head's frames were read with the table: keep their pages.
    for (i, fr) in f.frames.iter().enumerate() {
        let (at, end) = (fr.offset as usize, fr.offset as usize + fr.len as usize);
        if end <= stored.len() {
            let page = bundle::decompress_page(
                &stored[at..end],
                fr.crc,
                BUNDLE_FIRST_PAGE + i as u64,
                page_size,
                f.txn_tag,
            )
            .map_err(|v| v.in_file(src.name()))?;
            let _ = f.pages[i].set(Arc::from(page));
        }
    }
    Ok(Some(Bundle::Framed(f)))
}
