//! The metadata bundle (format 3.0, container.md §6.7) changes where a state's tables are
//! stored, never what they say: a file written with its metadata bundled and the same model
//! written with every table in pages of its own read the same nodes, blocks, cuts,
//! adjacency lists and samples, and both pass `verify --full`. The writer bundles exactly
//! when the stored form fits its limit, and commits move a file between the two layouts
//! as the limit says, each state valid. A hostile bundle (a frame that inflates past its
//! pages, a page count that lies, bytes that are not zstd, a page of a foreign tag, a
//! reference past the bundle's end) is corruption reported by opening, never a panic or an
//! allocation the record did not bound.

mod common;

use std::io::Cursor;

use proptest::prelude::*;

use fmrh::model::{BuildOptions, Model, SampleRect, Thresholds};
use fmrh::store::io::SimDisk;
use fmrh::store::{verify, write_to, Bytes, Container, WriteOptions};
use fmrh::{store::Store, store::VerifyMode, types::Invariant, Error, Heightfield};

fn write(hf: &Heightfield, block: u32, bundle_limit: u64) -> Vec<u8> {
    let options = WriteOptions {
        bundle_limit,
        ..WriteOptions::default()
    };
    write_with(hf, block, &options)
}

fn write_with(hf: &Heightfield, block: u32, options: &WriteOptions) -> Vec<u8> {
    let model = Model::build(
        hf.clone(),
        &BuildOptions {
            block_size: block,
            thresholds: Thresholds::Ladder,
            precision: None,
            thin: Default::default(),
        },
    )
    .unwrap();
    let mut out = Cursor::new(Vec::new());
    write_to(&model, &hf.metadata, options, &mut out).unwrap();
    out.into_inner()
}

fn terrain(w: u32, h: u32, seed: u32) -> Heightfield {
    Heightfield::from_fn(w, h, |x, y| {
        let v = ((x * 31 + y * 17 + seed) % 23) as f32 + (x as f32 * 0.1).sin() * 30.0;
        if (x * 7 + y * 3 + seed).is_multiple_of(97) {
            f32::NAN
        } else {
            v.round()
        }
    })
    .unwrap()
}

/// Everything a reader can ask of a store's metadata, in one comparable value.
fn everything(s: &Store<Bytes<Vec<u8>>>) -> String {
    // Where each index lies differs by layout; what it holds may not.
    let clusters: Vec<_> = s
        .clusters()
        .iter()
        .map(|c| (c.threshold, c.max_error, c.nodes()))
        .collect();
    let mut out = format!("{:?}\n{clusters:?}\n", s.header());
    out += &format!("{:?}\n", s.nodes().unwrap());
    let (cols, rows) = s.domain().nodes_across(s.domain().finest_level());
    for y in 0..rows {
        for x in 0..cols {
            out += &format!("{:?}\n", s.stored_block(x, y).unwrap());
        }
    }
    for c in 0..s.clusters().len() {
        let scan: Vec<_> = s
            .scan_hilbert(c, 0..=u64::MAX)
            .unwrap()
            .collect::<Result<_, _>>()
            .unwrap();
        out += &format!("{scan:?}\n");
        for e in 0..4 {
            out += &format!("{:?}\n", s.adjacency(c, e).unwrap());
        }
    }
    out
}

fn assert_valid(bytes: &[u8], what: &str) {
    let report = verify(Bytes(bytes), VerifyMode::Full).unwrap();
    assert!(report.valid, "{what}: {report:#?}");
}

proptest! {
    #![proptest_config(ProptestConfig { cases: 24, ..ProptestConfig::default() })]

    /// Bundled and paged files of one model read the same, both valid, and the bundled one
    /// is never the larger.
    #[test]
    fn bundled_and_paged_files_read_the_same(
        w in 9u32..120, h in 9u32..120, seed in 0u32..1000,
        block in prop::sample::select(vec![9u32, 17, 33]),
    ) {
        let hf = terrain(w, h, seed);
        let bundled = write(&hf, block, 1 << 20);
        let paged = write(&hf, block, 0);
        let b = Store::from_bytes(bundled.clone()).unwrap();
        let p = Store::from_bytes(paged.clone()).unwrap();
        prop_assert!(b.layout().unwrap().bundle_bytes > 0);
        prop_assert_eq!(p.layout().unwrap().bundle_bytes, 0);
        prop_assert_eq!(everything(&b), everything(&p));
        let all = b.domain().data_rect();
        let (wb, wp) = (b.read_window(all).unwrap(), p.read_window(all).unwrap());
        prop_assert!(wb.samples().iter().zip(wp.samples()).all(|(x, y)| x.to_bits() == y.to_bits()));
        prop_assert!(bundled.len() <= paged.len());
        assert_valid(&bundled, "bundled");
        assert_valid(&paged, "paged");
        // Opening the bundled file reads the slots and the bundle, nothing more.
        let open = b.open_reads();
        prop_assert!(open.bytes() <= b.layout().unwrap().bundle_bytes + 4 * 256);
    }
}

/// The writer keeps the bundle exactly when its stored form fits the limit.
#[test]
fn the_writer_bundles_exactly_within_its_limit() {
    let hf = terrain(200, 150, 7);
    let big = write(&hf, 9, 1 << 20);
    let stored = Store::from_bytes(big)
        .unwrap()
        .layout()
        .unwrap()
        .bundle_bytes;
    assert!(stored > 1000, "{stored}");
    let at = Store::from_bytes(write(&hf, 9, stored)).unwrap();
    assert_eq!(at.layout().unwrap().bundle_bytes, stored);
    let under = Store::from_bytes(write(&hf, 9, stored - 1)).unwrap();
    assert_eq!(under.layout().unwrap().bundle_bytes, 0);
    assert!(under.layout().unwrap().node_table_pages > 0);
}

/// Commits follow the container's limit: a bundled file goes to pages and back, every state
/// valid (page ownership included: the pages a layout leaves behind are free, I-8) and
/// holding the samples committed.
#[test]
fn commits_move_a_file_between_bundle_and_pages() {
    let hf = terrain(150, 130, 3);
    let disk = SimDisk::new(write(&hf, 17, 1 << 20));
    let (c, _) = Container::open_io(disk.clone()).unwrap();
    let mut freed_tables = false;
    for round in 0..12u32 {
        let limit = if round % 3 == 1 { 0 } else { 1 << 20 };
        c.set_bundle_limit(limit);
        let patch = Heightfield::from_fn(20, 15, |x, y| (round * 100 + x + y) as f32).unwrap();
        let mut txn = c.begin_write().unwrap();
        let at = u64::from(round) * 9;
        txn.replace_region(at, 40, &patch).unwrap();
        txn.commit().unwrap();
        let snap = c.read().unwrap();
        assert_eq!(
            snap.layout().unwrap().bundle_bytes == 0,
            limit == 0,
            "round {round}"
        );
        let got = snap
            .read_window(SampleRect {
                col0: at,
                row0: 40,
                col1: at + 19,
                row1: 54,
            })
            .unwrap();
        assert_eq!(got.samples(), patch.samples(), "round {round}");
        if round % 3 == 2 {
            // The paged state before this one had table pages; they are free now.
            freed_tables |= snap.free_pages().unwrap().len() > 4;
        }
        drop(snap);
        assert_valid(&disk.current(), &format!("round {round}"));
    }
    assert!(
        freed_tables,
        "leaving the paged layout freed no table pages"
    );
    c.close().unwrap();
    assert_valid(&disk.current(), "closed");
}

/// A bundled vector as this version writes it (5.0: a frame per page).
fn bundled_vector() -> Vec<u8> {
    common::vector("hills-20x13-voids.fmrh")
}

/// The same vector as 4.0 wrote it: the bundle one zstd frame.
fn single_frame_vector() -> Vec<u8> {
    common::vector("v4.0/hills-20x13-voids.fmrh")
}

/// The current vector's bundle pages, each compressed as a frame of its own (by page), and
/// the head's pages (the dataset header's and the directory's).
fn frames_of(bytes: &[u8]) -> (Vec<Vec<u8>>, Vec<usize>) {
    let raw = common::bundle::pages(bytes);
    let pages: Vec<&[u8]> = raw.chunks(1024).collect();
    let head = (0..pages.len())
        .filter(|&i| &pages[i][..4] == b"FMHD" || &pages[i][..4] == b"FMCD")
        .collect();
    (
        pages
            .iter()
            .map(|p| zstd::bulk::compress(p, 3).unwrap())
            .collect(),
        head,
    )
}

fn corrupt(bytes: &[u8]) -> (Invariant, String) {
    match Store::from_bytes(bytes) {
        Err(Error::Corrupt {
            invariant, detail, ..
        }) => {
            let report = verify(Bytes(bytes), VerifyMode::Fast).unwrap();
            assert!(!report.valid, "verify called it valid: {detail}");
            (invariant, detail)
        }
        Err(e) => panic!("expected corruption, got {e}"),
        Ok(_) => panic!("a hostile bundle opened"),
    }
}

#[test]
fn a_frame_that_inflates_past_its_pages_is_refused() {
    let mut bytes = single_frame_vector();
    let pages = common::bundle::pages(&bytes);
    let count = (pages.len() / 1024) as u32;
    // 64 MiB of zeros in a few KiB: the record says `count` pages.
    let bomb = zstd::bulk::compress(&vec![0u8; 64 << 20], 19).unwrap();
    common::bundle::store_raw(&mut bytes, &bomb, count);
    let (inv, detail) = corrupt(&bytes);
    assert_eq!(inv, Invariant::Page, "{detail}");
}

#[test]
fn a_page_count_that_lies_is_refused() {
    for delta in [-1i64, 1] {
        let mut bytes = single_frame_vector();
        let pages = common::bundle::pages(&bytes);
        let count = (pages.len() / 1024) as i64 + delta;
        let stored = zstd::bulk::compress(&pages, 3).unwrap();
        common::bundle::store_raw(&mut bytes, &stored, count as u32);
        let (inv, detail) = corrupt(&bytes);
        assert_eq!(inv, Invariant::Page, "{delta}: {detail}");
    }
}

#[test]
fn bytes_that_are_not_zstd_are_refused() {
    let mut bytes = single_frame_vector();
    common::bundle::store_raw(&mut bytes, b"certainly not a zstd frame", 3);
    let (inv, detail) = corrupt(&bytes);
    assert_eq!(inv, Invariant::Page, "{detail}");
}

/// Whether `report` fails I-5 naming bundle page `i`.
fn names_page(report: &fmrh::store::VerifyReport, i: usize) -> bool {
    let name = format!("page {}", (1u64 << 40) + i as u64);
    report
        .checks
        .iter()
        .any(|c| c.id == Invariant::Page && c.failures.iter().any(|f| f.contains(&name)))
}

/// The same hostile frames in a 5.0 bundle, one per page: in the head, opening refuses them;
/// elsewhere, the first lookup that reaches the page does, and the validator always does.
/// A page in another page's frame, and a frame table whose page count lies, are refused too.
#[test]
fn hostile_frames_of_a_framed_bundle_are_refused() {
    let clean = bundled_vector();
    let (frames, head) = frames_of(&clean);
    let pages = frames.len() as u32;
    assert!(
        head.len() >= 2 && frames.len() > head.len() + 2,
        "{head:?} of {}",
        frames.len()
    );
    let rest: Vec<usize> = (0..frames.len()).filter(|i| !head.contains(i)).collect();
    let bomb = zstd::bulk::compress(&vec![0u8; 64 << 20], 19).unwrap();
    let bad_frames: [&[u8]; 3] = [
        &bomb,
        b"certainly not a zstd frame",
        &zstd::bulk::compress(&vec![7u8; 1024], 3).unwrap(),
    ];
    for bad in bad_frames {
        // In the head: opening reads and checks it.
        let mut in_head = frames.clone();
        in_head[head[0]] = bad.to_vec();
        let mut bytes = clean.clone();
        common::bundle::store_frames(&mut bytes, &in_head, &head, pages);
        let (inv, detail) = corrupt(&bytes);
        assert_eq!(inv, Invariant::Page, "{detail}");
        // Past the head: every page is damaged in turn; a lookup that reaches it, or the
        // validator, refuses it.
        let mut refused_by_a_lookup = 0;
        for &k in &rest {
            let mut later = frames.clone();
            later[k] = bad.to_vec();
            let mut bytes = clean.clone();
            common::bundle::store_frames(&mut bytes, &later, &head, pages);
            let store = Store::from_bytes(&bytes[..]).expect("opening reads only the head");
            match store
                .nodes()
                .and_then(|_| store.read_window(store.domain().data_rect()))
            {
                Err(Error::Corrupt { invariant, .. }) => {
                    assert_eq!(invariant, Invariant::Page);
                    refused_by_a_lookup += 1;
                }
                Err(e) => panic!("{e}"),
                Ok(_) => {}
            }
            let report = verify(Bytes(&bytes[..]), VerifyMode::Fast).unwrap();
            assert!(names_page(&report, k), "frame {k}: {report:#?}");
        }
        assert!(refused_by_a_lookup > 0);
    }
    // Two frames swapped: each holds another page's number.
    let mut swapped = frames.clone();
    swapped.swap(rest[0], rest[1]);
    let mut bytes = clean.clone();
    common::bundle::store_frames(&mut bytes, &swapped, &head, pages);
    let report = verify(Bytes(&bytes[..]), VerifyMode::Fast).unwrap();
    assert!(
        names_page(&report, rest[0]) || names_page(&report, rest[1]),
        "{report:#?}"
    );
    // A page count that lies: the table is read as that many entries.
    for lie in [pages - 1, pages + 1] {
        let mut bytes = clean.clone();
        common::bundle::store_frames(&mut bytes, &frames, &head, lie);
        assert!(Store::from_bytes(&bytes[..]).is_err(), "{lie} pages");
    }
    // Untouched, the same construction reads as the file it came from (it is not valid as a
    // whole: the old bundle's bytes stay in the file, owned by nothing).
    let mut bytes = clean.clone();
    common::bundle::store_frames(&mut bytes, &frames, &head, pages);
    let (a, b) = (
        Store::from_bytes(&bytes[..]).unwrap(),
        Store::from_bytes(&clean[..]).unwrap(),
    );
    assert_eq!(a.nodes().unwrap(), b.nodes().unwrap());
    let rect = b.domain().data_rect();
    let (sa, sb) = (a.read_window(rect).unwrap(), b.read_window(rect).unwrap());
    assert!(sa
        .samples()
        .iter()
        .zip(sb.samples())
        .all(|(x, y)| x.to_bits() == y.to_bits()));
}

#[test]
fn a_free_list_page_in_a_bundle_is_refused() {
    let mut bytes = bundled_vector();
    common::bundle::rewrite(&mut bytes, |raw| {
        let last = raw.len() / 1024 - 1;
        let page = &mut raw[last * 1024..(last + 1) * 1024];
        page[..4].copy_from_slice(b"FMFL");
        common::bundle::reseal_page(page);
    });
    let (inv, detail) = corrupt(&bytes);
    assert_eq!(inv, Invariant::Page, "{detail}");
    assert!(detail.contains("FMFL"), "{detail}");
}

/// A root reference past the bundle's last page: refused by the first lookup that follows
/// it, as a reference outside the file is.
#[test]
fn a_reference_past_the_bundle_is_refused() {
    let mut bytes = bundled_vector();
    let pages = (common::bundle::pages(&bytes).len() / 1024) as u64;
    // The node table's root (bytes 72..80) one page past the bundle's end.
    bytes[72..80].copy_from_slice(&((1u64 << 40) + pages).to_le_bytes());
    let crc = crc32fast::hash(&bytes[..252]);
    bytes[252..256].copy_from_slice(&crc.to_le_bytes());
    let store = Store::from_bytes(&bytes[..]).unwrap();
    match store.node(0) {
        Err(Error::Corrupt { detail, .. }) => assert!(detail.contains("bundle"), "{detail}"),
        other => panic!("{other:?}"),
    }
    let report = verify(Bytes(&bytes[..]), VerifyMode::Fast).unwrap();
    assert!(!report.valid);
}

/// The bundle's reference lives in bytes a 2.x record reserves: a 2.x record that sets
/// them is invalid, and a 3.0 record whose bundle lies outside the file is too (I-1).
#[test]
fn bundle_references_are_checked_in_the_record() {
    let mut outside = bundled_vector();
    let len = outside.len() as u64;
    outside[176..184].copy_from_slice(&(len - 10).to_le_bytes());
    let crc = crc32fast::hash(&outside[..252]);
    outside[252..256].copy_from_slice(&crc.to_le_bytes());
    let (inv, _) = corrupt(&outside);
    assert_eq!(inv, Invariant::CommitRecord);

    let mut old = common::vector("v2.1/hills-20x13-voids.fmrh");
    old[184] = 1;
    let crc = crc32fast::hash(&old[..252]);
    old[252..256].copy_from_slice(&crc.to_le_bytes());
    let (inv, detail) = corrupt(&old);
    assert_eq!(inv, Invariant::CommitRecord, "{detail}");
}

/// Regression (the container property test, a constant 49 x 81 field, blocks of 9, 1 KiB
/// pages): its 77 blocks share one constant payload and their records compress into a few
/// hundred bytes of bundle, so the file (3 KiB) is smaller than 41 bytes a block, which the
/// reader's guard against oversized windows demanded. The guard now counts the 32-byte
/// records against the file and the bundle's decompressed pages together.
#[test]
fn a_constant_field_smaller_than_its_block_records_reads_whole() {
    let hf = Heightfield::from_fn(49, 81, |_, _| 42.0).unwrap();
    let options = WriteOptions {
        page_size: 1024,
        ..WriteOptions::default()
    };
    let bytes = write_with(&hf, 9, &options);
    let store = Store::from_bytes(bytes.clone()).unwrap();
    // The guard counts the blocks a window's corners span, the last sample included: 7 x 11.
    assert!(7 * 11 * 41 > bytes.len(), "the case the guard refused");
    let whole = store.read_window(store.domain().data_rect()).unwrap();
    assert!(whole.samples().iter().all(|&v| v == 42.0));
    assert_valid(&bytes, "constant");
}
