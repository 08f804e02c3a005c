//! A change to several tiles is atomic across the files (`format-spec/dataset.md` §4). A
//! patch across the shared edge of two tiles, and across the corner of four, runs on
//! simulated disks that share one power supply; power goes off after every one of its
//! writes, syncs and length changes in turn, and every file's unsynced operations are then
//! kept, dropped or torn (by several seeds). In every crash image a dataset reader sees every
//! tile old or every tile new (the whole grid is compared with the old and the new terrain),
//! never a mix; `recover` then brings every file back, the dataset verifies, and the next
//! change commits on top of what the reader saw. The I/O-error loop fails each operation of
//! each file in turn: the change reports the error, the files read all old, and the next
//! change (on healthy disks) succeeds.

mod common;

use std::collections::BTreeMap;
use std::path::Path;

use common::fields::{self, Character};
use common::tiles;
use fmrh::dataset::{Dataset, Files};
use fmrh::model::SampleRect;
use fmrh::store::io::{Damage, Fault, OpKind, SimDisk, SimPower};
use fmrh::{Error, Heightfield};

/// A dataset's files on simulated disks sharing one power supply.
struct SimFiles {
    disks: BTreeMap<String, SimDisk>,
    power: SimPower,
}

impl SimFiles {
    /// The files of the dataset directory `dir`, as they are, all durable.
    fn of(dir: &Path) -> SimFiles {
        let power = SimPower::new();
        let disks = std::fs::read_dir(dir)
            .unwrap()
            .map(|e| e.unwrap())
            .map(|e| {
                let name = e.file_name().to_string_lossy().into_owned();
                let bytes = std::fs::read(e.path()).unwrap();
                (
                    name.clone(),
                    SimDisk::on_power(bytes, Path::new(&name), &power),
                )
            })
            .collect();
        SimFiles { disks, power }
    }

    /// Files holding `images`.
    fn from_images(images: &BTreeMap<String, Vec<u8>>) -> SimFiles {
        let power = SimPower::new();
        let disks = images
            .iter()
            .map(|(n, b)| {
                (
                    n.clone(),
                    SimDisk::on_power(b.clone(), Path::new(n), &power),
                )
            })
            .collect();
        SimFiles { disks, power }
    }

    /// What every file holds after a crash with `damage` (each file its own pattern).
    fn crash(&self, damage: Damage) -> BTreeMap<String, Vec<u8>> {
        self.disks
            .iter()
            .enumerate()
            .map(|(i, (n, d))| {
                let damage = match damage {
                    Damage::Random(seed) => {
                        Damage::Random(seed.wrapping_mul(31).wrapping_add(i as u64))
                    }
                    other => other,
                };
                (n.clone(), d.crash_image(damage))
            })
            .collect()
    }

    /// What every file holds now (no crash).
    fn current(&self) -> BTreeMap<String, Vec<u8>> {
        self.disks
            .iter()
            .map(|(n, d)| (n.clone(), d.current()))
            .collect()
    }
}

impl Files for SimFiles {
    type File = SimDisk;

    fn open(&self, name: &str) -> fmrh::Result<SimDisk> {
        self.disks
            .get(name)
            .cloned()
            .ok_or_else(|| Error::InvalidArgument(format!("no file {name}")))
    }
}

/// Writes `images` into a fresh directory, as a dataset a reader can open.
fn materialise(images: &BTreeMap<String, Vec<u8>>) -> tempfile::TempDir {
    let dir = tempfile::tempdir().unwrap();
    for (n, b) in images {
        std::fs::write(dir.path().join(n), b).unwrap();
    }
    dir
}

/// `field` with `patch` written at `(col0, row0)`.
fn patched(field: &Heightfield, patch: &Heightfield, col0: u64, row0: u64) -> Vec<f32> {
    let mut v = field.samples().to_vec();
    let w = field.width() as u64;
    for y in 0..u64::from(patch.height()) {
        for x in 0..u64::from(patch.width()) {
            v[((row0 + y) * w + col0 + x) as usize] =
                patch.samples()[(y * u64::from(patch.width()) + x) as usize];
        }
    }
    v
}

fn same(a: &[f32], b: &[f32]) -> bool {
    common::first_difference(a, b).is_none()
}

struct Case {
    _dir: tempfile::TempDir,
    base: BTreeMap<String, Vec<u8>>,
    old: Vec<f32>,
    new: Vec<f32>,
    patch: Heightfield,
    at: (u64, u64),
    grid: SampleRect,
}

/// A dataset of `field` cut at `cols` x `rows`, and a patch at `at`.
fn case(
    w: u32,
    h: u32,
    cols: &[u64],
    rows: &[u64],
    patch_size: (u32, u32),
    at: (u64, u64),
) -> Case {
    let field = fields::make(w, h, Character::Hills, 0.02, 17);
    let dir = tempfile::tempdir().unwrap();
    let rects = tiles::split(&field, cols, rows, &[]);
    let ds = tiles::build(dir.path(), &field, &rects, &tiles::options(None));
    let patch = fields::make(patch_size.0, patch_size.1, Character::Noise, 0.05, 99);
    let base = SimFiles::of(&ds).current();
    Case {
        _dir: dir,
        base,
        old: field.samples().to_vec(),
        new: patched(&field, &patch, at.0, at.1),
        patch,
        at,
        grid: SampleRect {
            col0: 0,
            row0: 0,
            col1: u64::from(w) - 1,
            row1: u64::from(h) - 1,
        },
    }
}

/// Which terrain the dataset in `dir` shows: `Some(false)` old, `Some(true)` new.
fn shows(c: &Case, dir: &Path) -> Option<bool> {
    let ds = Dataset::open(dir).unwrap_or_else(|e| panic!("the dataset does not open: {e}"));
    let got = ds
        .read_window(c.grid)
        .unwrap_or_else(|e| panic!("the dataset does not read: {e}"));
    if same(got.samples(), &c.old) {
        Some(false)
    } else if same(got.samples(), &c.new) {
        Some(true)
    } else {
        None
    }
}

fn valid(dir: &Path) -> bool {
    let r = tiles::verify(dir, fmrh::store::VerifyMode::Fast);
    if !r.valid {
        eprintln!("{}", serde_json::to_string_pretty(&r).unwrap());
    }
    r.valid
}

fn crash_matrix(c: &Case, tiles_touched: usize) {
    // A run without a crash: how many operations the change takes.
    let files = SimFiles::from_images(&c.base);
    let done = fmrh::dataset::replace(&files, c.at.0, c.at.1, &c.patch).unwrap();
    assert_eq!(done.tiles.len(), tiles_touched);
    let total = files.power.ops();
    let after = materialise(&files.current());
    assert_eq!(shows(c, after.path()), Some(true));
    assert!(valid(after.path()));
    let mut seen = [0u32; 2];
    for k in 0..=total {
        let files = SimFiles::from_images(&c.base);
        files.power.power_off_after(k);
        let r = fmrh::dataset::replace(&files, c.at.0, c.at.1, &c.patch);
        // Power lost before the manifest's record is synced fails the change; after it, only
        // the tiles' clean closes are left, which may fail quietly: the change is durable.
        assert!(r.is_ok() || k < total, "no crash, yet {r:?}");
        for damage in [
            Damage::KeepAll,
            Damage::DropAll,
            Damage::Random(k),
            Damage::Random(k + 1000),
        ] {
            let image = files.crash(damage);
            let dir = materialise(&image);
            let state = shows(c, dir.path()).unwrap_or_else(|| {
                panic!("crash after {k}, {damage:?}: a mix of old and new tiles")
            });
            assert!(
                r.is_err() || state,
                "crash after {k}, {damage:?}: the change returned Ok but is not durable"
            );
            seen[usize::from(state)] += 1;
            // Recover, verify, and change again on top of what the reader saw.
            let rec =
                fmrh::dataset::recover(&fmrh::dataset::Dir(dir.path().to_path_buf())).unwrap();
            assert_eq!(
                shows(c, dir.path()),
                Some(state),
                "recovery changed the state: {rec:?}"
            );
            assert!(
                valid(dir.path()),
                "crash after {k}, {damage:?}: invalid after recovery"
            );
            let again = fmrh::dataset::replace(
                &fmrh::dataset::Dir(dir.path().to_path_buf()),
                c.at.0,
                c.at.1,
                &c.patch,
            )
            .unwrap();
            assert_eq!(again.tiles.len(), tiles_touched);
            assert_eq!(shows(c, dir.path()), Some(true));
            assert!(valid(dir.path()));
        }
    }
    assert!(
        seen[0] > 0 && seen[1] > 0,
        "the matrix saw only one side: {seen:?}"
    );
}

#[test]
fn a_two_tile_change_is_all_old_or_all_new_after_a_crash_anywhere() {
    // Tiles 0..=24 and 24..=48 share column 24; the patch covers it.
    let c = case(49, 25, &[24], &[], (10, 8), (19, 9));
    crash_matrix(&c, 2);
}

#[test]
fn a_four_tile_change_is_all_old_or_all_new_after_a_crash_anywhere() {
    // A 2 x 2 dataset; the patch covers the corner where all four meet.
    let c = case(41, 41, &[20], &[20], (9, 9), (16, 16));
    crash_matrix(&c, 4);
}

#[test]
fn every_failed_operation_leaves_the_dataset_old_and_the_next_change_succeeds() {
    let c = case(41, 41, &[20], &[20], (9, 9), (16, 16));
    let names: Vec<String> = c.base.keys().cloned().collect();
    let counted = SimFiles::from_images(&c.base);
    fmrh::dataset::replace(&counted, c.at.0, c.at.1, &c.patch).unwrap();
    let mut failures = 0;
    for name in &names {
        for kind in [OpKind::Write, OpKind::Sync, OpKind::SetLen] {
            let n = counted.disks[name].count(kind);
            for nth in 1..=n {
                let files = SimFiles::from_images(&c.base);
                files.disks[name].inject(Fault {
                    kind,
                    nth,
                    sticky: false,
                });
                let r = fmrh::dataset::replace(&files, c.at.0, c.at.1, &c.patch);
                // The manifest's last sync is the commit point: a failure before it leaves
                // the dataset old; the manifest record's own write failing is the same.
                let dir = materialise(&files.current());
                // The manifest record's write and the sync after it are the commit point: when
                // they fail, what reached the file decides, and either side is right.
                let commit_point = name == "MANIFEST" && nth == n && kind != OpKind::SetLen;
                match r {
                    Err(_) => {
                        failures += 1;
                        let state = shows(&c, dir.path());
                        assert!(
                            state.is_some(),
                            "{name} {kind:?} #{nth}: a mix of old and new"
                        );
                        if !commit_point {
                            assert_eq!(
                                state,
                                Some(false),
                                "{name} {kind:?} #{nth} failed, yet the dataset moved"
                            );
                        }
                    }
                    // Only the clean closes after the manifest commit may fail quietly.
                    Ok(_) => {
                        assert_eq!(shows(&c, dir.path()), Some(true), "{name} {kind:?} #{nth}")
                    }
                }
                fmrh::dataset::recover(&fmrh::dataset::Dir(dir.path().to_path_buf())).unwrap();
                assert!(valid(dir.path()));
                fmrh::dataset::replace(
                    &fmrh::dataset::Dir(dir.path().to_path_buf()),
                    c.at.0,
                    c.at.1,
                    &c.patch,
                )
                .unwrap();
                assert_eq!(shows(&c, dir.path()), Some(true));
            }
        }
    }
    assert!(
        failures > 10,
        "only {failures} injected failures reached the change"
    );
}

#[test]
fn a_change_that_frees_the_end_of_a_tile_keeps_the_pinned_state_whole() {
    // Two large patches over the same samples, then a small one elsewhere: the first large
    // patch's pages, at the end of the tile files, are freed by the second and reusable
    // after the third, so the next change could cut them off the files. It must not while
    // the manifest pins the third state, whose length includes them. (The small patch lies
    // in the east tile: since format 6.2 writes the coarse grids last, one in the west tile
    // reuses those end pages, and the precondition below catches that.)
    let mut c = case(49, 25, &[24], &[], (20, 20), (14, 2));
    let files = SimFiles::from_images(&c.base);
    let mut terrain = Heightfield::new(49, 25, c.old.clone()).unwrap();
    for (i, (w, at)) in [(20u32, (14u64, 2u64)), (20, (14, 2)), (3, (30, 10))]
        .into_iter()
        .enumerate()
    {
        let p = fields::make(w, w, Character::Noise, 0.0, 40 + i as u64);
        fmrh::dataset::replace(&files, at.0, at.1, &p).unwrap();
        terrain = Heightfield::new(49, 25, patched(&terrain, &p, at.0, at.1)).unwrap();
    }
    c.base = files.current();
    // The precondition: some tile's pinned state ends in free pages a commit may cut.
    let dir = materialise(&c.base);
    let ds = Dataset::open(dir.path()).unwrap();
    let trailing_free = ds.tiles().unwrap().iter().any(|t| {
        let s = ds.open_tile(t).unwrap();
        let last = s.page_count() - 1;
        s.free_pages()
            .unwrap()
            .iter()
            .any(|f| f.page == last && f.freed_txn < s.txn_id())
    });
    assert!(
        trailing_free,
        "no tile ends in reusable free pages: the case does not test the floor"
    );
    c.old = terrain.samples().to_vec();
    c.patch = fields::make(3, 3, Character::Noise, 0.0, 8);
    c.at = (22, 4);
    c.new = patched(&terrain, &c.patch, 22, 4);
    crash_matrix(&c, 2);
}
