//! Transactions: replacing samples through a `Container` gives exactly the file a fresh
//! build of the new samples describes (same nodes, errors and cuts), the result passes
//! `verify --full`, snapshots keep their state across commits, an aborted transaction
//! changes nothing, and a snapshot taken in the middle of a commit reads a state some commit
//! made (never the writer's recovery mark, which copies a state under a new txn id).

mod common;

use common::txn::{build_bytes, described, paste, patch, samples_digest};
use fmrh::model::Thresholds;
use std::path::Path;
use std::sync::{Arc, Condvar, Mutex};

use fmrh::store::io::{Io, SimDisk};
use fmrh::store::{verify, Bytes, Container};
use fmrh::{store::Store, Heightfield};

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
        let report = verify(Bytes(disk.current()), fmrh::store::VerifyMode::Full).unwrap();
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
            let report = verify(Bytes(after.current()), fmrh::store::VerifyMode::Full).unwrap();
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

/// A device that stops the writer at its `pause_at`-th write until a reader has taken a
/// snapshot, so a test can look at a commit from the middle.
struct PausingDisk {
    disk: SimDisk,
    pause_at: u64,
    writes: Mutex<u64>,
    /// 0: running; 1: writer paused, waiting for the reader; 2: reader done.
    gate: Arc<(Mutex<u8>, Condvar)>,
}

impl Io for PausingDisk {
    fn len(&self) -> std::io::Result<u64> {
        self.disk.len()
    }
    fn read_at(&self, offset: u64, buf: &mut [u8]) -> std::io::Result<()> {
        self.disk.read_at(offset, buf)
    }
    fn write_at(&self, offset: u64, data: &[u8]) -> std::io::Result<()> {
        let n = {
            let mut w = self.writes.lock().unwrap();
            *w += 1;
            *w
        };
        if n == self.pause_at {
            let (state, cv) = &*self.gate;
            let mut s = state.lock().unwrap();
            *s = 1;
            cv.notify_all();
            while *s != 2 {
                s = cv.wait(s).unwrap();
            }
        }
        self.disk.write_at(offset, data)
    }
    fn sync(&self) -> std::io::Result<()> {
        self.disk.sync()
    }
    fn set_len(&self, len: u64) -> std::io::Result<()> {
        self.disk.set_len(len)
    }
    fn name(&self) -> &Path {
        self.disk.name()
    }
}

/// Regression (the flaky `readers_running_scenes_see_only_whole_snapshots`): the first
/// commit after opening publishes a recovery mark (the durable record copied under txn + 1)
/// before writing its pages. A snapshot taken right then must read the opened state's txn,
/// which is the one readers knew, not the mark's, which no commit returned.
#[test]
fn a_snapshot_in_the_middle_of_a_commit_reads_a_committed_state() {
    let hf = terrain(130, 97);
    let gate = Arc::new((Mutex::new(0u8), Condvar::new()));
    let disk = PausingDisk {
        disk: SimDisk::new(build_bytes(&hf, 17, &Thresholds::Ladder)),
        // Write 1 is the mark's record; write 2 is the commit's first payload.
        pause_at: 2,
        writes: Mutex::new(0),
        gate: Arc::clone(&gate),
    };
    let (container, _) = Container::open_io(disk).unwrap();
    let opened = container.read().unwrap().txn_id();
    let seen = std::thread::scope(|scope| {
        let reader = scope.spawn(|| {
            let (state, cv) = &*gate;
            let mut s = state.lock().unwrap();
            while *s != 1 {
                s = cv.wait(s).unwrap();
            }
            let txn = container.read().unwrap().txn_id();
            *s = 2;
            cv.notify_all();
            txn
        });
        let mut txn = container.begin_write().unwrap();
        txn.replace_region(3, 3, &patch(20, 20, 4.0)).unwrap();
        let summary = txn.commit().unwrap();
        (reader.join().unwrap(), summary.txn_id)
    });
    let (mid_commit, committed) = seen;
    assert_eq!(
        mid_commit, opened,
        "a snapshot read the recovery mark's txn"
    );
    assert_eq!(committed, opened + 2, "the mark took txn {}", opened + 1);
    assert_eq!(container.read().unwrap().txn_id(), committed);
}
