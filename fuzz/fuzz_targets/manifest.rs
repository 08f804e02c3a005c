//! Fuzz target: a dataset's MANIFEST from the fuzzer (`format-spec/dataset.md`), read as a
//! reader reads it: the slots, the head, every tile page and every tile's adjacent-cluster
//! tables, decoded. Each step must return a value or an error: never panic, hang or allocate
//! from an unchecked size.
//!
//! The first byte picks the mode:
//!
//! * **raw** (even): the rest is the file, byte for byte.
//! * **structure-aware** (odd): the rest edits the golden manifest
//!   (`format-spec/vectors/dataset-3-tiles/MANIFEST`): 4-byte edits, each a 3-byte offset and a
//!   value, then every checksum is made right again (each tile's tables, each tile page, the
//!   head, both records), so the edits reach the fields behind them.
//!
//! cargo fuzz run --sanitizer none manifest corpus/manifest

#![no_main]

use libfuzzer_sys::fuzz_target;

use fmrh::dataset::manifest::ManifestState;
use fmrh::format::crc32;
use fmrh::store::Bytes;

const GOLDEN: &[u8] = include_bytes!("../../format-spec/vectors/dataset-3-tiles/MANIFEST");

fn u32_at(b: &[u8], at: usize) -> Option<u32> {
    Some(u32::from_le_bytes(b.get(at..at.checked_add(4)?)?.try_into().ok()?))
}

fn u64_at(b: &[u8], at: usize) -> Option<u64> {
    Some(u64::from_le_bytes(b.get(at..at.checked_add(8)?)?.try_into().ok()?))
}

/// Writes the CRC of `m[from..from + len]` at `at`, when both lie inside.
fn seal(m: &mut [u8], from: u64, len: u64, at: usize) -> Option<()> {
    let from = usize::try_from(from).ok()?;
    let end = from.checked_add(usize::try_from(len).ok()?)?;
    let crc = crc32(m.get(from..end)?);
    m.get_mut(at..at + 4)?.copy_from_slice(&crc.to_le_bytes());
    Some(())
}

/// Makes every checksum of slot 0's state right again, innermost first.
fn reseal(m: &mut [u8]) -> Option<()> {
    let head = u64_at(m, 32)?;
    let head_len = u64::from(u32_at(m, 40)?);
    let area = head.checked_sub(u64_at(m, 96)?)?;
    let pages = u32_at(m, usize::try_from(head).ok()? + 4)?.min(64);
    for i in 0..u64::from(pages) {
        let entry = usize::try_from(head + 256 + 64 * i).ok()?;
        let (offset, length) = (u64_at(m, entry)?, u64::from(u32_at(m, entry + 8)?));
        for r in 0..(length / 128).min(32) {
            let rec = usize::try_from(offset + 128 * r).ok()?;
            let (at, len) = (u64_at(m, rec + 48)?, u64::from(u32_at(m, rec + 56)?));
            let _ = seal(m, area.checked_add(at)?, len, rec + 60);
        }
        seal(m, offset, length, entry + 12)?;
    }
    seal(m, head, head_len, 44)?;
    seal(m, 0, 252, 252)
}

fuzz_target!(|data: &[u8]| {
    let Some((&mode, rest)) = data.split_first() else {
        return;
    };
    let bytes = if mode & 1 == 0 {
        rest.to_vec()
    } else {
        let mut m = GOLDEN.to_vec();
        for e in rest.chunks_exact(4) {
            let at = (usize::from(e[0]) << 16 | usize::from(e[1]) << 8 | usize::from(e[2])) % m.len();
            m[at] = e[3];
        }
        let _ = reseal(&mut m);
        m
    };
    let src = Bytes(&bytes[..]);
    if let Ok(state) = ManifestState::read(&src) {
        let _ = state.georeference();
        for p in 0..state.head.pages.len() {
            if let Ok(records) = state.page(&src, p) {
                for t in records.iter() {
                    let _ = t.rect();
                    if let Ok(tables) = state.adjacency(&src, t) {
                        let _ = fmrh::dataset::adjacency::decode(&tables);
                    }
                }
            }
        }
    }
});
