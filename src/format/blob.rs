//! Blobs: a run of consecutive structured pages holding one byte string (the dataset header,
//! the cluster directory).
//!
//! Each page holds `P - 24` content bytes after its header, whose `count` says how many; every
//! page but the last is full, `level` is 0, and the bytes after the content are zero.

use zerocopy::byteorder::little_endian::U64;

use super::page::{check_page, check_tail, encode_page, PageStamp, PAGE_HEADER_LEN};
use super::{Invariant, Violation};

on_disk! {
    /// Where a blob lives: pages `first_page ..` holding `length` content bytes.
    #[derive(Default, Eq)]
    pub struct BlobRef {
        /// First page of the run.
        pub first_page: U64,
        /// Content bytes (the pages hold `P - 24` content bytes each).
        pub length: U64,
    }
}

const _: () = assert!(size_of::<BlobRef>() == 16);

/// Content bytes one blob page holds.
pub fn content_per_page(page_size: u32) -> u64 {
    u64::from(page_size) - PAGE_HEADER_LEN as u64
}

/// Pages a blob of `length` bytes occupies.
pub fn blob_pages(length: u64, page_size: u32) -> u64 {
    length.div_ceil(content_per_page(page_size))
}

/// The sealed pages of a blob of `content` starting at page `first_page`, written by
/// transaction `txn`, and its reference.
pub fn encode_blob(
    content: &[u8],
    tag: [u8; 4],
    first_page: u64,
    txn: u64,
    page_size: u32,
) -> (BlobRef, Vec<Vec<u8>>) {
    let per_page = page_size as usize - PAGE_HEADER_LEN;
    let pages = content
        .chunks(per_page)
        .zip(first_page..)
        .map(|(chunk, page_no)| {
            // A chunk is at most `per_page` < 2^16 bytes.
            let count = u32::try_from(chunk.len()).unwrap_or(u32::MAX);
            encode_page(page_size, tag, PageStamp { page_no, txn }, 0, count, chunk)
        })
        .collect();
    let blob = BlobRef {
        first_page: U64::new(first_page),
        length: U64::new(content.len() as u64),
    };
    (blob, pages)
}

/// Checks a blob reference against the file before any page is read: not empty, at most
/// `max_len` bytes, every page past the commit slots and inside `page_count` pages, or every
/// page inside the state's `bundle_pages` bundle pages (§6.7). Returns the pages it occupies.
pub fn check_blob_ref(
    blob: &BlobRef,
    max_len: u64,
    page_size: u32,
    page_count: u64,
    bundle_pages: u64,
    name: &str,
) -> Result<u64, Violation> {
    let (len, first) = (blob.length.get(), blob.first_page.get());
    let pages = blob_pages(len, page_size);
    let (lo, hi) = if super::bundle::is_bundle_page(first) {
        let b = super::bundle::BUNDLE_FIRST_PAGE;
        (b, b + bundle_pages)
    } else {
        (2, page_count)
    };
    if len == 0 || len > max_len || first < lo || first.saturating_add(pages) > hi {
        return Err(Violation::new(
            Invariant::DatasetHeader,
            name,
            format!("blob of {len} bytes at page {first} does not fit the file"),
        ));
    }
    Ok(pages)
}

/// The content of page `index` (from 0) of `blob`, which is page `page_no` of the file:
/// checks its header (I-5, all but the txn tag), its count, and its zero tail.
pub fn blob_page_content<'p>(
    page: &'p [u8],
    blob: &BlobRef,
    index: u64,
    tag: [u8; 4],
    page_size: u32,
    name: &str,
) -> Result<&'p [u8], Violation> {
    let page_no = blob.first_page.get().saturating_add(index);
    let h = check_page(page, page_no, tag)?;
    let per_page = content_per_page(page_size);
    let want = blob
        .length
        .get()
        .saturating_sub(index.saturating_mul(per_page))
        .min(per_page);
    let at = format!("{name} page {page_no}");
    if u64::from(h.count.get()) != want || h.level.get() != 0 {
        return Err(Violation::new(
            Invariant::Page,
            at,
            format!("holds {} bytes, expected {want}", h.count.get()),
        ));
    }
    // `want` is at most a page's content.
    let end = PAGE_HEADER_LEN + usize::try_from(want).unwrap_or(usize::MAX);
    check_tail(page, end, &at)?;
    Ok(&page[PAGE_HEADER_LEN..end])
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::format::page::tag;

    #[test]
    fn a_blob_round_trips_across_pages() {
        let content: Vec<u8> = (0..2500u32).map(|i| i.to_le_bytes()[0]).collect();
        let (blob, pages) = encode_blob(&content, tag::DATASET_HEADER, 5, 1, 1024);
        assert_eq!(pages.len() as u64, blob_pages(2500, 1024));
        assert_eq!(check_blob_ref(&blob, 4096, 1024, 8, 0, "b").unwrap(), 3);
        assert!(check_blob_ref(&blob, 4096, 1024, 7, 9, "b").is_err());
        // In a bundle: inside its pages, never straddling its end.
        let b = crate::format::bundle::BUNDLE_FIRST_PAGE;
        let (bundled, _) = encode_blob(&content, tag::DATASET_HEADER, b + 1, 1, 1024);
        assert_eq!(check_blob_ref(&bundled, 4096, 1024, 8, 4, "b").unwrap(), 3);
        assert!(check_blob_ref(&bundled, 4096, 1024, 1 << 41, 3, "b").is_err());
        let mut back = Vec::new();
        for (i, page) in pages.iter().enumerate() {
            let part =
                blob_page_content(page, &blob, i as u64, tag::DATASET_HEADER, 1024, "b").unwrap();
            back.extend_from_slice(part);
        }
        assert_eq!(back, content);
    }
}
