//! Identical small payloads are stored once (format 2.0, container §7): a terrain that is
//! mostly sea has thousands of blocks that code to the same few bytes, and every one of them
//! names one payload. Such a file verifies in full, reads back sample for sample, and a
//! transaction that rewrites some of the sharing blocks leaves the others, and the shared
//! payload, intact.

use std::collections::HashSet;

use fmrh::store::Container;
use fmrh::CreateOptions;
use fmrh::{store::Store, store::VerifyMode, Heightfield};

/// Sea (height 0) with one island in the middle.
fn island() -> Heightfield {
    Heightfield::from_fn(513, 385, |x, y| {
        let (dx, dy) = (x as f32 - 256.0, y as f32 - 190.0);
        (120.0 - (dx * dx + dy * dy).sqrt()).max(0.0).round()
    })
    .unwrap()
}

fn verify_full(path: &std::path::Path) {
    let report = fmrh::store::verify(
        fmrh::store::FileSource::open(path).unwrap(),
        VerifyMode::Full,
    )
    .unwrap();
    assert!(report.valid, "{report:#?}");
}

#[test]
fn sea_blocks_share_one_payload_and_survive_transactions() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("island.fmrh");
    let field = island();
    fmrh::create(&path, field.clone(), &CreateOptions::default()).unwrap();
    let store = Store::open(&path).unwrap();
    let (cols, rows) = store.domain().nodes_across(store.domain().finest_level());
    let refs: Vec<_> = (0..rows)
        .flat_map(|y| (0..cols).map(move |x| (x, y)))
        .map(|(x, y)| store.stored_block(x, y).unwrap().payload)
        .collect();
    let distinct: HashSet<_> = refs.iter().map(|r| r.offset).collect();
    // 8 x 6 blocks of 65²: the island meets the middle ones; the sea blocks of each shape
    // (interior, and the clipped east and south edges) share one payload.
    assert!(
        distinct.len() + 20 <= refs.len(),
        "{} payloads for {} blocks",
        distinct.len(),
        refs.len()
    );
    let back = store.read_window(store.domain().data_rect()).unwrap();
    assert_eq!(back.samples(), field.samples());
    drop(store);
    verify_full(&path);

    // Raise the sea in the north-west corner: two sharing blocks get payloads of their own.
    let container = Container::open(&path).unwrap();
    let mut txn = container.begin_write().unwrap();
    let patch = Heightfield::from_fn(100, 40, |_, _| 3.0).unwrap();
    txn.replace_region(0, 0, &patch).unwrap();
    txn.commit().unwrap();
    container.close().unwrap();
    verify_full(&path);
    let store = Store::open(&path).unwrap();
    let after = store.read_window(store.domain().data_rect()).unwrap();
    let mut want = field.samples().to_vec();
    for y in 0..40 {
        for x in 0..100 {
            want[y * 513 + x] = 3.0;
        }
    }
    assert_eq!(after.samples(), &want[..]);
}
