//! `fmrh serve` without a browser: what it serves is exactly the files' bytes, by single
//! and multiple ranges, with an ETag that changes when a commit does and `If-Match` that
//! refuses a changed file; fmrh's own remote reader reads a served container and a served
//! dataset to the same scenes as the local files; the scene API answers what `fmrh scene`
//! answers, its mesh is the scene's (grid or TIN, as `fmrh mesh` writes it); and nothing
//! outside the served paths, nothing but GET and HEAD, and no malformed query gets
//! anything but a clear error. (The page itself is tested in Chromium by tests/viewer.rs.)

mod common;

use std::path::{Path, PathBuf};

use common::serve::{puget, Served};
use common::{fmrh, ok_json};

const CAMERA: [&str; 6] = [
    "--eye",
    "20000,180000,6000",
    "--target",
    "80000,80000,500",
    "--tau",
    "1",
];

/// A 2 x 2 tile dataset of synthetic hills, 10 m a sample, in `dir/ds`.
fn dataset(dir: &Path) -> PathBuf {
    let field = common::fields::make(257, 257, common::fields::Character::Hills, 0.0, 5);
    let rects = common::tiles::split(&field, &[128], &[128], &[]);
    common::tiles::build(dir, &field, &rects, &common::tiles::options(None))
}

/// The blocks of a scene's JSON, as (level, key, error bits): what must not differ between
/// a local read and a remote one.
fn blocks(scene: &serde_json::Value) -> Vec<(u64, u64, u64, Option<u64>)> {
    scene["blocks"]
        .as_array()
        .expect("blocks")
        .iter()
        .map(|b| {
            (
                b["level"].as_u64().unwrap(),
                b["key"].as_u64().unwrap(),
                b["error"].as_f64().unwrap().to_bits(),
                b["tile"].as_u64(),
            )
        })
        .collect()
}

fn scene_json(file: &str, camera: &[&str], extra: &[&str]) -> serde_json::Value {
    let mut args = vec!["scene", file];
    args.extend(camera);
    args.extend(extra);
    args.push("--json");
    ok_json(&fmrh(&args))
}

#[test]
fn the_remote_reader_reads_what_is_served_as_it_reads_the_file() {
    let dir = tempfile::tempdir().unwrap();
    let file = puget(dir.path());
    let ds = dataset(dir.path());
    let served = Served::start(&[&file, &ds]);

    let local = scene_json(file.to_str().unwrap(), &CAMERA, &["--load"]);
    let url = format!("{}/files/ps1k.fmrh", served.base());
    let remote = scene_json(&url, &CAMERA, &["--load"]);
    assert!(!blocks(&local).is_empty());
    assert_eq!(blocks(&local), blocks(&remote));
    assert_eq!(local["stats"]["bytes"], remote["stats"]["bytes"]);
    // The reader opened it in one round (a multi-range request the server answered whole).
    assert_eq!(
        remote["requests"]["open"]["rounds"], 1,
        "{}",
        remote["requests"]
    );
    assert_eq!(remote["requests"]["open"]["requests"], 1);

    let camera = [
        "--eye",
        "1280,3000,2500",
        "--target",
        "1280,1280,0",
        "--tau",
        "1",
    ];
    let local = scene_json(ds.to_str().unwrap(), &camera, &[]);
    let remote = scene_json(&format!("{}/files/ds/", served.base()), &camera, &[]);
    let tiles: std::collections::BTreeSet<_> = blocks(&local).iter().map(|b| b.3).collect();
    assert!(tiles.len() > 1, "the camera sees several tiles: {tiles:?}");
    assert_eq!(blocks(&local), blocks(&remote));
}

#[test]
fn ranges_etags_and_refusals() {
    let dir = tempfile::tempdir().unwrap();
    let file = puget(dir.path());
    let ds = dataset(dir.path());
    let served = Served::start(&[&file, &ds]);
    let bytes = std::fs::read(&file).unwrap();
    let len = bytes.len();

    let whole = served.get("/files/ps1k.fmrh");
    assert_eq!(whole.status, 200);
    assert_eq!(whole.body, bytes);
    assert_eq!(whole.header("accept-ranges"), Some("bytes"));
    let etag = whole.header("etag").expect("an ETag").to_string();
    assert!(
        etag.starts_with('"') && etag.ends_with('"'),
        "a strong ETag: {etag}"
    );

    let one = served.ask("GET", "/files/ps1k.fmrh", &[("Range", "bytes=100-199")]);
    assert_eq!(one.status, 206);
    assert_eq!(one.body, &bytes[100..200]);
    assert_eq!(
        one.header("content-range"),
        Some(&*format!("bytes 100-199/{len}"))
    );
    let tail = served.ask("GET", "/files/ps1k.fmrh", &[("Range", "bytes=-10")]);
    assert_eq!(tail.body, &bytes[len - 10..]);

    // Two ranges: a multipart answer whose parts are the bytes asked for.
    let two = served.ask("GET", "/files/ps1k.fmrh", &[("Range", "bytes=0-3,-4")]);
    assert_eq!(two.status, 206);
    let kind = two.header("content-type").unwrap();
    let boundary = kind
        .strip_prefix("multipart/byteranges; boundary=")
        .unwrap_or_else(|| panic!("{kind}"));
    let text = two.body.clone();
    let mut parts = Vec::new();
    let mut at = 0;
    let find = |hay: &[u8], needle: &[u8], from: usize| {
        hay[from..]
            .windows(needle.len())
            .position(|w| w == needle)
            .map(|p| p + from)
    };
    while let Some(start) = find(&text, b"Content-Range: bytes ", at) {
        let eol = find(&text, b"\r\n", start).unwrap();
        let range = std::str::from_utf8(&text[start + 21..eol])
            .unwrap()
            .to_string();
        let (span, _) = range.split_once('/').unwrap();
        let (a, b) = span.split_once('-').unwrap();
        let (a, b): (usize, usize) = (a.parse().unwrap(), b.parse().unwrap());
        let body = eol + 4;
        parts.push((a, text[body..body + b - a + 1].to_vec()));
        at = body + b - a + 1;
    }
    assert_eq!(
        parts,
        vec![
            (0, bytes[..4].to_vec()),
            (len - 4, bytes[len - 4..].to_vec())
        ]
    );
    assert!(text.ends_with(format!("--{boundary}--\r\n").as_bytes()));

    // Past the end: 416, saying how long the file is.
    let past = served.ask(
        "GET",
        "/files/ps1k.fmrh",
        &[("Range", &format!("bytes={len}-"))],
    );
    assert_eq!(past.status, 416);
    assert_eq!(
        past.header("content-range"),
        Some(&*format!("bytes */{len}"))
    );

    // If-Match: the right ETag reads, another is refused.
    let ok = served.ask(
        "GET",
        "/files/ps1k.fmrh",
        &[("Range", "bytes=0-0"), ("If-Match", &etag)],
    );
    assert_eq!(ok.status, 206);
    let stale = served.ask("GET", "/files/ps1k.fmrh", &[("If-Match", "\"other\"")]);
    assert_eq!(stale.status, 412);

    // HEAD: the length, no body.
    let head = served.ask("HEAD", "/files/ps1k.fmrh", &[]);
    assert_eq!(head.status, 200);
    assert_eq!(head.header("content-length"), Some(&*len.to_string()));
    assert!(head.body.is_empty());

    // A dataset's files, and nothing else.
    let manifest = served.get("/files/ds/MANIFEST");
    assert_eq!(manifest.status, 200);
    assert_eq!(manifest.body, std::fs::read(ds.join("MANIFEST")).unwrap());
    for path in [
        "/files/../Cargo.toml",
        "/files/ds/../ps1k.fmrh",
        "/files/ds/%2e%2e/ps1k.fmrh",
        "/files/ds/%2E%2E%2Fps1k.fmrh",
        "/files/ds/",
        "/files/ds",
        "/files/ds/.",
        "/files/ps1k.fmrh/x",
        "/files/nothing",
        "/etc/passwd",
    ] {
        let a = served.get(path);
        assert_eq!(a.status, 404, "{path}");
        assert!(a.json()["error"].as_str().is_some(), "{path}");
    }
    assert_eq!(served.get("/files/ds/%zz").status, 400);
    let post = served.ask("POST", "/files/ps1k.fmrh", &[]);
    assert_eq!(post.status, 405);
    assert_eq!(post.header("allow"), Some("GET, HEAD"));
    // What a client controls is bounded: a huge head, a body, another protocol.
    let huge = "x".repeat(20 << 10);
    assert_eq!(served.ask("GET", "/", &[("X-Big", &huge)]).status, 431);
    assert_eq!(
        served.ask("POST", "/", &[("Content-Length", "5")]).status,
        400
    );
    assert_eq!(
        std::fs::read(&file).unwrap(),
        bytes,
        "the server changed a file"
    );
}

/// Regression: with tiny_http 0.12, a connection that arrived while the pool's threads sat
/// on idle keep-alive connections could wait until one closed (a remote dataset's scene
/// stalled for 60 s about one run in three). Idle connections must never hold up others.
#[test]
fn idle_keep_alive_connections_hold_up_no_one() {
    use std::io::{Read, Write};
    let dir = tempfile::tempdir().unwrap();
    let file = puget(dir.path());
    let served = Served::start(&[&file]);
    // Twelve connections that asked once and then stay open, silent.
    let idle: Vec<std::net::TcpStream> = (0..12)
        .map(|_| {
            let mut s = std::net::TcpStream::connect(&served.address).unwrap();
            s.write_all(b"GET /files/ps1k.fmrh HTTP/1.1\r\nHost: x\r\nRange: bytes=0-0\r\n\r\n")
                .unwrap();
            let mut answer = [0u8; 12];
            s.read_exact(&mut answer).unwrap();
            assert_eq!(&answer, b"HTTP/1.1 206");
            s
        })
        .collect();
    // Twelve more at once, each answered (a hang fails by the read timeout, not forever).
    let threads: Vec<_> = (0..12)
        .map(|_| {
            let address = served.address.clone();
            std::thread::spawn(move || {
                let mut s = std::net::TcpStream::connect(&address).unwrap();
                s.set_read_timeout(Some(std::time::Duration::from_secs(20)))
                    .unwrap();
                s.write_all(b"GET /files/ps1k.fmrh HTTP/1.0\r\nRange: bytes=0-3\r\n\r\n")
                    .unwrap();
                let mut all = Vec::new();
                s.read_to_end(&mut all).expect("an answer within 20 s");
                all
            })
        })
        .collect();
    for t in threads {
        let all = t.join().unwrap();
        assert!(all.starts_with(b"HTTP/1.1 206"));
        assert!(all.ends_with(b"FMRH"));
    }
    drop(idle);
}

#[test]
fn a_commit_while_serving_changes_the_etag() {
    let dir = tempfile::tempdir().unwrap();
    let file = puget(dir.path());
    let served = Served::start(&[&file]);
    let before = served.get("/files/ps1k.fmrh");
    let etag = before.header("etag").unwrap().to_string();
    // A 16 x 16 patch, committed by another process while the server runs.
    let patch = dir.path().join("patch.f32");
    let samples: Vec<u8> = [123.5f32; 256]
        .iter()
        .flat_map(|v| v.to_le_bytes())
        .collect();
    std::fs::write(&patch, samples).unwrap();
    std::fs::write(
        patch.with_extension("json"),
        serde_json::json!({ "width": 16, "height": 16, "units": "metres" }).to_string(),
    )
    .unwrap();
    let out = fmrh(&[
        "replace",
        file.to_str().unwrap(),
        "--at",
        "300,300",
        patch.to_str().unwrap(),
    ]);
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let after = served.get("/files/ps1k.fmrh");
    assert_eq!(after.body, std::fs::read(&file).unwrap());
    assert_ne!(after.header("etag").unwrap(), etag);
    // A reader that opened the old version is refused, never given the new bytes.
    let stale = served.ask(
        "GET",
        "/files/ps1k.fmrh",
        &[("Range", "bytes=0-9"), ("If-Match", &etag)],
    );
    assert_eq!(stale.status, 412);
    // The scene API sees the commit: the patch's height is drawn.
    let q = "/api/scene?item=ps1k.fmrh&eye=49500,49500,3000&target=49500,49200,0&tau=0.5";
    let scene = served.get(q).json();
    assert!(scene["blocks"].as_u64().unwrap() > 0, "{scene}");
}

#[test]
fn the_scene_api_answers_what_fmrh_scene_answers() {
    let dir = tempfile::tempdir().unwrap();
    let file = puget(dir.path());
    let served = Served::start(&[&file]);

    let items = served.get("/api/items").json();
    let item = &items["items"][0];
    assert_eq!(item["name"], "ps1k.fmrh");
    assert_eq!(item["width"], 1025);
    assert_eq!(item["spacing_m"], serde_json::json!([160.0, 160.0]));
    assert_eq!(items["level_colours"].as_array().unwrap().len(), 256);

    let query = "item=ps1k.fmrh&eye=20000%2C180000%2C6000&target=80000,80000,500&tau=1\
                 &fov=60&viewport=640x360";
    let api = served.get(&format!("/api/scene?{query}"));
    assert_eq!(api.status, 200);
    let api = api.json();
    let cli = scene_json(
        file.to_str().unwrap(),
        &CAMERA,
        &["--fov", "60", "--viewport", "640x360"],
    );
    let stats = &cli["stats"];
    assert_eq!(api["blocks"], stats["blocks"]);
    assert_eq!(api["payload_bytes"], stats["bytes"]);
    assert_eq!(api["max_error_m"], stats["max_error"]);
    assert_eq!(api["max_screen_error_px"], stats["max_screen_error"]);
    let listed: Vec<(u64, u64)> = api["list"]
        .as_array()
        .unwrap()
        .iter()
        .map(|b| (b["level"].as_u64().unwrap(), b["key"].as_u64().unwrap()))
        .collect();
    let expected: Vec<(u64, u64)> = blocks(&cli).iter().map(|b| (b.0, b.1)).collect();
    assert_eq!(listed, expected);
    let per_level: u64 = api["levels"]
        .as_object()
        .unwrap()
        .values()
        .map(|n| n.as_u64().unwrap())
        .sum();
    assert_eq!(per_level, api["blocks"].as_u64().unwrap());

    // The mesh: the same glTF binary `fmrh mesh` writes for that camera.
    let mesh = served.get(&format!("/api/mesh?{query}"));
    assert_eq!(mesh.status, 200);
    assert_eq!(mesh.header("content-type"), Some("model/gltf-binary"));
    let glb = dir.path().join("scene.glb");
    let mut args = vec!["mesh", file.to_str().unwrap()];
    args.extend(CAMERA);
    args.extend([
        "--fov",
        "60",
        "--viewport",
        "640x360",
        "-o",
        glb.to_str().unwrap(),
    ]);
    let out = fmrh(&args);
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    assert_eq!(mesh.body, std::fs::read(&glb).unwrap());
    // And with `max_error`, the TINs `fmrh mesh --max-error` writes.
    let tin = served.get(&format!("/api/mesh?{query}&max_error=2.5"));
    assert_eq!(tin.status, 200);
    args.extend(["--max-error", "2.5", "--force"]);
    let out = fmrh(&args);
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    assert_eq!(tin.body, std::fs::read(&glb).unwrap());
    assert!(tin.body.len() < mesh.body.len());

    // Bad queries: 400 and a message that names the problem.
    for (query, says) in [
        ("item=ps1k.fmrh&eye=1,2,3&target=4,5,6", "`tau` is required"),
        ("eye=1,2,3&target=4,5,6&tau=1", "`item` is required"),
        (
            "item=nope&eye=1,2,3&target=4,5,6&tau=1",
            "no item is served as `nope`",
        ),
        ("item=ps1k.fmrh&eye=1,2&target=4,5,6&tau=1", "eye `1,2`"),
        ("item=ps1k.fmrh&eye=1,2,3&target=4,5,6&tau=x", "`tau`"),
        (
            "item=ps1k.fmrh&eye=1,2,3&target=4,5,6&tau=-1",
            "tolerance -1 px",
        ),
        (
            "item=ps1k.fmrh&eye=1,2,3&target=4,5,6&tau=1&viewport=big",
            "viewport",
        ),
        (
            "item=ps1k.fmrh&eye=1,2,3&target=4,5,6&tau=1&mode=fast",
            "`mode`",
        ),
        (
            "item=ps1k.fmrh&eye=1,2,3&target=4,5,6&tau=1&colour=red",
            "unknown parameter `colour`",
        ),
        ("item=ps1k.fmrh&eye=1,2,3&target=1,2,3&tau=1", ""),
        ("item=%ff&eye=1,2,3&target=4,5,6&tau=1", "percent-encoded"),
        (
            "item=ps1k.fmrh&eye=1,2,3&target=4,5,6&tau=1&max_error=-1",
            "`max_error` -1",
        ),
        (
            "item=ps1k.fmrh&eye=1,2,3&target=4,5,6&tau=1&max_error=low",
            "`max_error`: `low`",
        ),
        (
            "item=ps1k.fmrh&eye=1,2,3&target=4,5,6&tau=1&max_error=1&cracks=stitch",
            "`cracks=stitch`",
        ),
    ] {
        for api in ["scene", "mesh"] {
            let a = served.get(&format!("/api/{api}?{query}"));
            assert_eq!(
                a.status,
                400,
                "{api}?{query}: {}",
                String::from_utf8_lossy(&a.body)
            );
            let message = a.json()["error"].as_str().unwrap().to_string();
            assert!(message.contains(says), "{api}?{query}: {message}");
        }
    }
    // A camera that sees no terrain: a scene of no blocks, and no mesh.
    let away = "item=ps1k.fmrh&eye=80000,-50000,3000&target=80000,-900000,3000&tau=1";
    assert_eq!(
        served.get(&format!("/api/scene?{away}")).json()["blocks"],
        0
    );
    assert_eq!(served.get(&format!("/api/mesh?{away}")).status, 400);

    // The page and its script.
    let page = served.get("/");
    assert_eq!(
        page.header("content-type"),
        Some("text/html; charset=utf-8")
    );
    assert!(String::from_utf8_lossy(&page.body).contains("<script src=\"/viewer.js\">"));
    assert_eq!(served.get("/viewer.js").status, 200);
}

#[test]
fn serve_refuses_what_it_cannot_serve() {
    let dir = tempfile::tempdir().unwrap();
    let file = puget(dir.path());
    let other = dir.path().join("b");
    std::fs::create_dir(&other).unwrap();
    std::fs::copy(&file, other.join("ps1k.fmrh")).unwrap();
    let not_a_container = dir.path().join("x.fmrh");
    std::fs::write(&not_a_container, b"hello").unwrap();
    let f = file.to_str().unwrap();
    let twin = other.join("ps1k.fmrh");
    let bad = not_a_container.to_str().unwrap();
    let missing = dir.path().join("missing.fmrh");
    // Exit 2 for what the user asked wrongly, a missing file included (as every command:
    // issue 40; 1 is for the system's failures).
    for (args, code, says) in [
        (vec![f, twin.to_str().unwrap()], 2, "both named `ps1k.fmrh`"),
        (vec![bad], 2, "x.fmrh"),
        (vec![missing.to_str().unwrap()], 2, "missing.fmrh"),
        (vec!["http://127.0.0.1:1/a.fmrh"], 2, "not URLs"),
        (vec![other.to_str().unwrap()], 2, "without a MANIFEST"),
        (
            vec![f, "--bind", "256.0.0.1", "--port", "0"],
            2,
            "cannot listen",
        ),
    ] {
        let mut all = vec!["serve"];
        all.extend(args.iter().copied());
        let out = fmrh(&all);
        let stderr = String::from_utf8_lossy(&out.stderr);
        assert_eq!(out.status.code(), Some(code), "{args:?}: {stderr}");
        assert!(stderr.contains(says), "{args:?}: {stderr}");
    }
}
