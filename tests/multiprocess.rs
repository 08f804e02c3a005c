//! Readers in other processes never see a state that was never committed, and never fail,
//! while a writer commits (format §11.6).
//!
//! One writer (this process, through `Container`) commits random replacements to a container
//! built from a real DEM, while reader processes, the `fmrh` command line, loop over
//! `extract` (positioned reads), `scene` (positioned reads and `--mmap`) and `verify --full`.
//! After each commit, while the file is still, the writer records what every committed state
//! reads as: the hash of its samples, and the output of `fmrh scene`. Every concurrent read
//! must be exactly one of those, every command must succeed, and `verify` must never call the
//! file invalid (it may say a writer is committing, exit 75, which is counted).
//!
//! `FMRH_STRESS_COMMITS` sets the number of commits (100 by default; the longer run of
//! issue 13 is `FMRH_STRESS_COMMITS=1000 cargo test --release --test multiprocess`).
//!
//! The second test kills a registered reader (an `fmrh scene` process) with SIGKILL: the
//! writer goes on, keeps the reader's pages while it lives, and reclaims them once it is gone.

mod common;

use std::collections::{BTreeMap, HashSet};
use std::hash::{DefaultHasher, Hasher};
use std::io::{Read as _, Write as _};
use std::path::{Path, PathBuf};
use std::process::{Command, Stdio};
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::{Arc, Mutex};

use common::data;
use common::fields::Rng;
use fmrh::ingest::{load, IngestOptions};
use fmrh::{store::Container, CreateOptions, Heightfield};

fn fmrh_bin() -> &'static str {
    env!("CARGO_BIN_EXE_fmrh")
}

fn hash(bytes: &[u8]) -> u64 {
    let mut h = DefaultHasher::new();
    h.write(bytes);
    h.finish()
}

/// A hash of a scene's JSON without its timings (`*_ns`), which differ run to run, and
/// without its read report (`reads`): a reader that opened while a commit was published
/// chose its state again, and read the slots more times, but the scene it answers is a
/// committed state's, which is what this test checks.
fn scene_hash(stdout: &[u8]) -> u64 {
    match serde_json::from_slice::<serde_json::Value>(stdout) {
        Ok(mut v) => {
            common::without_keys(&mut v, &["reads"]);
            hash(v.to_string().as_bytes())
        }
        Err(_) => hash(stdout),
    }
}

fn samples_hash(samples: &[f32]) -> u64 {
    let bytes: Vec<u8> = samples.iter().flat_map(|v| v.to_le_bytes()).collect();
    hash(&bytes)
}

/// The files here have no spacing: the camera is placed in samples (`--spacing 1`).
const SCENE: [&str; 9] = [
    "--spacing=1",
    "--eye",
    "500,1300,600",
    "--target",
    "500,400,0",
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
    /// Shown by failure messages (through `Debug`).
    #[allow(dead_code)]
    stderr: String,
}

fn scene_cmd(file: &Path, mmap: bool) -> Command {
    let mut c = Command::new(fmrh_bin());
    c.arg("scene").arg(file).args(SCENE);
    if mmap {
        c.arg("--mmap");
    }
    c
}

/// One reader process of `kind`, run to completion.
fn read_once(kind: &'static str, file: &Path, scratch: &Path) -> Read {
    let mut cmd = match kind {
        "extract" => {
            let mut c = Command::new(fmrh_bin());
            c.arg("extract")
                .arg(file)
                .arg("--force")
                .arg("-o")
                .arg(scratch.join("out.f32"));
            c
        }
        "scene" => scene_cmd(file, false),
        "scene-mmap" => scene_cmd(file, true),
        "verify" => {
            let mut c = Command::new(fmrh_bin());
            c.args(["verify", "--full"]).arg(file);
            c
        }
        _ => unreachable!(),
    };
    let out = cmd.output().expect("run fmrh");
    let output = match kind {
        "extract" if out.status.success() => {
            hash(&std::fs::read(scratch.join("out.f32")).expect("extract output"))
        }
        "scene" | "scene-mmap" => scene_hash(&out.stdout),
        _ => hash(&out.stdout),
    };
    Read {
        kind,
        code: out.status.code(),
        output,
        stderr: String::from_utf8_lossy(&out.stderr).into_owned(),
    }
}

fn commits() -> usize {
    std::env::var("FMRH_STRESS_COMMITS")
        .ok()
        .and_then(|v| v.parse().ok())
        .unwrap_or(100)
}

#[test]
fn readers_in_other_processes_see_only_committed_states() {
    let dir = tempfile::tempdir().unwrap();
    let file = dir.path().join("ps1k.fmrh");
    let hf = load(
        &data("puget-sound-1k/ps_height_1k.png"),
        &IngestOptions::default(),
    )
    .unwrap();
    let (w, h) = (hf.width(), hf.height());
    fmrh::create(&file, hf, &CreateOptions::default()).unwrap();
    let container = Container::open(&file).unwrap();

    // What each committed state reads as. While the file is still (between commits) the
    // writer copies it; a second thread reads each copy, with the library for the samples and
    // the command line for the scene, and deletes it. Commits then follow each other as fast
    // as they can, which is what makes the readers race them.
    let refs = Arc::new(Mutex::new((HashSet::new(), HashSet::new())));
    let (copies, copied) = std::sync::mpsc::channel::<PathBuf>();
    let recorder = {
        let refs = Arc::clone(&refs);
        std::thread::spawn(move || {
            for copy in copied {
                let store = fmrh::store::Store::open(&copy).unwrap();
                let all = store.read_window(store.domain().data_rect()).unwrap();
                let out = scene_cmd(&copy, false).output().unwrap();
                assert!(
                    out.status.success(),
                    "{}",
                    String::from_utf8_lossy(&out.stderr)
                );
                let mut r = refs.lock().unwrap();
                r.0.insert(samples_hash(all.samples()));
                r.1.insert(scene_hash(&out.stdout));
                drop((r, store));
                std::fs::remove_file(&copy).unwrap();
            }
        })
    };
    let states = tempfile::tempdir().unwrap();
    let keep = |i: usize| {
        let copy = states.path().join(format!("state-{i}.fmrh"));
        std::fs::copy(&file, &copy).unwrap();
        copies.send(copy).unwrap();
    };
    keep(0);

    let done = Arc::new(AtomicBool::new(false));
    let reads = Arc::new(Mutex::new(Vec::new()));
    let readers: Vec<_> = ["extract", "scene", "scene-mmap", "verify"]
        .into_iter()
        .map(|kind| {
            let (done, reads, file) = (Arc::clone(&done), Arc::clone(&reads), file.clone());
            let scratch = tempfile::tempdir().unwrap();
            std::thread::spawn(move || {
                // Each loop runs at least a few reads, and goes on while the writer commits.
                let mut n = 0;
                while !done.load(Ordering::Acquire) || n < 3 {
                    let r = read_once(kind, &file, scratch.path());
                    reads.lock().unwrap().push(r);
                    n += 1;
                }
            })
        })
        .collect();

    let mut rng = Rng::new(13);
    let n = commits();
    for i in 0..n {
        let pw = 1 + (rng.next_u64() % 32) as u32;
        let ph = 1 + (rng.next_u64() % 32) as u32;
        let col0 = rng.next_u64() % u64::from(w - pw);
        let row0 = rng.next_u64() % u64::from(h - ph);
        let base = 100.0 + i as f32;
        let patch = Heightfield::from_fn(pw, ph, |x, y| base + (x * 7 + y * 3) as f32).unwrap();
        let mut txn = container.begin_write().unwrap();
        txn.replace_region(col0, row0, &patch).unwrap();
        txn.commit().unwrap();
        keep(i + 1);
    }
    done.store(true, Ordering::Release);
    for r in readers {
        r.join().unwrap();
    }
    container.close().unwrap();
    drop(copies);
    recorder.join().unwrap();
    let (extracts, scenes) = std::mem::take(&mut *refs.lock().unwrap());

    let reads = std::mem::take(&mut *reads.lock().unwrap());
    let mut per_kind: BTreeMap<&str, (usize, HashSet<u64>, usize)> = BTreeMap::new();
    for r in &reads {
        let e = per_kind.entry(r.kind).or_default();
        e.0 += 1;
        match (r.kind, r.code) {
            ("verify", Some(0)) => {}
            ("verify", Some(75)) => e.2 += 1,
            ("verify", _) => panic!("verify called the file invalid or failed: {r:?}"),
            (_, Some(0)) => {
                let known = if r.kind == "extract" {
                    &extracts
                } else {
                    &scenes
                };
                assert!(
                    known.contains(&r.output),
                    "{} read something no committed state holds: {r:?}",
                    r.kind
                );
                e.1.insert(r.output);
            }
            _ => panic!("a reader failed: {r:?}"),
        }
    }
    eprintln!("{n} commits; reads per kind (count, distinct states seen, verify busy):");
    for (kind, (count, states, busy)) in &per_kind {
        eprintln!("  {kind:<11} {count:>5} {:>5} {busy:>5}", states.len());
    }
    for kind in ["extract", "scene", "scene-mmap", "verify"] {
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

#[test]
fn a_killed_reader_is_reclaimed() {
    let dir = tempfile::tempdir().unwrap();
    let file = dir.path().join("t.fmrh");
    let hf = Heightfield::from_fn(1025, 1025, |x, y| ((x * 3 + y * 5) % 97) as f32).unwrap();
    fmrh::create(&file, hf, &CreateOptions::default()).unwrap();
    let container = Container::open(&file).unwrap();
    let commit = |v: f32| {
        let mut txn = container.begin_write().unwrap();
        let patch = Heightfield::from_fn(9, 9, |_, _| v).unwrap();
        txn.replace_region(100, 100, &patch).unwrap();
        txn.commit().unwrap()
    };
    let held = commit(1.0).txn_id;

    // The reader: `fmrh scene` with a pipe nobody empties. Its JSON (about 180 KB) fills the
    // pipe, so it blocks while printing, its store (and its registration) alive.
    let mut child = Command::new(fmrh_bin())
        .arg("scene")
        .arg(&file)
        .args([
            "--spacing=1",
            "--eye",
            "512,1500,300",
            "--target",
            "512,500,0",
            "--tau",
            "0.5",
            "--json",
        ])
        .stdout(Stdio::piped())
        .stderr(Stdio::null())
        .spawn()
        .unwrap();
    let mut first = [0u8; 1];
    child
        .stdout
        .as_mut()
        .unwrap()
        .read_exact(&mut first)
        .unwrap();

    // While the reader lives, no commit may reuse what its state reaches.
    for v in 2..6 {
        let s = commit(v as f32);
        assert_eq!(
            s.reuse_limit, held,
            "commit {} ignored the reader",
            s.txn_id
        );
    }
    assert!(
        child.try_wait().unwrap().is_none(),
        "the reader finished early: its output fit the pipe, so this test proved nothing"
    );

    // kill -9: the kernel drops its lock with its file; the next commit reclaims the state.
    child.kill().unwrap();
    child.wait().unwrap();
    let s = commit(9.0);
    assert_eq!(
        s.reuse_limit,
        s.txn_id - 1,
        "the dead reader still pins txn {held}"
    );
    let s = commit(10.0);
    assert!(s.pages_reused > 0, "freed pages are reused again");
    container.close().unwrap();
}

/// `verify` while a writer holds the file: what a commit in progress leaves around the state
/// (here, pages appended past the committed length) is "busy", never "invalid"; the same bytes
/// with no writer are reported under I-3, as a crashed writer's leftovers.
#[test]
fn verify_while_a_writer_commits_is_busy_never_invalid() {
    let dir = tempfile::tempdir().unwrap();
    let file = dir.path().join("t.fmrh");
    let hf = Heightfield::from_fn(200, 150, |x, y| (x + y) as f32).unwrap();
    fmrh::create(&file, hf, &CreateOptions::default()).unwrap();
    let append = |bytes: usize| {
        let mut f = std::fs::OpenOptions::new()
            .append(true)
            .open(&file)
            .unwrap();
        f.write_all(&vec![0xA5; bytes]).unwrap();
    };
    let verify = || {
        Command::new(fmrh_bin())
            .args(["verify", "--full"])
            .arg(&file)
            .output()
            .unwrap()
    };
    let container = Container::open(&file).unwrap();
    let mut txn = container.begin_write().unwrap();
    txn.replace_region(5, 5, &Heightfield::from_fn(3, 3, |_, _| 9.0).unwrap())
        .unwrap();
    txn.commit().unwrap();
    // The next commit's pages, written but not yet published.
    append(8192);
    let out = verify();
    let text = String::from_utf8_lossy(&out.stdout);
    assert_eq!(out.status.code(), Some(75), "{text}");
    assert!(text.contains("BUSY") && !text.contains("INVALID"), "{text}");
    assert!(!text.contains("interrupted"), "{text}");
    let report = fmrh::store::verify(
        fmrh::store::FileSource::open(&file).unwrap(),
        fmrh::store::VerifyMode::Fast,
    )
    .unwrap();
    assert!(report.busy && !report.valid);
    // The clean close cuts the excess: valid again.
    container.close().unwrap();
    assert_eq!(verify().status.code(), Some(0));
    // With no writer, the same excess is a crashed writer's leftover: I-3.
    append(8192);
    let out = verify();
    let text = String::from_utf8_lossy(&out.stdout);
    assert_eq!(out.status.code(), Some(1), "{text}");
    assert!(
        text.contains("INVALID") && text.contains("interrupted"),
        "{text}"
    );
}
