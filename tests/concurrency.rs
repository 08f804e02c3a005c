//! Readers during commits: on a real file (Puget Sound east, 512 x 512, through `FileIo`),
//! one writer commits a sequence of replacements while two reader threads keep taking
//! snapshots and running view scenes on them: for each of four cameras, the scene's blocks
//! and every payload they reference, folded into one checksum. Each checksum a reader computes
//! must equal the checksum of the committed state its snapshot reads (computed by the writer
//! right after that commit), and a snapshot held across several commits must give the same
//! checksum twice. So readers never see a half-written state, and pages a snapshot still
//! reaches are never reused under it. Readers never wait for the writer: they take snapshots
//! while a transaction is open.

mod common;

use std::collections::BTreeMap;
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::Mutex;

use common::data;
use common::fields::Rng;
use common::txn::build_bytes;
use fmrh::ingest::{self, IngestOptions};
use fmrh::model::{BuildOptions, Model, Thresholds};
use fmrh::scene::{Camera, Mode, SceneOptions, Terrain};
use fmrh::store::{Container, Source};
use fmrh::{store::Store, Heightfield};

/// Folds every scene block of every camera, and the payload bytes it references, into a
/// checksum of what a renderer would draw.
fn scene_checksum<S: Source>(store: &Store<S>, cameras: &[Camera]) -> u64 {
    let terrain = Terrain::new(store).expect("terrain");
    let options = SceneOptions {
        tau: 1.0,
        mode: Mode::View,
        window: None,
        gap: fmrh::scene::DEFAULT_GAP,
    };
    let mut h = 0xcbf2_9ce4_8422_2325u64;
    let mut fold = |bytes: &[u8]| {
        for b in bytes {
            h = (h ^ u64::from(*b)).wrapping_mul(0x100_0000_01b3);
        }
    };
    for cam in cameras {
        let scene = terrain.scene(cam, &options).expect("scene");
        assert!(!scene.blocks.is_empty(), "a camera sees nothing");
        for b in &scene.blocks {
            fold(&b.key.to_le_bytes());
            fold(&[b.level]);
            fold(&b.error.to_bits().to_le_bytes());
            let p = b.payload;
            fold(&store.payload(p).expect("payload"));
        }
    }
    h
}

#[test]
fn readers_running_scenes_see_only_whole_snapshots() {
    let src = ingest::load(
        &data("puget-sound-east-512/ps-e_lg.f32"),
        &IngestOptions::default(),
    )
    .unwrap();
    let model = Model::build(
        src.clone(),
        &BuildOptions {
            block_size: 65,
            thresholds: Thresholds::Ladder,
            precision: None,
            thin: Default::default(),
        },
    )
    .unwrap();
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("ps.fmrh");
    std::fs::write(&path, build_bytes(&src, 65, &Thresholds::Ladder)).unwrap();
    let container = Container::open(&path).unwrap();
    let cameras: Vec<Camera> = {
        let s = container.read().unwrap();
        let frame = Terrain::new(&*s).unwrap().frame();
        (0..4)
            .map(|i| common::views::random_camera(&model, frame, &mut Rng::new(1000 + i)))
            .collect()
    };

    // txn id -> checksum of that committed state, as the writer saw it after committing.
    let committed: Mutex<BTreeMap<u64, u64>> = Mutex::new(BTreeMap::new());
    {
        let s = container.read().unwrap();
        committed
            .lock()
            .unwrap()
            .insert(s.txn_id(), scene_checksum(&*s, &cameras));
    }
    let done = AtomicBool::new(false);
    let seen: Mutex<Vec<(u64, u64)>> = Mutex::new(Vec::new());
    let held_across = Mutex::new(0u64);
    std::thread::scope(|scope| {
        for reader in 0..2u64 {
            let (container, cameras, done, seen, held_across) =
                (&container, &cameras, &done, &seen, &held_across);
            scope.spawn(move || {
                let mut round = 0u64;
                while !done.load(Ordering::Acquire) || round < 3 {
                    let s = container.read().unwrap();
                    let first = scene_checksum(&*s, cameras);
                    seen.lock().unwrap().push((s.txn_id(), first));
                    // Every few rounds, hold the snapshot while commits go by.
                    if (round + reader).is_multiple_of(4) {
                        std::thread::sleep(std::time::Duration::from_millis(30));
                        let again = scene_checksum(&*s, cameras);
                        assert_eq!(first, again, "a held snapshot changed");
                        if container.read().unwrap().txn_id() != s.txn_id() {
                            *held_across.lock().unwrap() += 1;
                        }
                    }
                    round += 1;
                }
            });
        }
        // Readers stop when the writer is done, or when it panics: a failing commit must fail
        // the test, not leave the readers looping.
        struct DoneOnDrop<'a>(&'a AtomicBool);
        impl Drop for DoneOnDrop<'_> {
            fn drop(&mut self) {
                self.0.store(true, Ordering::Release);
            }
        }
        let _done = DoneOnDrop(&done);
        let mut rng = Rng::new(7);
        for i in 0..24u32 {
            let (col0, row0) = (rng.next_u64() % 440, rng.next_u64() % 440);
            let patch = Heightfield::from_fn(65, 65, |x, y| {
                (f64::from(i * 13 + x * y % 29) + 40.0 * (f64::from(x + i) * 0.2).sin()) as f32
            })
            .unwrap();
            let mut w = container.begin_write().unwrap();
            w.replace_region(col0, row0, &patch).unwrap();
            // Readers take snapshots while this transaction is open, without waiting.
            std::thread::sleep(std::time::Duration::from_millis(5));
            let summary = w.commit().unwrap();
            let s = container.read().unwrap();
            assert_eq!(s.txn_id(), summary.txn_id);
            let sum = scene_checksum(&*s, &cameras);
            committed.lock().unwrap().insert(s.txn_id(), sum);
            drop(s);
            // Give the readers time to see this state.
            std::thread::sleep(std::time::Duration::from_millis(10));
        }
        done.store(true, Ordering::Release);
    });

    let committed = committed.into_inner().unwrap();
    let seen = seen.into_inner().unwrap();
    let states: std::collections::BTreeSet<u64> = seen.iter().map(|s| s.0).collect();
    for (txn, sum) in &seen {
        let expected = committed
            .get(txn)
            .unwrap_or_else(|| panic!("a reader saw txn {txn}, which no commit made"));
        assert_eq!(
            sum, expected,
            "a reader's scenes at txn {txn} differ from that state's"
        );
    }
    // The commits changed what the cameras see, and the readers saw several states.
    let distinct: std::collections::BTreeSet<u64> = committed.values().copied().collect();
    assert!(distinct.len() > 8, "{distinct:?}");
    let held = held_across.into_inner().unwrap();
    eprintln!(
        "{} reader scenes over {} states ({} commits), {held} snapshots held across a commit",
        seen.len(),
        states.len(),
        committed.len() - 1
    );
    assert!(
        states.len() >= 4 && held > 0,
        "too little overlap to show anything"
    );
    container.close().unwrap();
    let bytes = std::fs::read(&path).unwrap();
    let report =
        fmrh::store::verify(fmrh::store::Bytes(bytes), fmrh::store::VerifyMode::Full).unwrap();
    assert!(report.valid, "{report:#?}");
}
