//! The crash matrix on a real DEM (Puget Sound east, 512 x 512): a workload of five write
//! transactions (six replacements: a raised block and voids together, a flattened region
//! that merges nodes, rough ground there that splits them, flat again, and a small one whose
//! commit cuts the file's free tail) and a clean close, crashed after every mutating
//! operation (write, sync, set_len) with six damage patterns to the unsynced operations
//! (keep all, drop all, four random mixes of kept, dropped and torn 512-byte sectors).
//!
//! After every crash the file must open (recovering), pass `verify --full`, and hold exactly
//! the state of the last commit that returned or of the one in flight: the same digest of
//! all samples and the same model (node records and every cut). Each state's model is checked
//! once against a fresh build of its samples, so "the same model" means "the model a fresh
//! build of that content gives". Recovery itself is crashed too, after each of its
//! operations, and the next open must still recover. A recovered file must accept a further
//! commit. Both runs happen twice: with the metadata in a bundle (format 3.0, what a file of
//! this size gets) and with every table in pages of its own (what a larger file gets), since
//! the two commit different pages.

mod common;

use common::data;
use common::txn::{
    build_bytes, build_bytes_paged, described, digest_samples, paste, samples_digest, Described,
};
use fmrh::ingest::{self, IngestOptions};
use fmrh::model::Thresholds;
use fmrh::store::io::{Damage, SimDisk};
use fmrh::store::{verify, Bytes, Container};
use fmrh::{store::Store, Heightfield};
use rayon::prelude::*;
use std::collections::HashMap;
use std::hash::{BuildHasher, RandomState};
use std::sync::Mutex;

type Txn = Vec<(u64, u64, Heightfield)>;

fn workload() -> Vec<Txn> {
    let raised = Heightfield::from_fn(65, 65, |x, y| 150.0 + (x + y) as f32 * 0.5).unwrap();
    let voids = Heightfield::from_fn(30, 20, |x, y| {
        if (x + 2 * y) % 7 == 0 {
            f32::NAN
        } else {
            (x * y) as f32
        }
    })
    .unwrap();
    // Large enough that the rough grids outgrow every free run and are appended: commits
    // reuse the shortest free run that holds an extent and pack small payloads, so a small
    // change fits in what the file already has.
    let flat = Heightfield::from_fn(400, 300, |_, _| 100.0).unwrap();
    let steps = Heightfield::from_fn(400, 300, |x, y| {
        ((x.wrapping_mul(2_654_435_761) ^ y.wrapping_mul(40_503)) % 97) as f32 * 2.5
    })
    .unwrap();
    vec![
        vec![(100, 100, raised), (300, 50, voids)],
        // Flat ground: nodes merge.
        vec![(100, 150, flat)],
        // Rough ground in the same place: they split again, and their new grids are
        // appended at the file's end ...
        vec![(100, 150, steps)],
        // ... flat again: they merge, and those grids are freed ...
        vec![(
            100,
            150,
            Heightfield::from_fn(400, 300, |_, _| 101.0).unwrap(),
        )],
        // ... and cut off by the next commit (a length change after the record).
        vec![(
            450,
            10,
            Heightfield::from_fn(20, 12, |x, y| (x + y) as f32).unwrap(),
        )],
    ]
}

/// Runs the transactions in order; returns how many committed.
fn run(c: &Container<SimDisk>, txns: &[Txn]) -> fmrh::Result<usize> {
    let mut done = 0;
    for txn in txns {
        let mut w = c.begin_write()?;
        for (col0, row0, p) in txn {
            w.replace_region(*col0, *row0, p)?;
        }
        w.commit()?;
        done += 1;
    }
    Ok(done)
}

struct State {
    digest: u64,
    model: Described,
}

/// The states a crash may leave, and which distinct crash images were already checked.
///
/// Checking an image (open and recover it, `verify --full`, digest every sample, describe
/// the model) is a deterministic function of its bytes, and many crash points and damage
/// patterns leave the same bytes (a crash with nothing unsynced, say, gives one image
/// under all six). So each distinct image is checked once: images are keyed by their
/// length and two independently keyed 64-bit SipHashes of their bytes, and a repeat only
/// asserts that the state its first check found is allowed where it occurs now.
struct States {
    list: Vec<State>,
    hashers: (RandomState, RandomState),
    checked: Mutex<HashMap<(usize, u64, u64), usize>>,
}

impl States {
    fn new(list: Vec<State>) -> States {
        States {
            list,
            hashers: (RandomState::new(), RandomState::new()),
            checked: Mutex::new(HashMap::new()),
        }
    }

    /// Opens `image`, checks it, and returns which state it holds (one of `allowed`).
    fn check(&self, image: Vec<u8>, allowed: &[usize], what: &str) -> usize {
        let id = (
            image.len(),
            self.hashers.0.hash_one(&image),
            self.hashers.1.hash_one(&image),
        );
        let seen = self.checked.lock().unwrap().get(&id).copied();
        let which = match seen {
            Some(which) => which,
            None => {
                let which = self.check_afresh(image, allowed, what);
                self.checked.lock().unwrap().insert(id, which);
                which
            }
        };
        assert!(
            allowed.contains(&which),
            "{what}: samples are state {which}, none of the states {allowed:?}"
        );
        which
    }

    fn check_afresh(&self, image: Vec<u8>, allowed: &[usize], what: &str) -> usize {
        let disk = SimDisk::new(image);
        let (c, _) = Container::open_io(disk.clone()).unwrap_or_else(|e| panic!("{what}: {e}"));
        let report = verify(Bytes(disk.current()), fmrh::store::VerifyMode::Full).unwrap();
        assert!(report.valid, "{what}: {report:#?}");
        let s = c.read().unwrap();
        let digest = samples_digest(&s);
        let which = allowed
            .iter()
            .copied()
            .find(|&k| self.list[k].digest == digest)
            .unwrap_or_else(|| panic!("{what}: samples are none of the states {allowed:?}"));
        assert!(described(&s) == self.list[which].model, "{what}: model");
        which
    }
}

/// The workload on the real DEM, run once without faults: the container's bytes, the
/// transactions, every state (each checked against a fresh build of its samples), the
/// operation count at the end of each commit, and the total with the clean close.
struct Workload {
    bytes: Vec<u8>,
    txns: Vec<Txn>,
    states: States,
    ends: Vec<u64>,
    total: u64,
}

/// Opens `disk` for transactions; with `paged`, its commits keep every table in pages of
/// their own.
fn open(disk: &SimDisk, paged: bool) -> fmrh::Result<Container<SimDisk>> {
    let (c, _) = Container::open_io(disk.clone())?;
    if paged {
        c.set_bundle_limit(0);
    }
    Ok(c)
}

fn prepare(paged: bool) -> Workload {
    let src = ingest::load(
        &data("puget-sound-east-512/ps-e_lg.f32"),
        &IngestOptions::default(),
    )
    .unwrap();
    let bytes = if paged {
        build_bytes_paged(&src, 65, &Thresholds::Ladder)
    } else {
        build_bytes(&src, 65, &Thresholds::Ladder)
    };
    let stored = Store::from_bytes(bytes.clone()).unwrap();
    assert_eq!(stored.layout().unwrap().bundle_bytes == 0, paged);
    let thresholds = common::txn::thresholds(&stored);
    let txns = workload();
    let probe = SimDisk::new(bytes.clone());
    let c = open(&probe, paged).unwrap();
    let mut states = vec![State {
        digest: samples_digest(&stored),
        model: described(&stored),
    }];
    let mut ends = Vec::new();
    let mut hf = src;
    for (k, txn) in txns.iter().enumerate() {
        assert_eq!(run(&c, std::slice::from_ref(txn)).unwrap(), 1);
        ends.push(probe.ops());
        for (col0, row0, p) in txn {
            hf = paste(&hf, *col0, *row0, p);
        }
        let fresh = build_bytes(&hf, 65, &Thresholds::Explicit(thresholds.clone()));
        let fresh = Store::from_bytes(fresh).unwrap();
        let s = c.read().unwrap();
        let state = State {
            digest: samples_digest(&s),
            model: described(&s),
        };
        assert_eq!(state.digest, digest_samples(hf.samples()), "txn {k}");
        assert!(
            state.model == described(&fresh),
            "txn {k}: model != fresh build"
        );
        assert!(states.iter().all(|o| o.digest != state.digest));
        states.push(state);
    }
    c.close().unwrap();
    assert!(
        probe.count(fmrh::store::io::OpKind::SetLen) > 0,
        "no length change"
    );
    Workload {
        bytes,
        txns,
        states: States::new(states),
        ends,
        total: probe.ops(),
    }
}

#[test]
fn crash_anywhere_in_a_real_workload_recovers_old_or_new() {
    crash_anywhere(false);
}

#[test]
fn crash_anywhere_with_paged_tables_recovers_old_or_new() {
    crash_anywhere(true);
}

fn crash_anywhere(paged: bool) {
    let Workload {
        bytes,
        txns,
        states,
        ends,
        total,
    } = prepare(paged);
    let last = txns.len();

    let damages = |at: u64| {
        [Damage::KeepAll, Damage::DropAll]
            .into_iter()
            .chain((0..4).map(move |i| Damage::Random(at * 16 + i)))
    };
    // Per crash point: (cases, recovered-old, recovered-new, recovery crashes).
    let results: Vec<(u64, u64, u64, u64)> = (0..=total)
        .into_par_iter()
        .map(|at| {
            let committed = ends.iter().filter(|&&e| e <= at).count();
            let allowed: Vec<usize> = (committed..=(committed + 1).min(last)).collect();
            let disk = SimDisk::new(bytes.clone());
            let c = open(&disk, paged).unwrap();
            disk.power_off_after(at);
            let done = match run(&c, &txns) {
                Ok(n) => c.close().map(|_| n),
                Err(e) => {
                    std::mem::forget(c); // the process died: no clean close
                    Err(e)
                }
            };
            match done {
                Ok(n) => assert!(n == last && !disk.powered_off(), "at {at}"),
                Err(_) => assert!(disk.powered_off(), "at {at}: failed without a crash"),
            }
            let (mut old, mut new, mut recovery_crashes) = (0, 0, 0);
            for damage in damages(at) {
                let what = format!("crash at op {at} with {damage:?}");
                let image = disk.crash_image(damage);
                // Crash recovery itself after each of its operations.
                let rec = SimDisk::new(image.clone());
                let opened = Container::open_io(rec.clone());
                let recovery_ops = rec.ops();
                drop(opened.unwrap_or_else(|e| panic!("{what}: {e}")));
                for r in 0..recovery_ops {
                    let again = SimDisk::new(image.clone());
                    again.power_off_after(r);
                    let opened = Container::open_io(again.clone());
                    assert!(
                        opened.is_err(),
                        "{what}: recovery survived a crash at op {r}"
                    );
                    let image2 = again.crash_image(Damage::Random(at ^ (r << 32)));
                    states.check(image2, &allowed, &format!("{what}, recovery op {r}"));
                    recovery_crashes += 1;
                }
                let which = states.check(image.clone(), &allowed, &what);
                if which == committed {
                    old += 1;
                } else {
                    new += 1;
                }
                // The recovered file takes a further commit.
                if matches!(damage, Damage::Random(s) if s % 16 == 0) {
                    let disk = SimDisk::new(image);
                    let c = open(&disk, paged).unwrap();
                    let mut w = c.begin_write().unwrap();
                    let p = Heightfield::from_fn(9, 9, |x, _| x as f32).unwrap();
                    w.replace_region(7, 7, &p).unwrap();
                    w.commit()
                        .unwrap_or_else(|e| panic!("{what}: commit after recovery: {e}"));
                    drop(c);
                    let report =
                        verify(Bytes(disk.current()), fmrh::store::VerifyMode::Full).unwrap();
                    assert!(report.valid, "{what}: after a further commit: {report:#?}");
                }
            }
            (damages(at).count() as u64, old, new, recovery_crashes)
        })
        .collect();
    let sum = |f: fn(&(u64, u64, u64, u64)) -> u64| results.iter().map(f).sum::<u64>();
    let (cases, old, new, rec) = (sum(|r| r.0), sum(|r| r.1), sum(|r| r.2), sum(|r| r.3));
    eprintln!(
        "crash matrix (paged tables: {paged}): {} crash points x 6 damages = {cases} \
         crashes: recovered old {old}, recovered new {new}, failures 0; {rec} crashes during \
         recovery, all recovered",
        total + 1
    );
    assert_eq!(old + new, cases);
    assert!(old > 0 && new > 0 && rec > 0);
}

/// The I/O error loop: the same workload with the Nth write, sync or length change failing
/// (once, or from then on), for N = 1, 2, ... until the workload completes without meeting
/// the fault. Each time the error surfaces as an I/O error, the container is poisoned (every
/// later call fails with `Poisoned` and touches nothing), and the file, whatever becomes of
/// the operations not yet synced, holds the last committed state or the one in flight.
#[test]
fn io_error_at_every_operation_poisons_and_keeps_old_or_new() {
    io_errors(false);
}

#[test]
fn io_error_with_paged_tables_poisons_and_keeps_old_or_new() {
    io_errors(true);
}

fn io_errors(paged: bool) {
    use fmrh::store::io::{Fault, OpKind};
    use fmrh::Error;
    let Workload {
        bytes,
        txns,
        states,
        ..
    } = prepare(paged);

    let cases: Vec<(OpKind, bool)> = [OpKind::Write, OpKind::Sync, OpKind::SetLen]
        .into_iter()
        .flat_map(|k| [(k, false), (k, true)])
        .collect();
    let counts: Vec<(u64, u64)> = cases
        .par_iter()
        .map(|&(kind, sticky)| {
            let (mut failed, mut n) = (0u64, 1u64);
            loop {
                let what = format!("{kind:?} #{n} failing (sticky: {sticky})");
                let disk = SimDisk::new(bytes.clone());
                let c = open(&disk, paged).unwrap();
                disk.inject(Fault {
                    kind,
                    nth: n,
                    sticky,
                });
                let mut committed = 0;
                let mut error = None;
                for txn in &txns {
                    match run(&c, std::slice::from_ref(txn)) {
                        Ok(_) => committed += 1,
                        Err(e) => {
                            error = Some(e);
                            break;
                        }
                    }
                }
                match error {
                    Some(error) => {
                        assert!(matches!(error, Error::Io { .. }), "{what}: {error}");
                        assert!(c.is_poisoned(), "{what}");
                        let ops = disk.ops();
                        assert!(matches!(c.read(), Err(Error::Poisoned { .. })), "{what}");
                        assert!(
                            matches!(c.begin_write(), Err(Error::Poisoned { .. })),
                            "{what}"
                        );
                        assert!(matches!(c.close(), Err(Error::Poisoned { .. })), "{what}");
                        assert_eq!(disk.ops(), ops, "{what}: a poisoned container wrote");
                    }
                    // The last chance: the clean close (its handle is gone either way).
                    None => match c.close() {
                        Ok(_) => {
                            assert!(disk.count(kind) < n, "{what}: the fault fired unseen");
                            break;
                        }
                        Err(error) => {
                            assert!(matches!(error, Error::Io { .. }), "{what}: {error}");
                        }
                    },
                }
                failed += 1;
                let allowed: Vec<usize> = (committed..=(committed + 1).min(txns.len())).collect();
                for damage in [Damage::KeepAll, Damage::DropAll, Damage::Random(n)] {
                    states.check(
                        disk.crash_image(damage),
                        &allowed,
                        &format!("{what}, then {damage:?}"),
                    );
                }
                n += 1;
            }
            (n, failed)
        })
        .collect();
    for ((kind, sticky), (n, failed)) in cases.iter().zip(&counts) {
        eprintln!(
            "io error loop (paged tables: {paged}): {kind:?} (sticky: {sticky}): N = 1..={}: \
             {failed} errors surfaced, each poisoned, file old or new; N = {n} completes",
            n - 1
        );
        assert!(*failed > 0);
    }
}
