//! The rules `format-spec/` states for a clean-room reader, one test each, read from the
//! bytes at the offsets the spec gives rather than through the crate's structs:
//!
//! * the newest *sealed* commit record decides: one of another major version with a higher
//!   txn id makes the file unsupported, even beside a valid 1.x record (§3);
//! * a slot-1 record whose page size is not slot 0's is invalid, not a second geometry (§3);
//! * a slot 0 that is sealed but invalid names no page size: slot 1 is searched for (§3);
//! * a node's thinning bits are reserved where the dataset header lacks flag 16 (§6.1, I-10);
//! * transaction ids stop at `2^62 - 1`: a larger one is an invalid record (§2, I-1);
//! * a file shorter than the newest valid record's `file_length` is corrupt (I-3), and the
//!   older slot is not tried (§3);
//! * an empty tree's `TreeRef` is zero but for its table's record size (§4);
//! * adjacency runs count records, not bytes, and tile the table (§6.4, §6.5);
//! * every NaN of a source, whatever its sign or payload, is stored as `0x7FC00000` (§7);
//! * the threshold ladder's `1/√2` is the binary64 `0x3FE6A09E667F3BCD` (model §6).

mod common;

use common::txn::{build_bytes, patch};
use fmrh::format::FORMAT_MAJOR;
use fmrh::model::{cluster, Thresholds};
use fmrh::store::io::SimDisk;
use fmrh::store::{verify, Bytes, CheckStatus, Container};
use fmrh::{store::Store, store::VerifyMode, types::Invariant, Error, Heightfield};

fn u16_at(b: &[u8], at: usize) -> u16 {
    u16::from_le_bytes(b[at..at + 2].try_into().unwrap())
}
fn u32_at(b: &[u8], at: usize) -> u32 {
    u32::from_le_bytes(b[at..at + 4].try_into().unwrap())
}
fn u64_at(b: &[u8], at: usize) -> u64 {
    u64::from_le_bytes(b[at..at + 8].try_into().unwrap())
}

/// Writes `record` (256 bytes, CRC recomputed over 0..252) at `offset`.
fn put_record(file: &mut [u8], offset: usize, mut record: Vec<u8>) {
    let crc = fmrh::format::crc32(&record[..252]);
    record[252..256].copy_from_slice(&crc.to_le_bytes());
    file[offset..offset + 256].copy_from_slice(&record);
}

/// Slot 0's record with another major version, txn id and page size, resealed.
fn record_like(file: &[u8], major: u16, txn: u64, page_size: u32) -> Vec<u8> {
    let mut r = file[..256].to_vec();
    r[8..10].copy_from_slice(&major.to_le_bytes());
    r[12..16].copy_from_slice(&page_size.to_le_bytes());
    r[16..24].copy_from_slice(&txn.to_le_bytes());
    r
}

fn hills() -> Heightfield {
    Heightfield::from_fn(70, 50, |x, y| {
        ((x as f32 * 0.3).sin() * 20.0 + (y as f32 * 0.2).cos() * 15.0).round()
    })
    .unwrap()
}

fn fresh() -> Vec<u8> {
    build_bytes(&hills(), 17, &Thresholds::Ladder)
}

fn check(report: &fmrh::store::VerifyReport, id: Invariant) -> CheckStatus {
    report.checks.iter().find(|c| c.id == id).unwrap().status
}

#[test]
fn a_newer_major_versions_record_makes_the_file_unsupported() {
    let clean = fresh();
    let p = u32_at(&clean, 12);
    let (current, newer) = (FORMAT_MAJOR, FORMAT_MAJOR + 1);
    // Slot 1: a sealed record of the next major with a higher txn id than slot 0's (1).
    let mut file = clean.clone();
    put_record(&mut file, p as usize, record_like(&clean, newer, 2, p));
    match Store::from_bytes(file.clone()) {
        Err(Error::Unsupported { reason, .. }) => {
            assert!(reason.contains(&format!("{newer}.")), "{reason}")
        }
        other => panic!(
            "a superseded state was opened: {:?}",
            other.map(|s| s.txn_id())
        ),
    }
    assert!(matches!(
        verify(Bytes(&file), VerifyMode::Full),
        Err(Error::Unsupported { .. })
    ));
    // In slot 0 too, with slot 1 holding the older state of the current major.
    let mut file = clean.clone();
    let older = clean[..256].to_vec();
    put_record(&mut file, p as usize, older);
    put_record(&mut file, 0, record_like(&clean, newer, 7, p));
    assert!(matches!(
        Store::from_bytes(file),
        Err(Error::Unsupported { .. })
    ));
    // A newer major's record *older* than the valid one does not hide it.
    let mut file = clean.clone();
    put_record(&mut file, 0, record_like(&clean, current, 5, p));
    put_record(&mut file, p as usize, record_like(&clean, newer, 4, p));
    let store = Store::from_bytes(file.clone()).unwrap();
    assert_eq!(store.txn_id(), 5);
    let report = verify(Bytes(&file), VerifyMode::Fast).unwrap();
    assert_eq!(check(&report, Invariant::InactiveSlot), CheckStatus::Failed);
}

#[test]
fn a_slot_1_record_of_another_page_size_is_invalid() {
    let clean = fresh();
    let p = u32_at(&clean, 12);
    assert_eq!(p, 4096);
    for other in [1024u32, 8192] {
        let mut file = clean.clone();
        // A newer, sealed, otherwise valid record at offset P naming another page size.
        put_record(
            &mut file,
            p as usize,
            record_like(&clean, FORMAT_MAJOR, 2, other),
        );
        let store = Store::from_bytes(file.clone()).unwrap();
        assert_eq!(store.txn_id(), 1, "page size {other}: slot 1 was taken");
        let report = verify(Bytes(&file), VerifyMode::Full).unwrap();
        assert_eq!(check(&report, Invariant::InactiveSlot), CheckStatus::Failed);
        assert!(!report.valid);
        // Slot 1 with the right page size is taken.
        let mut file = clean.clone();
        put_record(
            &mut file,
            p as usize,
            record_like(&clean, FORMAT_MAJOR, 2, p),
        );
        assert_eq!(Store::from_bytes(file).unwrap().txn_id(), 2);
    }
}

#[test]
fn a_file_shorter_than_its_newest_record_is_corrupt_not_rolled_back() {
    // After one commit, slot 0 holds the commit (txn 3), which reaches pages appended past
    // the built file's end, and slot 1 the recovery mark (txn 2), a copy of the built state.
    let built = fresh();
    let disk = SimDisk::new(built.clone());
    let (container, _) = Container::open_io(disk.clone()).unwrap();
    let mut txn = container.begin_write().unwrap();
    txn.replace_region(10, 10, &patch(40, 30, 3.0)).unwrap();
    assert_eq!(txn.commit().unwrap().txn_id, 3);
    let mut file = disk.current();
    drop(container);
    let p = u32_at(&file, 12) as usize;
    let (newer, older) = (&file[..256], &file[p..p + 256]);
    assert_eq!((u64_at(newer, 16), u64_at(older, 16)), (3, 2));
    let (newer_len, older_len) = (u64_at(newer, 24), u64_at(older, 24));
    assert_eq!(older_len, built.len() as u64);
    assert!(newer_len > older_len, "the commit appended pages");
    // Cut to the older state's length: it would open, but the newer record says more.
    file.truncate(older_len as usize);
    match Store::from_bytes(file.clone()) {
        Err(Error::Corrupt { invariant, .. }) => assert_eq!(invariant, Invariant::FileLength),
        other => panic!("a truncated file opened: {:?}", other.map(|s| s.txn_id())),
    }
    let report = verify(Bytes(&file), VerifyMode::Full).unwrap();
    assert_eq!(report.txn_id, Some(3));
    assert_eq!(check(&report, Invariant::FileLength), CheckStatus::Failed);
    assert!(!report.valid);
}

#[test]
fn an_empty_tree_names_its_record_size() {
    let file = fresh();
    // The free list's TreeRef sits at 120 in the commit record: root, records, depth 0.
    let free = &file[120..144];
    assert_eq!(
        (u64_at(free, 0), u64_at(free, 8), u16_at(free, 16)),
        (0, 0, 0)
    );
    assert_eq!(u16_at(free, 18), 16, "the free list's record size");
    assert_eq!(u32_at(free, 20), 0);
    // A reader refuses an empty tree naming another record size.
    let mut bad = file.clone();
    let mut record = bad[..256].to_vec();
    record[138..140].copy_from_slice(&0u16.to_le_bytes());
    put_record(&mut bad, 0, record);
    match Store::from_bytes(bad) {
        Err(Error::Corrupt { invariant, .. }) => assert_eq!(invariant, Invariant::TreeShape),
        other => panic!("opened: {:?}", other.map(|s| s.txn_id())),
    }
}

#[test]
fn adjacency_runs_count_records_and_tile_the_table() {
    let file = fresh();
    let p = u32_at(&file, 12) as usize;
    let adjacency_records = u64_at(&file, 144 + 8);
    // The cluster directory blob: its first page, from byte 24 of that page.
    // The file keeps its metadata in a bundle (format 3.0, §6.7), whose pages are numbered
    // from 2^40.
    let (dir_page, dir_len) = (u64_at(&file, 56), u64_at(&file, 64) as usize);
    assert!(dir_len <= p - 24, "a one-page directory");
    let bundle = common::bundle::pages(&file);
    let at = (dir_page - (1 << 40)) as usize * p;
    let dir = &bundle[at + 24..at + 24 + dir_len];
    let count = u32_at(dir, 0) as usize;
    assert!(count >= 3, "{count} clusters");
    let mut next = 0u64;
    for c in 0..count {
        for edge in 0..4 {
            let at = 8 + c * 104 + 40 + edge * 16;
            let (first, n) = (u64_at(dir, at), u64_at(dir, at + 8));
            assert_eq!(first, next, "cluster {c} edge {edge}: first counts records");
            assert!(n > 0);
            next += n;
        }
    }
    assert_eq!(next, adjacency_records, "the runs tile the adjacency table");
    // The adjacency table's leaves hold 4-byte records: its pages hold them all.
    let store = Store::from_bytes(file.clone()).unwrap();
    let total: usize = (0..count)
        .flat_map(|c| (0..4).map(move |e| (c, e)))
        .map(|(c, e)| store.adjacency(c, e).unwrap().len())
        .sum();
    assert_eq!(total as u64, adjacency_records);
}

#[test]
fn every_nan_is_stored_as_the_canonical_void() {
    let nans = [
        f32::from_bits(0x7FC0_0000),
        f32::from_bits(0xFFC0_0000), // negative quiet NaN
        f32::from_bits(0x7FC0_1234), // quiet NaN with a payload
        f32::from_bits(0x7F80_0001), // signalling NaN
        f32::from_bits(0xFFFF_FFFF),
    ];
    let field = Heightfield::from_fn(20, 20, |x, y| {
        if y == 5 && (x as usize) < nans.len() {
            nans[x as usize]
        } else {
            (x * 3 + y) as f32
        }
    })
    .unwrap();
    let store = Store::from_bytes(build_bytes(&field, 9, &Thresholds::Ladder)).unwrap();
    let window = store.read_window(store.domain().data_rect()).unwrap();
    for x in 0..nans.len() {
        let v = window.samples()[5 * 20 + x];
        assert_eq!(
            v.to_bits(),
            0x7FC0_0000,
            "sample ({x}, 5): {:#x}",
            v.to_bits()
        );
    }
    // And in the block payloads themselves, every NaN is exactly those bits.
    let (cols, rows) = store.domain().nodes_across(store.domain().finest_level());
    let mut voids = 0;
    for y in 0..rows {
        for x in 0..cols {
            let block = store.block(x, y).unwrap();
            for s in block.view().samples() {
                let bits = s.get().to_bits();
                if f32::from_bits(bits).is_nan() {
                    assert_eq!(bits, 0x7FC0_0000);
                    voids += 1;
                }
            }
        }
    }
    assert!(voids >= nans.len(), "shared edges repeat voids: {voids}");
    assert!(
        verify(Bytes(store.source().0.clone()), VerifyMode::Full)
            .unwrap()
            .valid
    );
}

#[test]
fn the_ladder_constant_is_the_correctly_rounded_one_over_root_two() {
    const C: u64 = 0x3FE6_A09E_667F_3BCD;
    assert_eq!(cluster::LADDER_HALF_STEP.to_bits(), C);
    assert_eq!(std::f64::consts::FRAC_1_SQRT_2.to_bits(), C);
    assert_eq!(0.5f64.sqrt().to_bits(), C);
    // The trap the spec names: dividing by a rounded √2 lands one ulp below.
    assert_eq!((1.0 / 2f64.sqrt()).to_bits(), C - 1);
    // The odd rungs of the default ladder use exactly C.
    let root = 100.0f64;
    let ladder = cluster::default_ladder(root, Some(1e-3));
    for k in [1i32, 3, 5, 7] {
        let want = root * 0.5f64.powi((k - 1) / 2) * f64::from_bits(C);
        assert!(
            ladder.iter().any(|&t| t.to_bits() == want.to_bits()),
            "rung {k}: {want} not in {ladder:?}"
        );
    }
}

/// Container §3, step 2: a slot 0 that is sealed but invalid names no page size, so the
/// reader searches every allowed offset for slot 1 rather than trusting the page size it
/// names. Here slot 0 is resealed naming 8192 with a reserved field set (invalid whatever the
/// file's length), and slot 1 at 4096 holds txn 10: the file opens at txn 10, and the
/// validator fails I-4 (the inactive slot is not a valid record) and nothing else.
#[test]
fn a_sealed_but_invalid_slot_0_names_no_page_size() {
    let clean = fresh();
    let p = u32_at(&clean, 12);
    assert_eq!(p, 4096);
    let mut file = clean.clone();
    put_record(
        &mut file,
        p as usize,
        record_like(&clean, FORMAT_MAJOR, 10, p),
    );
    let mut bad = record_like(&clean, FORMAT_MAJOR, 1, 8192);
    bad[36] = 1; // the reserved word after the flags
    put_record(&mut file, 0, bad);
    let store = Store::from_bytes(file.clone()).unwrap();
    assert_eq!(store.txn_id(), 10);
    let report = verify(Bytes(&file), VerifyMode::Full).unwrap();
    let failed: Vec<Invariant> = report
        .checks
        .iter()
        .filter(|c| c.status == CheckStatus::Failed)
        .map(|c| c.id)
        .collect();
    assert_eq!(failed, vec![Invariant::InactiveSlot], "{report:?}");
}

/// Container §6.1 and I-10: a node's thinning bits (3–6) are reserved in a file whose
/// dataset header lacks flag 16, even in format 6: the fast validator fails I-10 and a
/// reader refuses the grid as corrupt. The file keeps its tables in pages (no bundle), so
/// one node record is changed in place and its page resealed.
#[test]
fn thinning_bits_without_the_header_flag_are_reserved() {
    use fmrh::model::BuildOptions;
    use fmrh::store::{write_to, WriteOptions};
    let hf = hills();
    let model = fmrh::model::Model::build(hf.clone(), &BuildOptions::default()).unwrap();
    let mut out = std::io::Cursor::new(Vec::new());
    let options = WriteOptions {
        bundle_limit: 0,
        ..WriteOptions::default()
    };
    write_to(&model, &hf.metadata, &options, &mut out).unwrap();
    let mut file = out.into_inner();
    let p = u32_at(&file, 12) as usize;
    assert!(verify(Bytes(&file), VerifyMode::Fast).unwrap().valid);
    // The node table's first leaf (page tag FMNT at level 0): node 0, the root, has a grid.
    let page = (2..file.len() / p)
        .find(|&n| &file[n * p..n * p + 4] == b"FMNT" && u16_at(&file, n * p + 16) == 0)
        .expect("a node table leaf page");
    let at = page * p;
    let flags = at + 24 + 10; // record 0's flags (§6.1, offset 10)
    let old = u16_at(&file, flags);
    file[flags..flags + 2].copy_from_slice(&(old | 1 << 3).to_le_bytes());
    let crc = fmrh::format::crc32(&file[at + 8..at + p]);
    file[at + 4..at + 8].copy_from_slice(&crc.to_le_bytes());
    let report = verify(Bytes(&file), VerifyMode::Fast).unwrap();
    assert_eq!(check(&report, Invariant::NodeTable), CheckStatus::Failed);
    let store = Store::from_bytes(file).unwrap();
    let root = store.node(0).unwrap();
    assert_eq!(root.grid_thin, 1);
    assert!(matches!(
        store.grid(&root),
        Err(Error::Corrupt {
            invariant: Invariant::NodeTable,
            ..
        })
    ));
}

/// Issue 39: a sealed record with `txn_id = 2^62` made every command exit 75, "superseded by
/// txn 2^62", naming its own state, so a retry looped forever. Ids stop at `2^62 - 1` (§2):
/// such a record is invalid (I-1, corrupt, exit 1); the last id opens, reads, and a commit on
/// it is refused without touching the file.
#[test]
fn transaction_ids_stop_below_two_to_the_62() {
    let built = fresh();
    let p = u32_at(&built, 12);
    let limit = fmrh::raw::MAX_TXN_ID;
    assert_eq!(limit, (1 << 62) - 1);
    for txn in [limit + 1, u64::MAX] {
        let mut file = built.clone();
        put_record(&mut file, 0, record_like(&built, FORMAT_MAJOR, txn, p));
        match Store::from_bytes(file.clone()) {
            Err(Error::Corrupt { invariant, .. }) => {
                assert_eq!(invariant, Invariant::CommitRecord, "txn {txn}")
            }
            other => panic!("txn {txn}: {:?}", other.map(|s| s.txn_id())),
        }
        let report = verify(Bytes(&file), VerifyMode::Fast).unwrap();
        assert_eq!(check(&report, Invariant::CommitRecord), CheckStatus::Failed);
        assert!(!report.valid && !report.busy);
    }
    let mut file = built.clone();
    put_record(&mut file, 0, record_like(&built, FORMAT_MAJOR, limit, p));
    let store = Store::from_bytes(file.clone()).unwrap();
    assert_eq!(store.txn_id(), limit);
    assert!(verify(Bytes(&file), VerifyMode::Full).unwrap().valid);
    let disk = SimDisk::new(file.clone());
    match Container::open_io(disk.clone()) {
        // Opening a container marks the state (a commit of its own): refused.
        Err(Error::Unsupported { reason, .. }) => assert!(reason.contains("last"), "{reason}"),
        Ok((container, _)) => {
            let mut txn = container.begin_write().unwrap();
            txn.replace_region(10, 10, &patch(4, 4, 3.0)).unwrap();
            match txn.commit() {
                Err(Error::Unsupported { reason, .. }) => {
                    assert!(reason.contains("last"), "{reason}")
                }
                other => panic!("a commit past the last txn id: {other:?}"),
            }
        }
        Err(e) => panic!("{e}"),
    }
    assert_eq!(disk.current(), file, "the refused commit changed the file");
}
