//! Reaching into a container's metadata bundle (format 3.0, container.md §6.7) the way a
//! damaged or hostile file would: decompress it with zstd itself, change its pages, and
//! store it again, resealing the commit record. Tests use it to build bundles that are
//! wrong in one chosen way.

#![allow(dead_code)]

/// The commit record's page size.
pub fn page_size(bytes: &[u8]) -> usize {
    u32::from_le_bytes(bytes[12..16].try_into().unwrap()) as usize
}

/// The bundle of slot 0's record, decompressed: its pages back to back.
pub fn pages(bytes: &[u8]) -> Vec<u8> {
    let offset = u64::from_le_bytes(bytes[176..184].try_into().unwrap()) as usize;
    let len = u32::from_le_bytes(bytes[184..188].try_into().unwrap()) as usize;
    assert!(len > 0, "the file has no bundle");
    zstd::stream::decode_all(&bytes[offset..offset + len]).unwrap()
}

/// Seals a page of the bundle again after a change: the CRC of bytes 8..P at 4..8.
pub fn reseal_page(page: &mut [u8]) {
    let crc = crc32fast::hash(&page[8..]);
    page[4..8].copy_from_slice(&crc.to_le_bytes());
}

/// Replaces slot 0's bundle with `stored` bytes (any bytes, compressed or not) appended in
/// whole pages at the end of the file, saying they decompress to `pages` pages; the record's
/// offset, length, CRC, pages and file length follow, and it is resealed.
pub fn store_raw(bytes: &mut Vec<u8>, stored: &[u8], pages: u32) {
    let p = page_size(bytes);
    let offset = bytes.len();
    bytes.extend_from_slice(stored);
    bytes.resize(bytes.len().next_multiple_of(p), 0);
    bytes[176..184].copy_from_slice(&(offset as u64).to_le_bytes());
    bytes[184..188].copy_from_slice(&(stored.len() as u32).to_le_bytes());
    bytes[188..192].copy_from_slice(&crc32fast::hash(stored).to_le_bytes());
    bytes[192..196].copy_from_slice(&pages.to_le_bytes());
    let len = bytes.len() as u64;
    bytes[24..32].copy_from_slice(&len.to_le_bytes());
    let crc = crc32fast::hash(&bytes[..252]);
    bytes[252..256].copy_from_slice(&crc.to_le_bytes());
}

/// Decompresses slot 0's bundle, lets `change` edit its pages, and stores it again
/// (compressed, appended: the old stored bytes become unreachable).
pub fn rewrite(bytes: &mut Vec<u8>, change: impl FnOnce(&mut Vec<u8>)) {
    let p = page_size(bytes);
    let mut raw = pages(bytes);
    change(&mut raw);
    let count = (raw.len() / p) as u32;
    let stored = zstd::bulk::compress(&raw, 3).unwrap();
    store_raw(bytes, &stored, count);
}
