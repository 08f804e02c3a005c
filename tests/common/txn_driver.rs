//! A driver for random transaction workloads on a simulated disk, checked step by step against
//! an in-memory model (the samples of the last committed state and of the open transaction).
//! The proptest state machine (`tests/txn_state_machine.rs`) and the cargo-fuzz target
//! `transactions` (which includes this file by path) both run it, so both check the same
//! properties:
//!
//! - the latest snapshot holds exactly the model's committed samples, and a transaction's
//!   replacements are invisible until it commits;
//! - every snapshot taken earlier keeps reading the samples it started with;
//! - a replacement that does not fit is refused with `InvalidArgument` and changes nothing;
//! - after a crash (at any operation of a commit, with any damage, even a second crash during
//!   recovery) or an injected I/O error (which must poison the container), the reopened file
//!   passes `verify --full` and holds the old or the new committed samples;
//! - the model the file describes (node records and every cut) equals a fresh build of its
//!   samples with the stored thresholds (checked at every reopen and at the end).
//!
//! Only the `fmrh` public API is used, and no test framework: a violated property panics.

#![allow(dead_code)]

use std::io::Cursor;

use fmrh::model::{BuildOptions, Model, Thresholds};
use fmrh::store::io::{Damage, Fault, OpKind, SimDisk};
use fmrh::store::{verify, write_to, Bytes, Container, Snapshot, Source, WriteOptions};
use fmrh::{store::Store, Error, Heightfield};

/// One step of a workload.
#[derive(Clone, Debug)]
pub enum Op {
    /// Starts a transaction (ignored when one is open).
    Begin,
    /// Adds a replacement to the open transaction (ignored when none is). The patch's
    /// samples come from `seed`; `voids` puts voids in it. It may not fit.
    Replace {
        col0: u16,
        row0: u16,
        width: u8,
        height: u8,
        seed: u32,
        voids: bool,
    },
    /// Commits the open transaction.
    Commit,
    /// Aborts it.
    Abort,
    /// Commits the open transaction (if any) with the power failing after `after` more
    /// operations, then crashes with `damage`; with `recovery`, the first reopen crashes
    /// too, after that many of its operations, with damage from the second seed.
    Crash {
        after: u16,
        damage: u64,
        recovery: Option<(u8, u64)>,
    },
    /// Commits the open transaction (if any) with an operation of `kind` failing: the
    /// `nth`-from-now (reduced to the range a commit reaches).
    Fail { kind: u8, nth: u8, sticky: bool },
    /// Closes the container cleanly and opens it again.
    Reopen,
    /// Takes a snapshot and keeps it.
    Snapshot,
    /// Drops the snapshot at this index (modulo how many are held).
    DropSnapshot(u8),
}

/// The samples of a state, with every void as the same NaN, for comparison.
fn canonical(samples: &[f32]) -> Vec<u32> {
    samples
        .iter()
        .map(|v| if v.is_nan() { 0x7FC0_0000 } else { v.to_bits() })
        .collect()
}

fn samples_of<S: Source>(s: &Store<S>) -> Vec<u32> {
    let hf = s
        .read_window(s.domain().data_rect())
        .expect("a committed state reads back");
    canonical(hf.samples())
}

/// The model a container describes, in comparable form: every node record without its
/// payload location, and every cut as (key, level) lists.
pub type Described = (Vec<String>, Vec<Vec<(u64, u8)>>);

/// The [`Described`] form of the model `s` holds.
pub fn described<S: Source>(s: &Store<S>) -> Described {
    let nodes = s
        .nodes()
        .expect("nodes read")
        .iter()
        .map(|n| {
            format!(
                "{} {} {} {} {} {} {} {:x} {:x} {:x} {:x} {}",
                n.key.0,
                n.level,
                n.child_mask,
                n.x,
                n.y,
                n.parent.unwrap_or(u32::MAX),
                n.subtree_len,
                n.static_error.to_bits(),
                n.monotone_error.to_bits(),
                n.min_height.to_bits(),
                n.max_height.to_bits(),
                n.valid_samples,
            )
        })
        .collect();
    let cuts = (0..s.clusters().len())
        .map(|c| {
            s.scan_codes(c, 0..s.clusters()[c].nodes())
                .expect("cluster scans")
                .map(|e| {
                    let e = e.expect("cluster entry reads");
                    (e.key.0, e.level)
                })
                .collect()
        })
        .collect();
    (nodes, cuts)
}

/// The driver: a simulated disk, the container on it, and the model.
pub struct Driver {
    width: u32,
    height: u32,
    block: u32,
    thresholds: Vec<f64>,
    disk: SimDisk,
    container: Option<Container<SimDisk>>,
    /// The samples of the last committed state.
    committed: Vec<f32>,
    /// The open transaction's replacements, applied at commit.
    txn: Option<Vec<(u64, u64, Heightfield)>>,
    snapshots: Vec<(Snapshot<SimDisk>, Vec<u32>)>,
    /// The samples the last commit attempted would give.
    last_attempt: Vec<f32>,
    /// Steps that checked a crash or a failure, for reports.
    pub crashes: u64,
    pub failures: u64,
    pub commits: u64,
}

/// The bytes of a fresh container of `hf`.
pub fn build_bytes(hf: &Heightfield, block: u32, thresholds: &Thresholds) -> Vec<u8> {
    build_bytes_with(hf, block, thresholds, &WriteOptions::default())
}

/// [`build_bytes`] with every table in pages of its own (no metadata bundle): the layout
/// of a file whose metadata is too large to bundle.
#[allow(dead_code)]
pub fn build_bytes_paged(hf: &Heightfield, block: u32, thresholds: &Thresholds) -> Vec<u8> {
    let paged = WriteOptions {
        bundle_limit: 0,
        ..WriteOptions::default()
    };
    build_bytes_with(hf, block, thresholds, &paged)
}

fn build_bytes_with(
    hf: &Heightfield,
    block: u32,
    thresholds: &Thresholds,
    write: &WriteOptions,
) -> Vec<u8> {
    let model = Model::build(
        hf.clone(),
        &BuildOptions {
            block_size: block,
            thresholds: thresholds.clone(),
            precision: None,
            thin: Default::default(),
        },
    )
    .expect("the model builds");
    let mut out = Cursor::new(Vec::new());
    write_to(&model, &hf.metadata, write, &mut out).expect("it writes");
    out.into_inner()
}

impl Driver {
    /// A container of a `width x height` synthetic terrain with blocks of `block` samples.
    pub fn new(width: u32, height: u32, block: u32) -> Driver {
        let hf = Heightfield::from_fn(width, height, |x, y| {
            ((x as f32 * 0.31).sin() * 12.0 + (y as f32 * 0.17).cos() * 9.0 + (x ^ y) as f32)
                .round()
        })
        .expect("the terrain is valid");
        let bytes = build_bytes(&hf, block, &Thresholds::Ladder);
        let thresholds = Store::from_bytes(bytes.clone())
            .expect("it opens")
            .clusters()
            .iter()
            .map(|c| c.threshold)
            .collect();
        let disk = SimDisk::new(bytes);
        let (container, _) = Container::open_io(disk.clone()).expect("it opens");
        Driver {
            width,
            height,
            block,
            thresholds,
            disk,
            container: Some(container),
            committed: hf.samples().to_vec(),
            txn: None,
            snapshots: Vec::new(),
            last_attempt: Vec::new(),
            crashes: 0,
            failures: 0,
            commits: 0,
        }
    }

    fn container(&self) -> &Container<SimDisk> {
        self.container.as_ref().expect("a container is open")
    }

    /// Whether a transaction is open.
    pub fn in_txn(&self) -> bool {
        self.txn.is_some()
    }

    /// Runs one step and checks what it promises.
    pub fn step(&mut self, op: &Op) {
        match *op {
            Op::Begin => {
                if self.txn.is_none() {
                    self.txn = Some(Vec::new());
                }
            }
            Op::Replace {
                col0,
                row0,
                width,
                height,
                seed,
                voids,
            } => {
                if let Some(txn) = self.txn.as_mut() {
                    let (w, h) = (u32::from(width.max(1)), u32::from(height.max(1)));
                    let patch = Heightfield::from_fn(w, h, |x, y| {
                        let v = (x.wrapping_mul(seed | 1) ^ y.wrapping_mul(seed >> 3)) % 211;
                        if voids && v % 5 == 0 {
                            f32::NAN
                        } else {
                            v as f32 - 50.0
                        }
                    })
                    .expect("the patch is valid");
                    txn.push((u64::from(col0), u64::from(row0), patch));
                }
            }
            Op::Commit => {
                if self.txn.is_some() {
                    let result = self.commit();
                    self.finish_commit(result);
                }
            }
            Op::Abort => {
                self.txn = None;
            }
            Op::Crash {
                after,
                damage,
                recovery,
            } => self.crash(after, damage, recovery),
            Op::Fail { kind, nth, sticky } => self.fail(kind, nth, sticky),
            Op::Reopen => {
                self.txn = None;
                self.snapshots.clear();
                let c = self.container.take().expect("a container is open");
                c.close().expect("a clean close succeeds");
                let states = [self.committed.clone()];
                self.open_checked(self.disk.current(), &states, None);
            }
            Op::Snapshot => {
                let s = self.container().read().expect("a snapshot");
                let samples = samples_of(&s);
                self.snapshots.push((s, samples));
            }
            Op::DropSnapshot(i) => {
                if !self.snapshots.is_empty() {
                    let i = usize::from(i) % self.snapshots.len();
                    self.snapshots.remove(i);
                }
            }
        }
        self.check();
    }

    /// The cheap checks after every step: the latest state and every snapshot.
    pub fn check(&self) {
        let c = self.container();
        let now = c.read().expect("a snapshot");
        assert!(
            samples_of(&now) == canonical(&self.committed),
            "the latest snapshot differs from the committed samples"
        );
        for (i, (s, samples)) in self.snapshots.iter().enumerate() {
            assert!(
                samples_of(s) == *samples,
                "snapshot {i} changed under a commit"
            );
        }
    }

    /// The expensive check: the file verifies and describes the model a fresh build gives.
    pub fn check_full(&self) {
        let report =
            verify(Bytes(self.disk.current()), fmrh::store::VerifyMode::Full).expect("verify runs");
        assert!(report.valid, "verify --full: {report:#?}");
        let now = self.container().read().expect("a snapshot");
        let hf = Heightfield::new(self.width, self.height, self.committed.clone())
            .expect("the samples form a heightfield");
        let fresh = build_bytes(
            &hf,
            self.block,
            &Thresholds::Explicit(self.thresholds.clone()),
        );
        let fresh = Store::from_bytes(fresh).expect("the fresh build opens");
        assert!(
            described(&now) == described(&fresh),
            "the stored model differs from a fresh build of the same samples"
        );
    }

    /// Commits the open transaction; returns the samples it committed. Replacements that do
    /// not fit must be refused without effect.
    fn commit(&mut self) -> Result<Vec<f32>, Error> {
        let txn = self.txn.take().unwrap_or_default();
        let fits = |col0: u64, row0: u64, patch: &Heightfield| {
            col0 + u64::from(patch.width()) <= u64::from(self.width)
                && row0 + u64::from(patch.height()) <= u64::from(self.height)
        };
        let mut next = self.committed.clone();
        for (col0, row0, patch) in &txn {
            if fits(*col0, *row0, patch) {
                let pw = u64::from(patch.width());
                for j in 0..u64::from(patch.height()) {
                    for k in 0..pw {
                        next[((row0 + j) * u64::from(self.width) + col0 + k) as usize] =
                            patch.samples()[(j * pw + k) as usize];
                    }
                }
            }
        }
        self.last_attempt = next.clone();
        let c = self.container.as_ref().expect("a container is open");
        let mut w = c.begin_write()?;
        for (col0, row0, patch) in &txn {
            match w.replace_region(*col0, *row0, patch) {
                Ok(()) => assert!(fits(*col0, *row0, patch), "a misfit patch was accepted"),
                Err(Error::InvalidArgument(_)) if !fits(*col0, *row0, patch) => {}
                Err(e) => panic!("replace_region: {e}"),
            }
            // Readers see the committed state while the transaction is open.
            let s = c.read()?;
            assert!(
                samples_of(&s) == canonical(&self.committed),
                "a reader saw an uncommitted replacement"
            );
        }
        w.commit()?;
        Ok(next)
    }

    fn finish_commit(&mut self, result: Result<Vec<f32>, Error>) {
        self.committed = result.expect("a commit without faults succeeds");
        self.commits += 1;
    }

    fn crash(&mut self, after: u16, damage: u64, recovery: Option<(u8, u64)>) {
        let old = self.committed.clone();
        self.disk.power_off_after(u64::from(after));
        // The states the file may hold after the crash: a commit that returned is durable.
        let states = if self.txn.is_some() {
            match self.commit() {
                Ok(next) => vec![next],
                Err(_) => {
                    assert!(self.disk.powered_off(), "a commit failed without a crash");
                    vec![old, self.last_attempt.clone()]
                }
            }
        } else {
            vec![old]
        };
        self.snapshots.clear();
        let damage = match damage % 4 {
            0 => Damage::KeepAll,
            1 => Damage::DropAll,
            _ => Damage::Random(damage),
        };
        let image = self.disk.crash_image(damage);
        // The process died: whatever its container does on the way out hits the old disk.
        drop(self.container.take());
        self.crashes += 1;
        self.open_checked(image, &states, recovery);
    }

    fn fail(&mut self, kind: u8, nth: u8, sticky: bool) {
        let kind = match kind % 3 {
            0 => OpKind::Write,
            1 => OpKind::Sync,
            _ => OpKind::SetLen,
        };
        let old = self.committed.clone();
        if self.txn.is_none() {
            return;
        }
        // A commit makes a few dozen writes, a few syncs, at most one or two length changes.
        let range = match kind {
            OpKind::Write => 40,
            OpKind::Sync => 4,
            OpKind::SetLen => 2,
        };
        let nth = self.disk.count(kind) + 1 + u64::from(nth) % range;
        self.disk.inject(Fault { kind, nth, sticky });
        match self.commit() {
            Ok(next) => {
                // The fault was not reached; take it out of play by reopening.
                self.committed = next;
                self.commits += 1;
                self.snapshots.clear();
                let c = self.container.take().expect("a container is open");
                drop(c);
                let states = [self.committed.clone()];
                self.open_checked(self.disk.current(), &states, None);
            }
            Err(e) => {
                assert!(matches!(e, Error::Io { .. }), "a failed commit said: {e}");
                let c = self.container.take().expect("a container is open");
                assert!(c.is_poisoned(), "an I/O error did not poison the container");
                assert!(matches!(c.read(), Err(Error::Poisoned { .. })));
                assert!(matches!(c.begin_write(), Err(Error::Poisoned { .. })));
                let ops = self.disk.ops();
                drop(c);
                assert_eq!(self.disk.ops(), ops, "a poisoned container wrote");
                self.snapshots.clear();
                self.failures += 1;
                let new = self.last_attempt.clone();
                self.open_checked(self.disk.current(), &[old, new], None);
            }
        }
    }

    /// Opens `image` on a fresh disk (crashing the first attempt if asked), checks it
    /// verifies and holds one of `states`, and makes that the model.
    fn open_checked(&mut self, image: Vec<u8>, states: &[Vec<f32>], recovery: Option<(u8, u64)>) {
        let image = match recovery {
            Some((after, seed)) => {
                let disk = SimDisk::new(image);
                disk.power_off_after(u64::from(after));
                match Container::open_io(disk.clone()) {
                    Ok((c, _)) => {
                        // Recovery finished before the power failed; the process dies now.
                        std::mem::drop(c);
                        disk.crash_image(Damage::Random(seed))
                    }
                    Err(_) => disk.crash_image(Damage::Random(seed)),
                }
            }
            None => image,
        };
        let disk = SimDisk::new(image);
        let (container, _) = Container::open_io(disk.clone()).expect("a crashed file opens");
        let s = container.read().expect("a snapshot");
        let got = samples_of(&s);
        drop(s);
        let which = states
            .iter()
            .find(|st| canonical(st) == got)
            .expect("the file holds neither the old nor the new state");
        self.committed = which.clone();
        self.disk = disk;
        self.container = Some(container);
        self.check_full();
    }
}
