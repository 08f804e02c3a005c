//! A container read over HTTP range requests (issue 17, first part) gives exactly what the
//! local file gives: the same samples, the same scene, a valid full verification; it opens in
//! two requests (the object's first 128 KiB and last 64 KiB). And the network's faults get a
//! correct retry or a clear error, never wrong data: 5xx answers are retried, a server that
//! ignores `Range` is refused without its body being read, and an object replaced on the
//! server after the reader opened it is reported as changed underneath.
//!
//! The server is a small one in this file (std threads, one request a connection), so the
//! default suite needs nothing installed; nginx and S3 servers come with the rest of issue 17.

#![cfg(feature = "remote")]

mod common;

use std::io::{BufRead, BufReader, Read, Write};
use std::net::TcpListener;
use std::sync::{Arc, Mutex};

use fmrh::model::{BuildOptions, Model};
use fmrh::scene::{Camera, SceneOptions, Terrain};
use fmrh::store::remote::HttpSource;
use fmrh::store::{Store, VerifyMode, WriteOptions};

/// What the test server serves, and how it misbehaves.
#[derive(Default)]
struct Served {
    bytes: Vec<u8>,
    etag: String,
    /// Answer every request with the whole object (200), as a server without ranges does.
    ignore_range: bool,
    /// Answer this many more requests with 500.
    fail_next: u32,
    /// Requests answered.
    requests: u32,
}

/// Starts a server for `served`; returns its URL.
fn serve(served: Arc<Mutex<Served>>) -> String {
    let listener = TcpListener::bind("127.0.0.1:0").unwrap();
    let url = format!("http://{}/tile.fmrh", listener.local_addr().unwrap());
    std::thread::spawn(move || {
        for stream in listener.incoming() {
            let Ok(mut stream) = stream else { continue };
            let served = Arc::clone(&served);
            std::thread::spawn(move || {
                let mut reader = BufReader::new(stream.try_clone().unwrap());
                let (mut range, mut if_match) = (None, None);
                loop {
                    let mut line = String::new();
                    if reader.read_line(&mut line).unwrap_or(0) == 0 || line == "\r\n" {
                        break;
                    }
                    let lower = line.to_ascii_lowercase();
                    if let Some(v) = lower.strip_prefix("range: bytes=") {
                        range = Some(v.trim().to_string());
                    }
                    if lower.starts_with("if-match:") {
                        if_match = Some(line[9..].trim().to_string());
                    }
                }
                let mut s = served.lock().unwrap();
                s.requests += 1;
                let head = |status: &str, extra: &str, len: usize| {
                    format!("HTTP/1.1 {status}\r\nContent-Length: {len}\r\nConnection: close\r\n{extra}\r\n")
                };
                let reply: Vec<u8> = if s.fail_next > 0 {
                    s.fail_next -= 1;
                    head("500 Internal Server Error", "", 0).into_bytes()
                } else if if_match.as_ref().is_some_and(|m| *m != s.etag) {
                    head("412 Precondition Failed", "", 0).into_bytes()
                } else if s.ignore_range || range.is_none() {
                    let mut r = head("200 OK", &format!("ETag: {}\r\n", s.etag), s.bytes.len())
                        .into_bytes();
                    r.extend_from_slice(&s.bytes);
                    r
                } else {
                    let r = range.unwrap_or_default();
                    let (a, b) = r.split_once('-').unwrap();
                    let total = s.bytes.len() as u64;
                    let from: u64 = a.parse().unwrap();
                    let to: u64 = b.parse::<u64>().unwrap().min(total - 1);
                    let body = &s.bytes[from as usize..=to as usize];
                    let extra = format!(
                        "Content-Range: bytes {from}-{to}/{total}\r\nETag: {}\r\n",
                        s.etag
                    );
                    let mut out = head("206 Partial Content", &extra, body.len()).into_bytes();
                    out.extend_from_slice(body);
                    out
                };
                drop(s);
                let _ = stream.write_all(&reply);
                let _ = stream.flush();
                let mut rest = Vec::new();
                let _ = stream.read_to_end(&mut rest);
            });
        }
    });
    url
}

/// Puget Sound 1k (bundled), as a container in memory.
fn container() -> Vec<u8> {
    let hf = common::views::puget_1k();
    let model = Model::build(hf.clone(), &BuildOptions::default()).unwrap();
    let mut out = std::io::Cursor::new(Vec::new());
    fmrh::store::write_to(&model, &hf.metadata, &WriteOptions::default(), &mut out).unwrap();
    out.into_inner()
}

fn served(bytes: Vec<u8>) -> Arc<Mutex<Served>> {
    Arc::new(Mutex::new(Served {
        bytes,
        etag: "\"v1\"".into(),
        ..Served::default()
    }))
}

#[test]
fn a_remote_container_reads_exactly_as_the_local_one() {
    let bytes = container();
    let local = Store::from_bytes(bytes.clone()).unwrap();
    let server = served(bytes);
    let url = serve(Arc::clone(&server));
    let remote = Store::open_url(&url).unwrap();
    assert_eq!(
        server.lock().unwrap().requests,
        2,
        "opening: the prefix and the suffix"
    );
    let all = local.domain().data_rect();
    let (a, b) = (
        local.read_window(all).unwrap(),
        remote.read_window(all).unwrap(),
    );
    assert!(common::first_difference(a.samples(), b.samples()).is_none());
    let cam = Camera::looking_at(
        glam::DVec3::new(20000.0, 180000.0, 6000.0),
        glam::DVec3::new(80000.0, 80000.0, 500.0),
    );
    let options = SceneOptions::new(1.0);
    let sl = Terrain::new(&local)
        .unwrap()
        .scene(&cam, &options)
        .unwrap()
        .blocks;
    let sr = Terrain::new(&remote)
        .unwrap()
        .scene(&cam, &options)
        .unwrap()
        .blocks;
    assert_eq!(sl, sr);
    let report = fmrh::store::verify(HttpSource::open(&url).unwrap(), VerifyMode::Full).unwrap();
    assert!(report.valid, "{:?}", report.checks);
}

#[test]
fn server_errors_are_retried_and_a_server_without_ranges_is_refused() {
    let server = served(container());
    let url = serve(Arc::clone(&server));
    server.lock().unwrap().fail_next = 2;
    let source = HttpSource::open(&url).unwrap();
    assert_eq!(source.request_stats().retries, 2);
    server.lock().unwrap().ignore_range = true;
    let err = HttpSource::open(&url).unwrap_err().to_string();
    assert!(err.contains("ignored the Range"), "{err}");
    // Every try failing: an I/O error, not corruption.
    server.lock().unwrap().ignore_range = false;
    server.lock().unwrap().fail_next = 100;
    let err = HttpSource::open(&url).unwrap_err();
    assert!(matches!(err, fmrh::Error::Io { .. }), "{err}");
}

#[test]
fn an_object_replaced_on_the_server_is_changed_underneath_not_mixed() {
    let bytes = container();
    let server = served(bytes.clone());
    let url = serve(Arc::clone(&server));
    let remote = Store::open_url(&url).unwrap();
    // The origin re-uploads another version.
    {
        let mut s = server.lock().unwrap();
        s.bytes = bytes.iter().map(|b| b ^ 0x55).collect();
        s.etag = "\"v2\"".into();
    }
    let err = remote
        .read_window(remote.domain().data_rect())
        .unwrap_err()
        .to_string();
    assert!(err.contains("changed underneath"), "{err}");
    // A fresh open reads the new version (here garbage: not a container), never a mix.
    assert!(Store::open_url(&url).is_err());
}

#[test]
fn info_verify_extract_and_scene_take_a_url_and_print_what_they_print_locally() {
    let bytes = container();
    let dir = tempfile::tempdir().unwrap();
    let file = dir.path().join("ps1k.fmrh");
    std::fs::write(&file, &bytes).unwrap();
    let url = serve(served(bytes));
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
        } else {
            assert_eq!(l, r, "{args:?}");
        }
    }
    let v = common::ok_json(&common::fmrh(&["verify", "--full", "--json", url.as_str()]));
    assert_eq!(v["valid"], true);
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
