//! The input handling of the `open_verify` fuzz target, shared with `tests/fuzz_regressions.rs`,
//! which replays the target's corpus (its seeds and every input that once crashed it) on every
//! test run. See `open_verify.rs` for the modes.

const VECTORS: [&[u8]; 8] = [
    include_bytes!("../../format-spec/vectors/ramp-9x9.fmrh"),
    include_bytes!("../../format-spec/vectors/hills-20x13-voids.fmrh"),
    include_bytes!("../../format-spec/vectors/cliff-33x33.fmrh"),
    include_bytes!("../../format-spec/vectors/v1.1/hills-20x13-voids.fmrh"),
    include_bytes!("../../format-spec/vectors/waves-17x17-precision-0.3.fmrh"),
    include_bytes!("../../format-spec/vectors/hills-20x13-voids-paged.fmrh"),
    include_bytes!("../../format-spec/vectors/v2.1/cliff-33x33.fmrh"),
    include_bytes!("../../format-spec/vectors/v4.0/hills-20x13-voids.fmrh"),
];

const TAGS: [&[u8; 4]; 7] = [
    b"FMHD", b"FMCD", b"FMNT", b"FMBT", b"FMCI", b"FMAJ", b"FMFL",
];

/// `original` with `edits` applied and every checksum recomputed. An edit whose offset has
/// its top bit set lands in the decompressed metadata bundle (format 3.0) when the file has
/// one; the bundle is then compressed again (one frame before 5.0, a frame per page from 5.0
/// on) and stored at the end of the file, and the record names it (offset, length, CRC,
/// pages, head, file length).
pub fn resealed(original: &[u8], edits: &[u8]) -> Vec<u8> {
    let mut bytes = original.to_vec();
    let mut bundle = bundle_pages(&bytes);
    let mut bundle_edited = false;
    for e in edits.chunks_exact(4) {
        let at = usize::from(e[0]) | usize::from(e[1]) << 8 | usize::from(e[2] & 0x7f) << 16;
        match bundle.as_mut() {
            Some(b) if e[2] & 0x80 != 0 => {
                let i = at % b.len();
                b[i] = e[3];
                bundle_edited = true;
            }
            _ => {
                let i = at % bytes.len();
                bytes[i] = e[3];
            }
        }
    }
    // The vectors use 1 KiB pages; a page size edited away leaves the other checksums wrong,
    // which is fine: that path is the raw mode's.
    let p = 1024;
    for page in bytes.chunks_exact_mut(p).skip(2) {
        reseal_page(page);
    }
    if let (Some(mut b), true) = (bundle, bundle_edited) {
        for page in b.chunks_exact_mut(p) {
            reseal_page(page);
        }
        let pages: Vec<Vec<u8>> = b.chunks(p).map(|c| c.to_vec()).collect();
        let (stored, crc, head_len) = if framed(&bytes) {
            let head: Vec<usize> = (0..pages.len())
                .filter(|&i| pages[i][..4] == *b"FMHD" || pages[i][..4] == *b"FMCD")
                .collect();
            let (stored, head_len) =
                fmrh::format::bundle::compress_framed(&pages, &head, 1).unwrap_or_default();
            let crc = crc32fast::hash(stored.get(..12 * pages.len()).unwrap_or(&[]));
            (stored, crc, head_len)
        } else {
            let stored = fmrh::format::bundle::compress(&[b.clone()], 1).unwrap_or_default();
            let crc = crc32fast::hash(&stored);
            (stored, crc, 0)
        };
        let offset = bytes.len();
        bytes.extend_from_slice(&stored);
        bytes.resize(bytes.len().next_multiple_of(p), 0);
        let len = bytes.len() as u64;
        let r = &mut bytes[..256];
        r[176..184].copy_from_slice(&(offset as u64).to_le_bytes());
        r[184..188].copy_from_slice(&(stored.len() as u32).to_le_bytes());
        r[188..192].copy_from_slice(&crc.to_le_bytes());
        r[192..196].copy_from_slice(&(pages.len() as u32).to_le_bytes());
        r[196..200].copy_from_slice(&head_len.to_le_bytes());
        r[24..32].copy_from_slice(&len.to_le_bytes());
    }
    for slot in 0..2 {
        let r = &mut bytes[slot * p..slot * p + 256];
        if r[..4] == *b"FMRH" {
            let crc = crc32fast::hash(&r[..252]);
            r[252..].copy_from_slice(&crc.to_le_bytes());
        }
    }
    bytes
}

/// Makes a structured page's CRC right again (a page is structured when it starts with a
/// known tag).
fn reseal_page(page: &mut [u8]) {
    if TAGS.iter().any(|t| page[..4] == t[..]) {
        let crc = crc32fast::hash(&page[8..]);
        page[4..8].copy_from_slice(&crc.to_le_bytes());
    }
}

/// Whether slot 0's record stores its bundle a frame per page (major 5 and later).
fn framed(bytes: &[u8]) -> bool {
    bytes.len() >= 10 && u16::from_le_bytes([bytes[8], bytes[9]]) >= 5
}

/// Slot 0's metadata bundle, decompressed, if the file has one (commit record bytes
/// 176..196: offset, stored length, CRC, pages; from 5.0 a frame table first).
fn bundle_pages(bytes: &[u8]) -> Option<Vec<u8>> {
    let r = bytes.get(..256)?;
    let offset = usize::try_from(u64::from_le_bytes(r[176..184].try_into().ok()?)).ok()?;
    let len = u32::from_le_bytes(r[184..188].try_into().ok()?) as usize;
    if len == 0 {
        return None;
    }
    let stored = bytes.get(offset..offset.checked_add(len)?)?;
    if !framed(bytes) {
        return zstd::bulk::decompress(stored, 1 << 20).ok();
    }
    let pages = u32::from_le_bytes(r[192..196].try_into().ok()?) as usize;
    let mut out = Vec::new();
    for e in stored.get(..pages.checked_mul(12)?)?.chunks_exact(12) {
        let at = u32::from_le_bytes(e[..4].try_into().ok()?) as usize;
        let flen = u32::from_le_bytes(e[4..8].try_into().ok()?) as usize;
        let frame = stored.get(at..at.checked_add(flen)?)?;
        out.extend(zstd::bulk::decompress(frame, 1 << 16).ok()?);
        if out.len() > 1 << 20 {
            return None;
        }
    }
    Some(out)
}

pub fn check(bytes: &[u8]) {
    let full = fmrh::store::verify(fmrh::store::Bytes(bytes), fmrh::store::VerifyMode::Full);
    let _ = fmrh::store::verify(fmrh::store::Bytes(bytes), fmrh::store::VerifyMode::Fast);
    match fmrh::store::Store::from_bytes(bytes) {
        Ok(store) => {
            let whole = store.read_window(store.domain().data_rect());
            if full.as_ref().is_ok_and(|r| r.valid) {
                assert!(
                    whole.is_ok(),
                    "verify called it valid, reading failed: {whole:?}"
                );
            }
            exercise(&store);
        }
        Err(e) => assert!(
            !full.as_ref().is_ok_and(|r| r.valid),
            "verify called it valid, opening failed: {e}"
        ),
    }
}

fn exercise<S: fmrh::store::Source>(store: &fmrh::store::Store<S>) {
    let _ = store.layout();
    for c in 0..store.clusters().len() {
        let _ = store
            .scan_hilbert(c, 0..=u64::MAX)
            .map(|s| s.take(10_000).count());
        let _ = store.scan_codes(c, 0..10_000).map(|s| s.count());
        for e in 0..4 {
            let _ = store.adjacency(c, e);
        }
    }
    if let Ok(nodes) = store.nodes() {
        for n in nodes.iter().take(64) {
            let _ = store.grid(n);
        }
    }
    // A scene over the whole terrain, its blocks read in one coalesced batch and decoded.
    if let Ok(terrain) = fmrh::scene::Terrain::new(store) {
        let d = store.domain();
        let (w, h) = (f64::from(d.width()), f64::from(d.height()));
        let cam = fmrh::scene::Camera::looking_at(
            glam::DVec3::new(w / 2.0, h * 2.0, w + h),
            glam::DVec3::new(w / 2.0, h / 2.0, 0.0),
        );
        if let Ok(scene) = terrain.scene(&cam, &fmrh::scene::SceneOptions::new(0.5)) {
            let _ = fmrh::scene::load_blocks(store, &scene.blocks, 64);
        }
    }
}

/// Runs one fuzzer input: the first byte picks raw or structure-aware mode.
pub fn run(data: &[u8]) {
    let Some((&mode, rest)) = data.split_first() else {
        return;
    };
    if mode % 2 == 0 {
        check(rest);
    } else if let Some((&pick, edits)) = rest.split_first() {
        check(&resealed(VECTORS[usize::from(pick) % VECTORS.len()], edits));
    }
}
