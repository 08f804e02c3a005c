//! Fuzz target: arbitrary bytes as a container. Opening, reading and verifying (fast and full)
//! must return a value or an error: never panic, hang or allocate from an unchecked size.
//! Seed corpus: the golden vectors (`format-spec/vectors/*.fmrh`).
//!
//! mkdir -p corpus/open_verify && cp ../format-spec/vectors/*.fmrh corpus/open_verify/
//! cargo fuzz run --sanitizer none open_verify

#![no_main]

use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| {
    let _ = fmrh::store::verify(fmrh::store::Bytes(data), fmrh::VerifyMode::Full);
    if let Ok(store) = fmrh::Store::from_bytes(data) {
        exercise(&store);
    }
});

fn exercise<S: fmrh::store::Source>(store: &fmrh::Store<S>) {
    let _ = store.read_window(store.domain().data_rect());
    let _ = store.layout();
    for c in 0..store.clusters().len() {
        let _ = store.scan_hilbert(c, 0..=u64::MAX).map(|s| s.take(10_000).count());
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
}
