//! Property tests of the container: a model written to a `.fmrh` and read back is the same
//! model. The tests run on random fields of every character, with voids, block sizes and page
//! sizes (small pages give deep trees), and every layout a writer chooses: the metadata in a
//! bundle or in pages of its own (format §6.7), payloads coded or stored raw
//! (`WriteOptions::raw_payloads`). They check that the full validator passes, that
//! extraction returns every sample bit for bit (voids as NaN), that the node table and every
//! cluster equal the model's, that grids and blocks read back as the model's, and that both
//! range scans equal a brute-force filter of the cluster. The three sources (memory, a
//! mapping, positioned reads) must give identical answers.

mod common;

use std::io::Cursor;

use common::fields::any_field;
use fmrh::curve::HilbertKey;
use fmrh::model::{BuildOptions, Model, Thresholds};
use fmrh::store::{verify, write_to, Bytes, ScanEntry, Source, WriteOptions};
use fmrh::{store::Store, Heightfield};
use proptest::prelude::*;

fn write(field: &Heightfield, block_size: u32, page_size: u32) -> (Model, Vec<u8>) {
    write_as(field, block_size, page_size, Layout::Default)
}

/// How a test writes a container.
#[derive(Clone, Copy, Debug)]
enum Layout {
    /// What `fmrh build` writes.
    Default,
    /// Every table in pages of its own (no metadata bundle).
    Paged,
    /// Every payload's codes raw.
    RawPayloads,
}

fn write_as(
    field: &Heightfield,
    block_size: u32,
    page_size: u32,
    layout: Layout,
) -> (Model, Vec<u8>) {
    let model = Model::build(
        field.clone(),
        &BuildOptions {
            block_size,
            thresholds: Thresholds::Ladder,
            precision: None,
            thin: Default::default(),
        },
    )
    .unwrap();
    let mut out = Cursor::new(Vec::new());
    let options = WriteOptions {
        page_size,
        bundle_limit: match layout {
            Layout::Paged => 0,
            _ => WriteOptions::default().bundle_limit,
        },
        raw_payloads: matches!(layout, Layout::RawPayloads),
        ..WriteOptions::default()
    };
    write_to(&model, &field.metadata, &options, &mut out).unwrap();
    (model, out.into_inner())
}

/// Brute force: the cluster's nodes whose key span meets `lo..=hi`.
fn brute_scan(model: &Model, cluster: usize, lo: u64, hi: u64) -> Vec<ScanEntry> {
    let finest = model.domain().finest_level();
    model.clusters()[cluster]
        .nodes
        .iter()
        .map(|&i| (i, model.tree().node(i)))
        .filter(|(_, n)| n.key.0 <= hi && n.key.last(finest, n.level) >= lo)
        .map(|(i, n)| ScanEntry {
            key: n.key,
            level: n.level,
            node: i,
        })
        .collect()
}

fn check_store<S: Source>(
    store: &Store<S>,
    model: &Model,
    field: &Heightfield,
    ranges: &[(u64, u64)],
) {
    // Samples, bit for bit.
    let back = store.read_window(store.domain().data_rect()).unwrap();
    assert_eq!(
        (back.width(), back.height()),
        (field.width(), field.height())
    );
    for (a, b) in back.samples().iter().zip(field.samples()) {
        assert!(
            a.to_bits() == b.to_bits()
                || (a.is_nan() && b.is_nan() && a.to_bits() == f32::NAN.to_bits())
        );
    }
    // Nodes.
    let nodes = store.nodes().unwrap();
    assert_eq!(nodes.len(), model.tree().nodes().len());
    for (r, n) in nodes.iter().zip(model.tree().nodes()) {
        assert_eq!((r.key, r.level, r.x, r.y), (n.key, n.level, n.x, n.y));
        assert_eq!(r.monotone_error.to_bits(), n.monotone_error.to_bits());
        assert_eq!(r.static_error.to_bits(), n.static_error.to_bits());
    }
    // Grids expand to the model's node grids.
    let finest = model.domain().finest_level();
    for (i, r) in nodes.iter().enumerate() {
        if r.level < finest {
            let g = store.grid(r).unwrap();
            let want = model.node_grid(i as u32);
            assert_eq!(g.view().expanded(), want.heights);
        }
    }
    // Clusters and scans.
    assert_eq!(store.clusters().len(), model.clusters().len());
    let span = HilbertKey::span(finest, 0);
    for (c, cluster) in model.clusters().iter().enumerate() {
        let all: Vec<ScanEntry> = store
            .scan_codes(c, 0..u64::MAX)
            .unwrap()
            .map(Result::unwrap)
            .collect();
        let want: Vec<u32> = cluster.nodes.clone();
        assert_eq!(all.iter().map(|e| e.node).collect::<Vec<_>>(), want);
        assert_eq!(
            store.scan_hilbert(c, 0..=span - 1).unwrap().count(),
            want.len()
        );
        for &(a, b) in ranges {
            let (lo, hi) = (a % span, b % span);
            let (lo, hi) = (lo.min(hi), lo.max(hi));
            let got: Vec<ScanEntry> = store
                .scan_hilbert(c, lo..=hi)
                .unwrap()
                .map(Result::unwrap)
                .collect();
            assert_eq!(
                got,
                brute_scan(model, c, lo, hi),
                "cluster {c} range {lo}..={hi}"
            );
            let n = want.len() as u64;
            let (x, y) = ((a % (n + 2)), (b % (n + 2)));
            let (x, y) = (x.min(y), x.max(y));
            let codes: Vec<u32> = store
                .scan_codes(c, x..y)
                .unwrap()
                .map(|e| e.unwrap().node)
                .collect();
            let end = (y as usize).min(want.len());
            let start = (x as usize).min(end);
            assert_eq!(
                codes,
                want[start..end].to_vec(),
                "cluster {c} codes {x}..{y}"
            );
        }
        // Adjacency lists: every listed node is in the cut and touches its edge.
        for edge in 0..4 {
            for node in store.adjacency(c, edge).unwrap() {
                assert!(cluster.nodes.contains(&node));
            }
        }
    }
}

fn page_size() -> impl Strategy<Value = u32> {
    prop_oneof![Just(1024u32), Just(4096), Just(65536)]
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(96))]

    #[test]
    fn a_written_model_reads_back_whole(
        field in any_field(90),
        b in prop_oneof![Just(9u32), Just(17), Just(33)],
        p in page_size(),
        layout in prop_oneof![Just(Layout::Default), Just(Layout::Paged), Just(Layout::RawPayloads)],
        ranges in prop::collection::vec((any::<u64>(), any::<u64>()), 6),
    ) {
        let (model, bytes) = write_as(&field, b, p, layout);
        let report = verify(Bytes(&bytes), fmrh::store::VerifyMode::Full).unwrap();
        prop_assert!(report.valid, "{:#?}", report.checks);
        let store = Store::from_bytes(&bytes).unwrap();
        check_store(&store, &model, &field, &ranges);
        prop_assert_eq!(
            store.layout().unwrap().bundle_bytes == 0,
            matches!(layout, Layout::Paged)
        );
        if matches!(layout, Layout::RawPayloads) {
            // After the code's u32 length, its encoding byte: 0, raw.
            let root = store.node(0).unwrap();
            prop_assert_eq!(store.payload(root.payload).unwrap()[4], 0);
        }
    }
}

#[test]
fn the_three_sources_agree() {
    let field = common::fields::make(150, 97, common::fields::Character::Hills, 0.03, 7);
    let (model, bytes) = write(&field, 17, 1024);
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("hills.fmrh");
    std::fs::write(&path, &bytes).unwrap();
    let ranges = [(0, 5), (3, 900), (17, 18), (100, 4000)];
    check_store(&Store::from_bytes(&bytes).unwrap(), &model, &field, &ranges);
    check_store(&Store::open(&path).unwrap(), &model, &field, &ranges);
    // SAFETY: the file is private to this test and nothing writes it while mapped.
    let mapped = unsafe { Store::open_mapped(&path) }.unwrap();
    check_store(&mapped, &model, &field, &ranges);
}

#[test]
fn writing_is_deterministic() {
    let field = common::fields::make(70, 40, common::fields::Character::Noise, 0.3, 3);
    assert_eq!(write(&field, 9, 1024).1, write(&field, 9, 1024).1);
}

#[test]
fn a_deep_index_is_searched_correctly() {
    // 1024-byte pages hold 62 index entries: a 128 x 128 finest grid needs three levels.
    let field = common::fields::make(1025, 1025, common::fields::Character::Noise, 0.0, 11);
    let (model, bytes) = write(&field, 9, 1024);
    let store = Store::from_bytes(&bytes).unwrap();
    assert!(store.clusters()[0].index_depth() >= 3);
    let span = HilbertKey::span(model.domain().finest_level(), 0);
    let ranges: Vec<(u64, u64)> = (0..40u64)
        .map(|i| (i * 409 % span, (i * 409 + i * i * 31) % span))
        .collect();
    check_store(&store, &model, &field, &ranges);
}
