//! Fuzz target: a valid small container (a golden vector) with the fuzzer's edits applied
//! (byte writes at chosen offsets, or a truncation). Whatever the damage, verify and open
//! must not panic or hang, and a damaged file must never verify as valid unless the edits
//! left its bytes unchanged.
//!
//! cargo fuzz run --sanitizer none mutate_container

#![no_main]

use libfuzzer_sys::fuzz_target;

const VECTORS: [&[u8]; 3] = [
    include_bytes!("../../format-spec/vectors/ramp-9x9.fmrh"),
    include_bytes!("../../format-spec/vectors/hills-20x13-voids.fmrh"),
    include_bytes!("../../format-spec/vectors/cliff-33x33.fmrh"),
];

fuzz_target!(|data: &[u8]| {
    let Some((&pick, edits)) = data.split_first() else {
        return;
    };
    let original = VECTORS[usize::from(pick) % VECTORS.len()];
    let mut bytes = original.to_vec();
    // Each edit: 3 bytes of offset, 1 byte of value; an offset with the top bit set truncates.
    for e in edits.chunks_exact(4) {
        let at = usize::from(e[0]) | usize::from(e[1]) << 8 | usize::from(e[2] & 0x7f) << 16;
        if e[2] & 0x80 != 0 {
            bytes.truncate(at % (original.len() + 1));
        } else if !bytes.is_empty() {
            let i = at % bytes.len();
            bytes[i] = e[3];
        }
    }
    let verdict = fmrh::store::verify(fmrh::store::Bytes(&bytes), fmrh::store::VerifyMode::Full);
    if bytes != original {
        if let Ok(report) = &verdict {
            assert!(!report.valid, "a damaged container verified as valid");
        }
    }
    if let Ok(store) = fmrh::store::Store::from_bytes(&bytes[..]) {
        let _ = store.read_window(store.domain().data_rect());
        for c in 0..store.clusters().len() {
            let _ = store.scan_hilbert(c, 0..=u64::MAX).map(|s| s.count());
        }
    }
});
