//! A container read over HTTP range requests gives exactly what the local file gives (the
//! same samples, the same scene, a valid full verification) in few rounds: opening is one
//! round (one multi-range request, or two ranges a request on a server that answers only
//! one), a cold scene at most two more (the pages it refines into with its blocks' records, then
//! its payloads), and reading ahead costs a round per tree level.
//! And the network's faults get a correct retry or a clear error, never wrong data and
//! never a corruption report: delays past the timeout, `500`s, resets and bodies cut short
//! are retried; a server that ignores `Range` is refused without its body being read; an
//! object replaced on the server after the reader opened it is reported as changed
//! underneath. A property test throws random fault sequences at a reader: fewer faults
//! than tries always end in the right bytes.
//!
//! The origin is a small server in the tests (`common/origin.rs`, std threads), so the
//! default suite needs nothing installed; `tests/remote_servers.rs` reads from nginx and an
//! S3 server.

#![cfg(feature = "remote")]

mod common;

use std::sync::OnceLock;
use std::time::Duration;

use common::origin::{Fault, Origin};
use fmrh::model::{BuildOptions, Model};
use fmrh::scene::{load_blocks, Camera, SceneOptions, Terrain};
use fmrh::store::remote::{HttpSource, RemoteOptions};
use fmrh::store::{Store, VerifyMode, WriteOptions};
use proptest::prelude::*;

/// Puget Sound 1k (bundled), as a container in memory, with its metadata bundled (`0`) or
/// in pages of their own (`1`).
fn container(paged: bool) -> Vec<u8> {
    static C: OnceLock<[Vec<u8>; 2]> = OnceLock::new();
    C.get_or_init(|| {
        let hf = common::views::puget_1k();
        let model = Model::build(hf.clone(), &BuildOptions::default()).unwrap();
        let write = |bundle_limit| {
            let mut out = std::io::Cursor::new(Vec::new());
            let options = WriteOptions {
                bundle_limit,
                ..WriteOptions::default()
            };
            fmrh::store::write_to(&model, &hf.metadata, &options, &mut out).unwrap();
            out.into_inner()
        };
        [write(WriteOptions::default().bundle_limit), write(0)]
    })[usize::from(paged)]
    .clone()
}

fn camera() -> Camera {
    Camera::looking_at(
        glam::DVec3::new(20000.0, 180000.0, 6000.0),
        glam::DVec3::new(80000.0, 80000.0, 500.0),
    )
}

/// Options that keep the fault tests fast: short backoff and timeout.
fn quick() -> RemoteOptions {
    RemoteOptions {
        backoff: Duration::from_millis(1),
        timeout: Duration::from_millis(500),
        ..RemoteOptions::default()
    }
}

#[test]
fn a_remote_container_reads_exactly_as_the_local_one() {
    for paged in [false, true] {
        let bytes = container(paged);
        let local = Store::from_bytes(bytes.clone()).unwrap();
        let origin = Origin::start();
        let url = origin.put("/ps1k.fmrh", bytes, "v1");
        let remote = Store::open_url(&url).unwrap();
        // The prefix and the suffix in one multi-range request: a paged file (6.2) keeps its
        // dataset header, directory, top of the tree and tables' roots in the suffix.
        assert_eq!(origin.requests(), 1, "paged {paged}");
        let all = local.domain().data_rect();
        let (a, b) = (
            local.read_window(all).unwrap(),
            remote.read_window(all).unwrap(),
        );
        assert!(common::first_difference(a.samples(), b.samples()).is_none());
        let options = SceneOptions::new(1.0);
        let sl = Terrain::new(&local).unwrap().scene(&camera(), &options);
        let sr = Terrain::new(&remote).unwrap().scene(&camera(), &options);
        assert_eq!(sl.unwrap().blocks, sr.unwrap().blocks);
        let report =
            fmrh::store::verify(HttpSource::open(&url).unwrap(), VerifyMode::Full).unwrap();
        assert!(report.valid, "{:?}", report.checks);
    }
}

#[test]
fn open_is_one_round_and_a_cold_scene_at_most_two_more() {
    for paged in [false, true] {
        let origin = Origin::start();
        let url = origin.put("/ps1k.fmrh", container(paged), "v1");
        let store = Store::open_url(&url).unwrap();
        let opened = store.source().request_stats();
        // Bundled or paged (6.2: what opening reads lies in the suffix), one round.
        assert_eq!(opened.rounds, 1, "paged {paged}: {opened:?}");
        for tau in [1.0, 4.0] {
            let store = Store::open_url(&url).unwrap();
            let before = store.source().request_stats();
            let terrain = Terrain::new(&store).unwrap();
            let scene = terrain.scene(&camera(), &SceneOptions::new(tau)).unwrap();
            let loaded = load_blocks(&store, &scene.blocks, 0).unwrap();
            assert_eq!(loaded.len(), scene.blocks.len());
            let plan = store.source().request_stats().since(&before);
            // The table pages the scene refines into with its blocks' records (none when
            // bundled: the bundle came with the suffix), then the payloads (issue 44).
            assert!(
                plan.rounds <= 2,
                "paged {paged}, tau {tau}: a cold scene in {plan:?}"
            );
            // Warm: the same scene again reads no metadata, only payloads.
            let again = store.source().request_stats();
            let scene2 = terrain.scene(&camera(), &SceneOptions::new(tau)).unwrap();
            assert_eq!(scene2.blocks, scene.blocks);
            assert_eq!(store.source().request_stats(), again, "selection is warm");
        }
    }
}

#[test]
fn a_scene_loads_in_multi_range_requests_or_one_range_a_request_with_the_same_bytes() {
    let bytes = container(true);
    let local = Store::from_bytes(bytes.clone()).unwrap();
    let scene = Terrain::new(&local)
        .unwrap()
        .scene(&camera(), &SceneOptions::new(1.0))
        .unwrap();
    let want = load_blocks(&local, &scene.blocks, 0).unwrap();
    for first_only in [false, true] {
        let origin = Origin::start();
        let url = origin.put("/t.fmrh", bytes.clone(), "v1");
        origin.state.lock().unwrap().first_range_only = first_only;
        let store = Store::open_url(&url).unwrap();
        // Opening: both ends in one request; or, the first range only, the suffix in a
        // round of its own. The suffix holds every page opening reads (6.2).
        let opened = store.source().request_stats();
        let (requests, rounds) = if first_only { (2, 2) } else { (1, 1) };
        assert_eq!(
            (opened.requests, opened.rounds),
            (requests, rounds),
            "{opened:?}"
        );
        assert_eq!(store.source().multi_range(), !first_only);
        let got = load_blocks(&store, &scene.blocks, 0).unwrap();
        assert_eq!(got.len(), want.len());
        for (g, w) in got.iter().zip(&want) {
            assert_eq!(g.stored, w.stored, "first range only: {first_only}");
            assert_eq!(g.heights, w.heights);
        }
        let multi = origin
            .state
            .lock()
            .unwrap()
            .log
            .iter()
            .filter(|(_, r)| r.as_deref().is_some_and(|r| r.contains(',')))
            .count();
        // A server that answers one range only is asked once that way, then one range a
        // request.
        assert!(multi >= 1, "multi-range tried");
        if first_only {
            assert_eq!(multi, 1, "and given up after the first answer");
        }
    }
}

#[test]
fn a_large_metadata_area_comes_in_chunks_held_within_a_bound() {
    let bytes = container(true);
    let local = Store::from_bytes(bytes.clone()).unwrap();
    let want = local.read_window(local.domain().data_rect()).unwrap();
    let origin = Origin::start();
    let url = origin.put("/t.fmrh", bytes, "v1");
    let options = RemoteOptions {
        metadata_limit: 0,
        metadata_chunk: 16 << 10,
        held_limit: 48 << 10,
        ..RemoteOptions::default()
    };
    let store = Store::from_source(HttpSource::open_with(&url, options).unwrap()).unwrap();
    for _ in 0..2 {
        let got = store.read_window(store.domain().data_rect()).unwrap();
        assert!(common::first_difference(got.samples(), want.samples()).is_none());
        let held = store.source().held_bytes();
        assert!(held <= (48 << 10) + (16 << 10), "{held} bytes held");
    }
}

/// Read page by page (no whole metadata area, no chunks), a cold scene and load cost a
/// round per tree level when the reader names its lookups ahead, against a round per page
/// reached without; both give the local answer.
#[test]
fn reading_ahead_costs_a_round_per_tree_level_not_per_page() {
    let bytes = container(true);
    let local = Store::from_bytes(bytes.clone()).unwrap();
    let options = SceneOptions::new(1.0);
    let want = Terrain::new(&local)
        .unwrap()
        .scene(&camera(), &options)
        .unwrap();
    let heights: Vec<_> = load_blocks(&local, &want.blocks, 0)
        .unwrap()
        .into_iter()
        .map(|b| b.heights)
        .collect();
    let origin = Origin::start();
    let url = origin.put("/t.fmrh", bytes, "v1");
    let mut rounds = Vec::new();
    for read_ahead in [true, false] {
        let options_remote = RemoteOptions {
            metadata_limit: 0,
            metadata_chunk: u64::from(local.page_size()),
            read_ahead,
            ..RemoteOptions::default()
        };
        let store =
            Store::from_source(HttpSource::open_with(&url, options_remote).unwrap()).unwrap();
        let before = store.source().request_stats();
        let scene = Terrain::new(&store)
            .unwrap()
            .scene(&camera(), &options)
            .unwrap();
        let loaded = load_blocks(&store, &scene.blocks, 0).unwrap();
        assert_eq!(scene.blocks, want.blocks, "read ahead {read_ahead}");
        let got: Vec<_> = loaded.into_iter().map(|b| b.heights).collect();
        assert_eq!(got, heights, "read ahead {read_ahead}");
        rounds.push(store.source().request_stats().since(&before).rounds);
    }
    // Reading ahead: the root's leaf, the index (root and leaves), the entries' nodes, a
    // refinement wave, the load's records and ancestors, the payloads. Measured: 5 against
    // 12 page by page.
    let (ahead, page_by_page) = (rounds[0], rounds[1]);
    assert!(
        ahead <= 6 && ahead * 2 <= page_by_page,
        "{ahead} rounds reading ahead, {page_by_page} page by page"
    );
}

#[test]
fn each_fault_is_retried_and_the_bytes_are_right() {
    let bytes = container(true);
    let local = Store::from_bytes(bytes.clone()).unwrap();
    let want = local.read_window(local.domain().data_rect()).unwrap();
    for fault in [
        Fault::Status500,
        Fault::Reset,
        Fault::Truncate,
        Fault::Delay(Duration::from_millis(50)),
        // Past the timeout: the request is abandoned and sent again.
        Fault::Delay(Duration::from_millis(1500)),
    ] {
        // At open, and at the metadata area's fetch and the payload batch after it.
        for skip in [0, 2, 3] {
            let origin = Origin::start();
            let url = origin.put("/t.fmrh", bytes.clone(), "v1");
            let mut queue = vec![Fault::Delay(Duration::ZERO); skip];
            queue.extend([fault, fault]);
            origin.fail(&queue);
            let source = HttpSource::open_with(&url, quick()).unwrap();
            let store = Store::from_source(source).unwrap();
            let got = store.read_window(store.domain().data_rect()).unwrap();
            assert!(
                common::first_difference(got.samples(), want.samples()).is_none(),
                "{fault:?} after {skip}"
            );
            let retries = store.source().request_stats().retries;
            if fault == Fault::Delay(Duration::from_millis(50)) {
                assert_eq!(retries, 0, "a delay within the timeout is waited for");
            } else {
                assert!(retries >= 1, "{fault:?}");
            }
        }
    }
}

#[test]
fn a_fault_on_every_try_is_an_io_error_not_corruption() {
    let bytes = container(true);
    for fault in [Fault::Status500, Fault::Reset, Fault::Truncate] {
        let origin = Origin::start();
        let url = origin.put("/t.fmrh", bytes.clone(), "v1");
        // Failing from the start: open fails.
        origin.state.lock().unwrap().always = Some(fault);
        let err = HttpSource::open_with(&url, quick()).unwrap_err();
        assert!(matches!(err, fmrh::Error::Io { .. }), "{fault:?}: {err}");
        // Failing after open: the reads fail, as I/O errors.
        origin.state.lock().unwrap().always = None;
        let store = Store::from_source(HttpSource::open_with(&url, quick()).unwrap()).unwrap();
        origin.state.lock().unwrap().always = Some(fault);
        let err = store.read_window(store.domain().data_rect()).unwrap_err();
        assert!(matches!(err, fmrh::Error::Io { .. }), "{fault:?}: {err}");
        // The validator says the same: the network failed, the file is not corrupt.
        let report = fmrh::store::verify(store.source(), VerifyMode::Full);
        assert!(
            matches!(report, Err(fmrh::Error::Io { .. })),
            "{fault:?}: {report:?}"
        );
    }
}

/// Issue 39: `verify` by URL exited 1 when the network failed, the code of INVALID. A failed
/// read decides nothing: exit 74, and no verdict printed.
#[test]
fn verify_by_url_exits_74_when_the_network_fails_not_1() {
    let origin = Origin::start();
    let url = origin.put("/t.fmrh", container(true), "v1");
    origin.state.lock().unwrap().always = Some(Fault::Reset);
    let out = common::fmrh(&["verify", url.as_str()]);
    let text = String::from_utf8_lossy(&out.stdout);
    assert_eq!(out.status.code(), Some(74), "{text}");
    assert!(!text.contains("INVALID"), "{text}");
    origin.state.lock().unwrap().always = None;
    assert_eq!(
        common::fmrh(&["verify", url.as_str()]).status.code(),
        Some(0)
    );
}

#[test]
fn a_server_that_ignores_ranges_is_refused_without_its_body_being_read() {
    // 64 MiB: a reader that downloaded it would take all of it.
    let big = vec![7u8; 64 << 20];
    let origin = Origin::start();
    let url = origin.put("/big.fmrh", big, "v1");
    origin.state.lock().unwrap().always = Some(Fault::IgnoreRange);
    let err = HttpSource::open(&url).unwrap_err().to_string();
    assert!(err.contains("ignored the Range"), "{err}");
    // The multi-range request (a server may decline those alone), then the two ranges one
    // a request: each refused, none retried.
    assert_eq!(origin.requests(), 3, "refused, not retried");
    // The origin could write only what the sockets buffer before the reader hung up.
    let sent = origin.state.lock().unwrap().bytes_sent;
    assert!(sent < 3 * (64 << 20) / 4, "{sent} bytes went out");
}

#[test]
fn an_object_replaced_on_the_server_is_changed_underneath_not_mixed() {
    let bytes = container(true);
    let origin = Origin::start();
    let url = origin.put("/t.fmrh", bytes.clone(), "v1");
    let remote = Store::open_url(&url).unwrap();
    // The origin re-uploads another version (here: another container, the bundled one).
    origin.put("/t.fmrh", container(false), "v2");
    let err = remote
        .read_window(remote.domain().data_rect())
        .unwrap_err()
        .to_string();
    assert!(err.contains("changed underneath"), "{err}");
    // A fresh open reads the new version whole.
    let fresh = Store::open_url(&url).unwrap();
    let local = Store::from_bytes(container(false)).unwrap();
    assert_eq!(fresh.pin(), local.pin());
}

/// The bundled Puget Sound 1k with a 4 x 4 patch raised by 1 m: another file of the same
/// length (the lengths are whole pages), for servers that give no ETag.
fn container_edited() -> Vec<u8> {
    let mut hf = common::views::puget_1k();
    let w = hf.width() as usize;
    let mut samples = hf.samples().to_vec();
    for y in 500..504 {
        for x in 300..304 {
            samples[y * w + x] += 1.0;
        }
    }
    let metadata = hf.metadata.clone();
    hf = fmrh::Heightfield::new(hf.width(), hf.height(), samples)
        .unwrap()
        .with_metadata(metadata);
    let model = Model::build(hf.clone(), &BuildOptions::default()).unwrap();
    let mut out = std::io::Cursor::new(Vec::new());
    fmrh::store::write_to(&model, &hf.metadata, &WriteOptions::default(), &mut out).unwrap();
    out.into_inner()
}

/// Issue 39: without a usable ETag, a re-upload of another file of the same length was
/// reported as corruption (I-9 or I-5, exit 2). The reader's state is no longer published
/// and no newer one took its place: the object changed underneath (`Error::Changed`, exit
/// 75), as with an ETag.
#[test]
fn a_same_length_re_upload_without_an_etag_is_changed_not_corrupt() {
    let (a, b) = (container(false), container_edited());
    assert_eq!(a.len(), b.len(), "the test needs two files of one length");
    assert_ne!(a, b);
    let origin = Origin::start();
    let url = origin.put("/t.fmrh", a, "");
    let remote = Store::open_url(&url).unwrap();
    assert_eq!(remote.source().etag(), None);
    origin.put("/t.fmrh", b.clone(), "");
    let err = remote.read_window(remote.domain().data_rect()).unwrap_err();
    assert!(matches!(err, fmrh::Error::Changed { .. }), "{err}");
    assert_eq!(err.kind(), "changed");
    // A fresh open reads the new file whole.
    let fresh = Store::open_url(&url).unwrap();
    assert_eq!(fresh.pin(), Store::from_bytes(b).unwrap().pin());
}

/// The same for a dataset whose files are all re-uploaded (no ETags): the manifest's pins
/// then name states the tiles no longer hold, which is a change underneath (exit 75), not a
/// D-4 corruption (exit 2).
#[test]
fn a_re_uploaded_dataset_without_etags_is_changed_not_corrupt() {
    let build = |bump: f32| {
        let field = common::fields::make(65, 33, common::fields::Character::Hills, 0.0, 5);
        let mut samples = field.samples().to_vec();
        samples[20 * 65 + 50] += bump;
        let field = fmrh::Heightfield::new(65, 33, samples).unwrap();
        let dir = tempfile::tempdir().unwrap();
        let rects = common::tiles::split(&field, &[32], &[], &[]);
        let ds = common::tiles::build(dir.path(), &field, &rects, &common::tiles::options(None));
        let files: Vec<(String, Vec<u8>)> = std::fs::read_dir(&ds)
            .unwrap()
            .map(|e| e.unwrap())
            .map(|e| {
                (
                    e.file_name().to_string_lossy().into_owned(),
                    std::fs::read(e.path()).unwrap(),
                )
            })
            .collect();
        (dir, ds, files)
    };
    let (_da, local_a, a) = build(0.0);
    let (_db, _, b) = build(1.0);
    let lengths = |f: &[(String, Vec<u8>)]| {
        f.iter()
            .map(|(n, b)| (n.clone(), b.len()))
            .collect::<Vec<_>>()
    };
    assert_eq!(
        lengths(&a),
        lengths(&b),
        "the test needs files of the same lengths"
    );
    assert_ne!(a, b);
    let origin = Origin::start();
    for (name, bytes) in &a {
        origin.put(&format!("/ds/{name}"), bytes.clone(), "");
    }
    let url = format!("{}/ds/", origin.base);
    let before = common::fmrh(&["info", "--json", url.as_str()]);
    assert!(
        before.status.success(),
        "{}",
        String::from_utf8_lossy(&before.stderr)
    );
    let terrain = fmrh::Terrain::open(&url).unwrap();
    for (name, bytes) in &b {
        origin.put(&format!("/ds/{name}"), bytes.clone(), "");
    }
    let err = terrain.read(None).unwrap_err();
    assert!(matches!(err, fmrh::Error::Changed { .. }), "{err}");
    // Read whole again, the new files are a sound dataset.
    let now = fmrh::Terrain::open(&url).unwrap().read(None).unwrap();
    let local = fmrh::Terrain::open(&local_a).unwrap().read(None).unwrap();
    assert_ne!(now.samples(), local.samples());
}

#[test]
fn a_missing_object_and_an_empty_one_are_clear_errors() {
    let origin = Origin::start();
    let err = Store::open_url(&format!("{}/nothing.fmrh", origin.base))
        .unwrap_err()
        .to_string();
    assert!(err.contains("404"), "{err}");
    let url = origin.put("/empty.fmrh", Vec::new(), "e");
    let err = Store::open_url(&url).unwrap_err().to_string();
    assert!(err.contains("416") || err.contains("empty"), "{err}");
    let url = origin.put("/junk.fmrh", b"not a container at all".to_vec(), "j");
    let err = Store::open_url(&url).unwrap_err();
    assert!(matches!(err, fmrh::Error::Input { .. }), "{err}");
}

proptest! {
    #![proptest_config(ProptestConfig { cases: 24, ..ProptestConfig::default() })]

    /// Random faults before and during a whole read: with fewer faults than tries the bytes
    /// are exactly the local ones; with more, the error is I/O, never corruption or a panic.
    #[test]
    fn random_faults_give_the_right_bytes_or_an_io_error(
        faults in prop::collection::vec(
            prop_oneof![
                Just(Fault::Status500),
                Just(Fault::Reset),
                Just(Fault::Truncate),
                Just(Fault::Delay(Duration::from_millis(5))),
                Just(Fault::Delay(Duration::ZERO)),
            ],
            0..8,
        )
    ) {
        let bytes = container(true);
        let local = Store::from_bytes(bytes.clone()).unwrap();
        let want = local.read_window(local.domain().data_rect()).unwrap();
        let origin = Origin::start();
        let url = origin.put("/t.fmrh", bytes, "v1");
        origin.fail(&faults);
        let options = quick();
        let failing = faults.iter().filter(|f| !matches!(f, Fault::Delay(_))).count();
        let result = HttpSource::open_with(&url, options.clone())
            .and_then(Store::from_source)
            .and_then(|s| s.read_window(s.domain().data_rect()));
        match result {
            Ok(got) => prop_assert!(
                common::first_difference(got.samples(), want.samples()).is_none()
            ),
            Err(e) => {
                prop_assert!(matches!(e, fmrh::Error::Io { .. }), "{e}");
                prop_assert!(failing >= options.tries as usize, "{faults:?}: {e}");
            }
        }
    }
}

#[test]
fn info_verify_extract_and_scene_take_a_url_and_print_what_they_print_locally() {
    let bytes = container(false);
    let dir = tempfile::tempdir().unwrap();
    let file = dir.path().join("ps1k.fmrh");
    std::fs::write(&file, &bytes).unwrap();
    let origin = Origin::start();
    let url = origin.put("/ps1k.fmrh", bytes, "v1");
    let local = file.to_str().unwrap();
    for args in [
        vec!["info", "--json"],
        vec![
            "scene",
            "--json",
            "--eye",
            "20000,180000,6000",
            "--target",
            "80000,80000,500",
            "--tau",
            "1",
            "--load",
        ],
    ] {
        let l = common::ok_json(&common::fmrh(&[args.clone(), vec![local]].concat()));
        let r = common::ok_json(&common::fmrh(&[args.clone(), vec![url.as_str()]].concat()));
        if args[0] == "scene" {
            // The same blocks and guarantees; only what was read, and how, differs.
            assert_eq!(l["blocks"], r["blocks"]);
            assert_eq!(
                l["stats"]["max_screen_error"],
                r["stats"]["max_screen_error"]
            );
            let plan = &r["requests"];
            assert!(plan["scene"]["rounds"].as_u64().unwrap() <= 4, "{plan}");
            assert_eq!(plan["open"]["rounds"], 1, "{plan}");
        } else {
            assert_eq!(l, r, "{args:?}");
        }
    }
    let v = common::ok_json(&common::fmrh(&["verify", "--full", "--json", url.as_str()]));
    assert_eq!(v["valid"], true);
    // A fly-through by URL: the same frames as the local file's.
    let route =
        std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/paths/puget-1k-orbit.csv");
    let fly = |src: &str| {
        common::ok_json(&common::fmrh(&[
            "fly",
            src,
            "--path",
            route.to_str().unwrap(),
            "--tau",
            "2",
            "--json",
        ]))
    };
    let (l, r) = (fly(local), fly(url.as_str()));
    let frames = |v: &serde_json::Value| -> Vec<(u64, u64)> {
        v["frames"]
            .as_array()
            .unwrap()
            .iter()
            .map(|f| {
                (
                    f["visible"].as_u64().unwrap(),
                    f["loaded"].as_u64().unwrap(),
                )
            })
            .collect()
    };
    assert_eq!(frames(&l), frames(&r));
    assert!(
        r["requests"]["requests"].as_u64().unwrap() > 0,
        "{}",
        r["requests"]
    );
    let (a, b) = (dir.path().join("l.f32"), dir.path().join("r.f32"));
    for (src, out) in [(local, &a), (url.as_str(), &b)] {
        let r = common::fmrh(&[
            "extract",
            src,
            "--window",
            "100,200,600,700",
            "-q",
            "-o",
            out.to_str().unwrap(),
        ]);
        assert!(r.status.success(), "{}", String::from_utf8_lossy(&r.stderr));
    }
    assert_eq!(std::fs::read(&a).unwrap(), std::fs::read(&b).unwrap());
}
