//! Reaching into a container's metadata bundle (format 3.0 and 5.0, container.md §6.7) the
//! way a damaged or hostile file would: decompress it with zstd itself, change its pages, and
//! store it again, resealing the commit record. Tests use it to build bundles that are
//! wrong in one chosen way. A record of major 5 or later stores a frame table and a frame
//! per page; older ones one frame.

#![allow(dead_code)]

/// The commit record's page size.
pub fn page_size(bytes: &[u8]) -> usize {
    u32::from_le_bytes(bytes[12..16].try_into().unwrap()) as usize
}

/// Whether slot 0's record stores its bundle a frame per page (major 5 and later).
pub fn framed(bytes: &[u8]) -> bool {
    u16::from_le_bytes([bytes[8], bytes[9]]) >= 5
}

/// The bundle of slot 0's record, decompressed: its pages back to back.
pub fn pages(bytes: &[u8]) -> Vec<u8> {
    let offset = u64::from_le_bytes(bytes[176..184].try_into().unwrap()) as usize;
    let len = u32::from_le_bytes(bytes[184..188].try_into().unwrap()) as usize;
    assert!(len > 0, "the file has no bundle");
    if !framed(bytes) {
        return zstd::stream::decode_all(&bytes[offset..offset + len]).unwrap();
    }
    let n = u32::from_le_bytes(bytes[192..196].try_into().unwrap()) as usize;
    let mut out = Vec::new();
    for i in 0..n {
        let e = offset + 12 * i;
        let at = u32::from_le_bytes(bytes[e..e + 4].try_into().unwrap()) as usize;
        let flen = u32::from_le_bytes(bytes[e + 4..e + 8].try_into().unwrap()) as usize;
        out.extend(zstd::stream::decode_all(&bytes[offset + at..offset + at + flen]).unwrap());
    }
    out
}

/// Seals a page of the bundle again after a change: the CRC of bytes 8..P at 4..8.
pub fn reseal_page(page: &mut [u8]) {
    let crc = crc32fast::hash(&page[8..]);
    page[4..8].copy_from_slice(&crc.to_le_bytes());
}

/// Appends `stored` in whole pages at the end of the file and makes slot 0's record name it:
/// offset, length, `crc`, `pages`, `head_len` and the file length follow, and it is resealed.
fn point_at(bytes: &mut Vec<u8>, stored: &[u8], crc: u32, pages: u32, head_len: u32) {
    let p = page_size(bytes);
    let offset = bytes.len();
    bytes.extend_from_slice(stored);
    bytes.resize(bytes.len().next_multiple_of(p), 0);
    bytes[176..184].copy_from_slice(&(offset as u64).to_le_bytes());
    bytes[184..188].copy_from_slice(&(stored.len() as u32).to_le_bytes());
    bytes[188..192].copy_from_slice(&crc.to_le_bytes());
    bytes[192..196].copy_from_slice(&pages.to_le_bytes());
    bytes[196..200].copy_from_slice(&head_len.to_le_bytes());
    let len = bytes.len() as u64;
    bytes[24..32].copy_from_slice(&len.to_le_bytes());
    let crc = crc32fast::hash(&bytes[..252]);
    bytes[252..256].copy_from_slice(&crc.to_le_bytes());
}

/// Replaces slot 0's bundle (3.x, 4.x: one frame) with `stored` bytes (any bytes, compressed
/// or not), saying they decompress to `pages` pages.
pub fn store_raw(bytes: &mut Vec<u8>, stored: &[u8], pages: u32) {
    assert!(!framed(bytes));
    point_at(bytes, stored, crc32fast::hash(stored), pages, 0);
}

/// Replaces slot 0's bundle (5.0: a frame per page) with `frames` (any bytes; entry `i` of
/// the table names `frames[i]`, with its CRC) behind a frame table, the frames of the pages `head` lists
/// stored first as the head, saying there are `pages` pages (the table has an entry per
/// frame either way).
pub fn store_frames(bytes: &mut Vec<u8>, frames: &[Vec<u8>], head: &[usize], pages: u32) {
    assert!(framed(bytes));
    let table_len = 12 * frames.len();
    let mut table = vec![0u8; table_len];
    let mut body = Vec::new();
    let mut head_len = table_len;
    let order = head
        .iter()
        .copied()
        .chain((0..frames.len()).filter(|i| !head.contains(i)));
    for (k, i) in order.enumerate() {
        let e = &mut table[12 * i..12 * i + 12];
        e[..4].copy_from_slice(&((table_len + body.len()) as u32).to_le_bytes());
        e[4..8].copy_from_slice(&(frames[i].len() as u32).to_le_bytes());
        e[8..].copy_from_slice(&crc32fast::hash(&frames[i]).to_le_bytes());
        body.extend_from_slice(&frames[i]);
        if k < head.len() {
            head_len = table_len + body.len();
        }
    }
    let crc = crc32fast::hash(&table);
    table.extend_from_slice(&body);
    point_at(bytes, &table, crc, pages, head_len as u32);
}

/// Decompresses slot 0's bundle, lets `change` edit its pages, and stores it again
/// (compressed, appended: the old stored bytes become unreachable). A framed bundle keeps the
/// writer's order: the dataset header's and cluster directory's frames first, as the head.
pub fn rewrite(bytes: &mut Vec<u8>, change: impl FnOnce(&mut Vec<u8>)) {
    let p = page_size(bytes);
    let mut raw = pages(bytes);
    change(&mut raw);
    let count = (raw.len() / p) as u32;
    if !framed(bytes) {
        let stored = zstd::bulk::compress(&raw, 3).unwrap();
        store_raw(bytes, &stored, count);
        return;
    }
    let pages: Vec<Vec<u8>> = raw.chunks(p).map(|c| c.to_vec()).collect();
    let head: Vec<usize> = (0..pages.len())
        .filter(|&i| &pages[i][..4] == b"FMHD" || &pages[i][..4] == b"FMCD")
        .collect();
    let (stored, head_len) = fmrh::format::bundle::compress_framed(&pages, &head, 3).unwrap();
    let crc = crc32fast::hash(&stored[..12 * pages.len()]);
    point_at(bytes, &stored, crc, count, head_len);
}
