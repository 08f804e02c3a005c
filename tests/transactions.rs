//! Transactions: replacing samples through a `Container` gives exactly the file a fresh
//! build of the new samples describes (same nodes, errors and cuts), the result passes
//! `verify --full`, snapshots keep their state across commits, and an aborted transaction
//! changes nothing.

mod common;

use common::txn::{build_bytes, described, paste, patch, samples_digest};
use fmrh::model::Thresholds;
use fmrh::store::io::SimDisk;
use fmrh::store::{verify, Bytes, Container};
use fmrh::{Heightfield, Store};

fn terrain(w: u32, h: u32) -> Heightfield {
    Heightfield::from_fn(w, h, |x, y| {
        ((x as f32 * 0.11).sin() * 30.0 + (y as f32 * 0.07).cos() * 20.0 + (x * y) as f32 * 0.01)
            .round()
    })
    .unwrap()
}

#[test]
fn replacement_commits_equal_a_fresh_build() {
    let (w, h) = (130u32, 97u32);
    let mut hf = terrain(w, h);
    let bytes = build_bytes(&hf, 17, &Thresholds::Ladder);
    let thresholds: Vec<f64> = Store::from_bytes(bytes.clone())
        .unwrap()
        .clusters()
        .iter()
        .map(|c| c.threshold)
        .collect();
    let disk = SimDisk::new(bytes);
    let (container, _) = Container::open_io(disk.clone()).unwrap();
    let edits = [
        (5u64, 9u64, patch(17, 17, 1.0)),
        (100, 80, patch(30, 17, 2.0)),
        (
            40,
            40,
            Heightfield::from_fn(9, 9, |x, y| if x == y { f32::NAN } else { 7.0 }).unwrap(),
        ),
        (0, 0, Heightfield::from_fn(w, 3, |_, _| 0.0).unwrap()),
    ];
    for (i, (c0, r0, p)) in edits.iter().enumerate() {
        let before = container.read().unwrap();
        let before_txn = before.txn_id();
        let before_model = described(&before);
        let mut txn = container.begin_write().unwrap();
        txn.replace_region(*c0, *r0, p).unwrap();
        let summary = txn.commit().unwrap();
        assert!(summary.blocks > 0, "edit {i}: {summary:?}");
        hf = paste(&hf, *c0, *r0, p);
        let fresh = build_bytes(&hf, 17, &Thresholds::Explicit(thresholds.clone()));
        let now = container.read().unwrap();
        assert_eq!(
            described(&now),
            described(&Store::from_bytes(fresh).unwrap()),
            "edit {i}"
        );
        // The samples read back are the new ones, exactly.
        let back = now.read_window(now.domain().data_rect()).unwrap();
        assert!(back
            .samples()
            .iter()
            .zip(hf.samples())
            .all(|(a, b)| a.to_bits() == b.to_bits() || (a.is_nan() && b.is_nan())));
        // The old snapshot still reads the old state.
        assert_eq!(before.txn_id(), before_txn);
        assert_eq!(described(&before), before_model);
        drop(before);
        let report = verify(Bytes(disk.current()), fmrh::VerifyMode::Full).unwrap();
        assert!(report.valid, "edit {i}: {report:#?}");
    }
}

#[test]
fn abort_changes_nothing() {
    let bytes = build_bytes(&terrain(60, 60), 9, &Thresholds::Ladder);
    let disk = SimDisk::new(bytes.clone());
    let (container, _) = Container::open_io(disk.clone()).unwrap();
    let mut txn = container.begin_write().unwrap();
    txn.replace_region(3, 3, &patch(10, 10, 3.0)).unwrap();
    txn.abort();
    assert_eq!(disk.current(), bytes);
    // The next transaction starts from the stored state, not the aborted one.
    let mut txn = container.begin_write().unwrap();
    txn.replace_region(20, 20, &patch(5, 5, 4.0)).unwrap();
    txn.commit().unwrap();
    let s = container.read().unwrap();
    let back = s.read_window(s.domain().data_rect()).unwrap();
    assert_eq!(back.get(3, 3), terrain(60, 60).get(3, 3));
}

/// Crash after every mutating operation of a commit, with several damage patterns: the
/// reopened file verifies and holds exactly the old or the new samples.
#[test]
fn crash_at_every_operation_recovers_old_or_new() {
    use fmrh::store::io::Damage;
    let bytes = build_bytes(&terrain(90, 70), 17, &Thresholds::Ladder);
    let old = samples_digest(&Store::from_bytes(bytes.clone()).unwrap());
    // The new state, and how many operations its commit takes.
    let probe = SimDisk::new(bytes.clone());
    let (c, _) = Container::open_io(probe.clone()).unwrap();
    let mut txn = c.begin_write().unwrap();
    txn.replace_region(20, 10, &patch(40, 30, 5.0)).unwrap();
    txn.commit().unwrap();
    let new = samples_digest(&c.read().unwrap());
    assert_ne!(old, new);
    let total = probe.ops();
    drop(c);
    let (mut olds, mut news) = (0, 0);
    for at in 0..=total {
        for damage in [Damage::KeepAll, Damage::DropAll]
            .into_iter()
            .chain((0..6).map(Damage::Random))
        {
            let disk = SimDisk::new(bytes.clone());
            let (c, _) = Container::open_io(disk.clone()).unwrap();
            disk.power_off_after(at);
            let result = (|| {
                let mut txn = c.begin_write()?;
                txn.replace_region(20, 10, &patch(40, 30, 5.0))?;
                txn.commit()
            })();
            assert_eq!(result.is_ok(), !disk.powered_off(), "at {at}");
            std::mem::forget(c); // the process died: no clean close
            let image = disk.crash_image(damage);
            let after = SimDisk::new(image);
            let (c2, _) = Container::open_io(after.clone())
                .unwrap_or_else(|e| panic!("at {at} {damage:?}: {e}"));
            let report = verify(Bytes(after.current()), fmrh::VerifyMode::Full).unwrap();
            assert!(report.valid, "at {at} {damage:?}: {report:#?}");
            let got = samples_digest(&c2.read().unwrap());
            if got == old {
                olds += 1;
            } else {
                assert_eq!(got, new, "at {at} {damage:?}");
                news += 1;
            }
        }
    }
    eprintln!(
        "{} crash points x 8 damages: old {olds}, new {news}",
        total + 1
    );
    assert!(olds > 0 && news > 0);
}
