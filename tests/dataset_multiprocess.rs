//! Readers of a dataset in other processes answer from exactly one published dataset state,
//! or say that state was superseded (exit 75), while a writer commits changes across tile
//! borders (`format-spec/dataset.md` §3.4, §4). Never a mix of states, never INVALID, never
//! another failure.
//!
//! The dataset is the bundled Puget Sound 1k DEM cut into 2 x 2 tiles. One writer (this
//! process, through `Terrain::edit`) commits patches that straddle the tile borders (a
//! vertical one, a horizontal one, or the corner where all four tiles meet), so that each
//! commit changes two or four tiles and then the manifest. After each commit, while the
//! directory is still, the writer copies it; a recorder thread reads each copy, with the
//! library for the samples and the command line for the scene and `info`. Reader processes,
//! the `fmrh` command line, loop over `extract`, `scene`, `info` and `verify --full` on the
//! live directory. Every answer that exits 0 must be one the recorder saw; `verify` must say
//! VALID (0) or superseded (75).
//!
//! `FMRH_STRESS_COMMITS` sets the number of commits (100 by default).

mod common;

use std::collections::{BTreeMap, HashSet};
use std::hash::{DefaultHasher, Hasher};
use std::path::{Path, PathBuf};
use std::process::Command;
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::{Arc, Mutex};

use common::fields::Rng;
use common::{data, tiles};
use fmrh::dataset::DatasetOptions;
use fmrh::ingest::{load, IngestOptions};
use fmrh::model::BuildOptions;
use fmrh::store::WriteOptions;
use fmrh::{Heightfield, Terrain};

fn fmrh_bin() -> &'static str {
    env!("CARGO_BIN_EXE_fmrh")
}

fn hash(bytes: &[u8]) -> u64 {
    let mut h = DefaultHasher::new();
    h.write(bytes);
    h.finish()
}

/// A hash of a command's JSON without what differs between two readers of the same state:
/// timings (`*_ns`), read reports (`reads`, `open_reads`, `open_bytes`: how often the slots
/// were read), paths (the recorder reads a copy in another directory), and the sizes of the
/// tile files on disk now (`file_bytes`, `total_bytes`: a commit in progress appends pages
/// that belong to no published state yet; `info` reports the disk, not the state).
fn json_hash(stdout: &[u8]) -> u64 {
    match serde_json::from_slice::<serde_json::Value>(stdout) {
        Ok(mut v) => {
            common::without_keys(
                &mut v,
                &[
                    "reads",
                    "open_reads",
                    "open_bytes",
                    "path",
                    "file",
                    "file_bytes",
                    "total_bytes",
                ],
            );
            hash(v.to_string().as_bytes())
        }
        Err(_) => hash(stdout),
    }
}

fn samples_hash(samples: &[f32]) -> u64 {
    let bytes: Vec<u8> = samples.iter().flat_map(|v| v.to_le_bytes()).collect();
    hash(&bytes)
}

/// The tiles are 10 m apart (`tiles::build`): a camera south of the data, looking north.
const SCENE: [&str; 8] = [
    "--eye",
    "5000,13000,6000",
    "--target",
    "5000,4000,0",
    "--tau",
    "2",
    "--json",
    "--viewport=800x600",
];

/// What a reader process got: the command, its exit code, a hash of its output, its stderr.
#[derive(Debug)]
struct Read {
    kind: &'static str,
    code: Option<i32>,
    output: u64,
    /// Its stderr, and its stdout when it failed: shown by failure messages (through
    /// `Debug`).
    #[allow(dead_code)]
    said: String,
}

fn command(kind: &str, dir: &Path, scratch: &Path) -> Command {
    let mut c = Command::new(fmrh_bin());
    match kind {
        "extract" => {
            c.arg("extract")
                .arg(dir)
                .arg("--force")
                .arg("-o")
                .arg(scratch.join("out.f32"));
        }
        "scene" => {
            c.arg("scene").arg(dir).args(SCENE);
        }
        "info" => {
            c.args(["info", "--json"]).arg(dir);
        }
        "verify" => {
            c.args(["verify", "--full"]).arg(dir);
        }
        _ => unreachable!(),
    }
    c
}

/// One reader process of `kind`, run to completion.
fn read_once(kind: &'static str, dir: &Path, scratch: &Path) -> Read {
    let out = command(kind, dir, scratch).output().expect("run fmrh");
    let output = match kind {
        "extract" if out.status.success() => {
            hash(&std::fs::read(scratch.join("out.f32")).expect("extract output"))
        }
        "scene" | "info" => json_hash(&out.stdout),
        _ => hash(&out.stdout),
    };
    Read {
        kind,
        code: out.status.code(),
        output,
        said: if out.status.success() {
            String::from_utf8_lossy(&out.stderr).into_owned()
        } else {
            format!(
                "{}{}",
                String::from_utf8_lossy(&out.stderr),
                String::from_utf8_lossy(&out.stdout)
            )
        },
    }
}

fn commits() -> usize {
    std::env::var("FMRH_STRESS_COMMITS")
        .ok()
        .and_then(|v| v.parse().ok())
        .unwrap_or(100)
}

fn copy_dir(from: &Path, to: &Path) {
    std::fs::create_dir_all(to).unwrap();
    for e in std::fs::read_dir(from).unwrap() {
        let e = e.unwrap();
        std::fs::copy(e.path(), to.join(e.file_name())).unwrap();
    }
}

/// What each published state answers: samples (extract), scenes, info.
#[derive(Default)]
struct Known {
    samples: HashSet<u64>,
    scenes: HashSet<u64>,
    infos: HashSet<u64>,
}

#[test]
fn dataset_readers_in_other_processes_see_only_published_states() {
    let work = tempfile::tempdir().unwrap();
    let field = load(
        &data("puget-sound-1k/ps_height_1k.png"),
        &IngestOptions::default(),
    )
    .unwrap();
    let (w, h) = (u64::from(field.width()), u64::from(field.height()));
    let (cut_x, cut_y) = (w / 2, h / 2);
    let rects = tiles::split(&field, &[cut_x], &[cut_y], &[]);
    assert_eq!(rects.len(), 4);
    let options = DatasetOptions {
        build: BuildOptions::default(),
        write: WriteOptions::default(),
        ..tiles::options(None)
    };
    let dir = tiles::build(work.path(), &field, &rects, &options);

    let known = Arc::new(Mutex::new(Known::default()));
    let (copies, copied) = std::sync::mpsc::channel::<PathBuf>();
    let recorder = {
        let known = Arc::clone(&known);
        std::thread::spawn(move || {
            let scratch = tempfile::tempdir().unwrap();
            for copy in copied {
                let all = Terrain::open(&copy).unwrap().read(None).unwrap();
                let mut answers = Vec::new();
                for kind in ["scene", "info"] {
                    let out = command(kind, &copy, scratch.path()).output().unwrap();
                    assert!(
                        out.status.success(),
                        "{kind} on a still copy: {}",
                        String::from_utf8_lossy(&out.stderr)
                    );
                    answers.push(json_hash(&out.stdout));
                }
                let mut k = known.lock().unwrap();
                k.samples.insert(samples_hash(all.samples()));
                k.scenes.insert(answers[0]);
                k.infos.insert(answers[1]);
                drop(k);
                std::fs::remove_dir_all(&copy).unwrap();
            }
        })
    };
    let states = tempfile::tempdir().unwrap();
    let keep = |i: usize| {
        let copy = states.path().join(format!("state-{i}"));
        copy_dir(&dir, &copy);
        copies.send(copy).unwrap();
    };
    keep(0);

    let done = Arc::new(AtomicBool::new(false));
    let reads = Arc::new(Mutex::new(Vec::new()));
    let readers: Vec<_> = ["extract", "scene", "info", "verify"]
        .into_iter()
        .map(|kind| {
            let (done, reads, dir) = (Arc::clone(&done), Arc::clone(&reads), dir.clone());
            let scratch = tempfile::tempdir().unwrap();
            std::thread::spawn(move || {
                let mut n = 0;
                while !done.load(Ordering::Acquire) || n < 3 {
                    let r = read_once(kind, &dir, scratch.path());
                    reads.lock().unwrap().push(r);
                    n += 1;
                }
            })
        })
        .collect();

    let mut rng = Rng::new(39);
    let n = commits();
    for i in 0..n {
        let pw = 2 + rng.next_u64() % 40;
        let ph = 2 + rng.next_u64() % 40;
        // Cover the shared column, the shared row, or both (the corner where four tiles meet).
        let (across_x, across_y) = match rng.next_u64() % 3 {
            0 => (true, false),
            1 => (false, true),
            _ => (true, true),
        };
        let col0 = if across_x {
            cut_x - rng.next_u64() % pw
        } else {
            rng.next_u64() % (w - pw)
        };
        let row0 = if across_y {
            cut_y - rng.next_u64() % ph
        } else {
            rng.next_u64() % (h - ph)
        };
        let base = 100.0 + i as f32;
        let patch =
            Heightfield::from_fn(pw as u32, ph as u32, |x, y| base + (x * 7 + y * 3) as f32)
                .unwrap();
        let terrain = Terrain::open(&dir).unwrap();
        let mut edit = terrain.edit().unwrap();
        edit.replace(col0, row0, patch).unwrap();
        edit.commit().unwrap();
        keep(i + 1);
    }
    done.store(true, Ordering::Release);
    for r in readers {
        r.join().unwrap();
    }
    drop(copies);
    recorder.join().unwrap();
    let known = std::mem::take(&mut *known.lock().unwrap());
    assert_eq!(
        known.samples.len(),
        n + 1,
        "every commit changed the samples"
    );

    let reads = std::mem::take(&mut *reads.lock().unwrap());
    // kind -> (runs, distinct states seen, superseded)
    let mut per_kind: BTreeMap<&str, (usize, HashSet<u64>, usize)> = BTreeMap::new();
    for r in &reads {
        let e = per_kind.entry(r.kind).or_default();
        e.0 += 1;
        match (r.kind, r.code) {
            (_, Some(75)) => e.2 += 1,
            ("verify", Some(0)) => {}
            ("verify", _) => panic!("verify called the dataset invalid or failed: {r:?}"),
            (_, Some(0)) => {
                let set = match r.kind {
                    "extract" => &known.samples,
                    "scene" => &known.scenes,
                    _ => &known.infos,
                };
                assert!(
                    set.contains(&r.output),
                    "{} answered what no published state holds: {r:?}",
                    r.kind
                );
                e.1.insert(r.output);
            }
            _ => panic!("a reader failed: {r:?}"),
        }
    }
    eprintln!("{n} commits; runs per kind (count, distinct states seen, superseded):");
    for (kind, (count, seen, superseded)) in &per_kind {
        eprintln!("  {kind:<8} {count:>5} {:>5} {superseded:>5}", seen.len());
    }
    for kind in ["extract", "scene", "info", "verify"] {
        assert!(
            per_kind.get(kind).is_some_and(|e| e.0 >= 3),
            "{kind} barely ran"
        );
    }
    // The readers really ran during the commits: they saw several states.
    assert!(
        per_kind["extract"].1.len() >= 2,
        "extract saw one state only"
    );
}

/// What a tile's commit in progress leaves around its pinned state (pages appended past its
/// length, while its writer holds it) makes `verify DIR` say BUSY (75), never INVALID: found
/// by the test above, once in a few runs, when a verify met a tile mid-commit before the
/// manifest moved.
#[test]
fn a_tile_mid_commit_makes_the_dataset_verify_busy_not_invalid() {
    use std::io::Write;
    let work = tempfile::tempdir().unwrap();
    let field = Heightfield::from_fn(65, 33, |x, y| ((x * 7 + y * 3) % 41) as f32).unwrap();
    let rects = tiles::split(&field, &[32], &[], &[]);
    let dir = tiles::build(work.path(), &field, &rects, &tiles::options(None));
    let tile = dir.join("t1.fmrh");
    assert!(tile.exists());
    let verify = || {
        Command::new(fmrh_bin())
            .args(["verify", "--full"])
            .arg(&dir)
            .output()
            .unwrap()
    };
    assert_eq!(verify().status.code(), Some(0));
    let writer = fmrh::store::Container::open(&tile).unwrap();
    // The next commit's pages, written but not yet published.
    std::fs::OpenOptions::new()
        .append(true)
        .open(&tile)
        .unwrap()
        .write_all(&[0xA5; 8192])
        .unwrap();
    let out = verify();
    let text = String::from_utf8_lossy(&out.stdout);
    assert_eq!(out.status.code(), Some(75), "{text}");
    assert!(text.contains("BUSY") && !text.contains("INVALID"), "{text}");
    // With no writer, the same bytes are a crashed writer's leftovers: I-3, INVALID, until
    // `fmrh recover` cuts them.
    writer.close().unwrap();
    let out = verify();
    let text = String::from_utf8_lossy(&out.stdout);
    assert_eq!(out.status.code(), Some(1), "{text}");
    assert!(text.contains("I-3"), "{text}");
    let r = common::fmrh(&["recover", dir.to_str().unwrap()]);
    assert!(r.status.success(), "{}", String::from_utf8_lossy(&r.stderr));
    assert_eq!(verify().status.code(), Some(0));
}

/// Regression (found as a rare failure of the stress test above): a reader opens the
/// MANIFEST and takes its length, a writer then commits a state that grows the file, and
/// only then does the reader choose a slot. The newest slot names a length past the one the
/// reader saw; that is a newer state, not damage (D-1), so the reader must look at the
/// length again before it calls the manifest corrupt.
#[test]
fn a_manifest_that_grew_after_the_reader_took_its_length_is_read_not_called_corrupt() {
    use fmrh::dataset::manifest::{ManifestState, MANIFEST_NAME};
    use fmrh::store::{FileSource, Source};
    let work = tempfile::tempdir().unwrap();
    let field = Heightfield::from_fn(65, 33, |x, y| ((x * 7 + y * 3) % 41) as f32).unwrap();
    let rects = tiles::split(&field, &[32], &[], &[]);
    let dir = tiles::build(work.path(), &field, &rects, &tiles::options(None));
    let manifest = dir.join(MANIFEST_NAME);
    let stale = FileSource::open(&manifest).unwrap();
    let before = stale.len();
    let mut grown = 0;
    for i in 0..8u32 {
        let terrain = Terrain::open(&dir).unwrap();
        let mut edit = terrain.edit().unwrap();
        let patch = Heightfield::from_fn(6, 4, |x, y| 500.0 + (i * 13 + x + y) as f32).unwrap();
        edit.replace(29, 10, patch).unwrap();
        edit.commit().unwrap();
        grown = std::fs::metadata(&manifest).unwrap().len();
        if grown > before {
            break;
        }
    }
    assert!(
        grown > before,
        "no commit grew the manifest ({before} bytes)"
    );
    assert_eq!(stale.len(), before, "the source still holds the old length");
    let state = ManifestState::read(&stale).expect("a newer state, not a corrupt manifest");
    let fresh = ManifestState::read(&FileSource::open(&manifest).unwrap()).unwrap();
    assert_eq!(state.record.txn_id.get(), fresh.record.txn_id.get());
    assert_eq!(state.record.file_length.get(), grown);
}
