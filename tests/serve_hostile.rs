//! `fmrh serve` facing hostile clients: each limit the server puts on what a client controls
//! holds, and the server goes on answering everyone else (issue 39). One test per limit:
//!
//! * a request head trickled a line at a time (slowloris) is cut off with `408` at the
//!   timeout, and a silent connection is closed at the timeout without a word;
//! * a head of too many header lines is `431` (its size is `tests/serve.rs`'s);
//! * one address holds at most 64 connections at once: the 65th is `503`, and once the
//!   others close, that address is served again;
//! * a client that stops reading an answer is let go after the timeout, whatever the
//!   answer's size;
//! * nothing outside what is served is reachable: no `..`, raw or percent-encoded, and no
//!   symbolic link in a dataset's directory;
//! * byte ranges that overlap, run backwards or come by the hundred are capped (the whole
//!   object instead), and several ranges of a large file are answered part by part from the
//!   file with exactly its bytes.
//!
//! The servers run with `--timeout 1`, so the tests wait seconds, not minutes. A hang fails
//! by a client-side read timeout, never by blocking the suite.

mod common;

use std::io::{Read, Write};
use std::net::TcpStream;
use std::path::Path;
use std::time::Duration;

use common::serve::{puget, Served};

const LONG: Duration = Duration::from_secs(20);

fn connect(served: &Served) -> TcpStream {
    let s = TcpStream::connect(&served.address).unwrap();
    s.set_read_timeout(Some(LONG)).unwrap();
    s
}

/// Everything the server sends until it closes (a hang fails after [`LONG`]).
fn rest(mut s: TcpStream) -> Vec<u8> {
    let mut all = Vec::new();
    match s.read_to_end(&mut all) {
        Ok(_) => all,
        // A reset after the server closed with unread bytes of ours: what came is the answer.
        Err(e) if e.kind() == std::io::ErrorKind::ConnectionReset => all,
        Err(e) => panic!("no end within {LONG:?}: {e} (after {} bytes)", all.len()),
    }
}

/// A one-tile dataset `dir/ds` (65² samples): the server serves any regular file of a
/// dataset's directory, so the tests put what they need beside its MANIFEST.
fn dataset(dir: &Path) -> std::path::PathBuf {
    let tile = dir.join("t.f32");
    let hf = fmrh::Heightfield::from_fn(65, 65, |x, y| (x * y) as f32).unwrap();
    let bytes: Vec<u8> = hf.samples().iter().flat_map(|v| v.to_le_bytes()).collect();
    std::fs::write(&tile, bytes).unwrap();
    std::fs::write(
        dir.join("t.json"),
        r#"{"width": 65, "height": 65, "spacing_m": [10, 10]}"#,
    )
    .unwrap();
    let layout = dir.join("layout.csv");
    std::fs::write(&layout, format!("{},0,0\n", tile.display())).unwrap();
    let ds = dir.join("ds");
    let out = common::fmrh(&[
        "dataset",
        "build",
        "-q",
        "-o",
        ds.to_str().unwrap(),
        "--layout",
        layout.to_str().unwrap(),
    ]);
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    ds
}

#[test]
fn a_trickled_request_head_is_cut_off_and_a_silent_connection_closed() {
    let dir = tempfile::tempdir().unwrap();
    let file = puget(dir.path());
    let served = Served::start_with(&[&file], &["--timeout", "1"]);
    // A header line every 300 ms, never the blank line that ends the head.
    let mut s = connect(&served);
    s.write_all(b"GET /files/ps1k.fmrh HTTP/1.1\r\n").unwrap();
    for i in 0..12 {
        std::thread::sleep(Duration::from_millis(300));
        if s.write_all(format!("X-Slow-{i}: y\r\n").as_bytes())
            .is_err()
        {
            break; // closed already
        }
    }
    let answer = rest(s);
    assert!(
        answer.starts_with(b"HTTP/1.1 408"),
        "{}",
        String::from_utf8_lossy(&answer)
    );
    // Nothing at all: closed at the timeout, with nothing said.
    let answer = rest(connect(&served));
    assert!(answer.is_empty(), "{}", String::from_utf8_lossy(&answer));
    // And the server answers the next client.
    assert_eq!(served.get("/files/ps1k.fmrh").status, 200);
}

#[test]
fn too_many_header_lines_are_refused() {
    let dir = tempfile::tempdir().unwrap();
    let file = puget(dir.path());
    let served = Served::start(&[&file]);
    let many: Vec<(String, String)> = (0..101).map(|i| (format!("X-{i}"), "1".into())).collect();
    let headers: Vec<(&str, &str)> = many.iter().map(|(k, v)| (k.as_str(), v.as_str())).collect();
    assert_eq!(served.ask("GET", "/", &headers).status, 431);
    assert_eq!(served.ask("GET", "/", &headers[..99]).status, 200);
}

#[test]
fn one_address_holds_at_most_64_connections() {
    let dir = tempfile::tempdir().unwrap();
    let file = puget(dir.path());
    let served = Served::start(&[&file]);
    // 64 connections, each answered once and then left open.
    let held: Vec<TcpStream> = (0..64)
        .map(|_| {
            let mut s = connect(&served);
            s.write_all(b"GET /files/ps1k.fmrh HTTP/1.1\r\nRange: bytes=0-0\r\n\r\n")
                .unwrap();
            let mut status = [0u8; 12];
            s.read_exact(&mut status).unwrap();
            assert_eq!(&status, b"HTTP/1.1 206");
            s
        })
        .collect();
    let answer = rest(connect(&served));
    assert!(
        answer.starts_with(b"HTTP/1.1 503"),
        "{}",
        String::from_utf8_lossy(&answer)
    );
    drop(held);
    // Once the server has seen them close, the address is served again. Each closed
    // connection's thread notices at once (end of stream), but the test cannot see when.
    let mut served_again = false;
    for _ in 0..100 {
        if served.get("/files/ps1k.fmrh").status == 200 {
            served_again = true;
            break;
        }
        std::thread::sleep(Duration::from_millis(50));
    }
    assert!(
        served_again,
        "the address stayed refused after its connections closed"
    );
}

#[test]
fn a_client_that_stops_reading_is_let_go() {
    let dir = tempfile::tempdir().unwrap();
    let ds = dataset(dir.path());
    // 256 MiB in the dataset's directory: far more than the sockets' buffers hold.
    let big = ds.join("big.bin");
    let f = std::fs::File::create(&big).unwrap();
    f.set_len(256 << 20).unwrap();
    drop(f);
    let served = Served::start_with(&[&ds], &["--timeout", "1"]);
    let mut s = connect(&served);
    s.write_all(b"GET /files/ds/big.bin HTTP/1.1\r\n\r\n")
        .unwrap();
    // Read nothing for four timeouts.
    std::thread::sleep(Duration::from_secs(4));
    let answer = rest(s);
    assert!(answer.starts_with(b"HTTP/1.1 200"));
    assert!(
        answer.len() < 256 << 20,
        "the whole answer went to a client that did not read"
    );
    assert_eq!(served.get("/files/ds/MANIFEST").status, 200);
}

#[test]
fn nothing_outside_what_is_served_is_reachable() {
    let dir = tempfile::tempdir().unwrap();
    let ds = dataset(dir.path());
    let secret = dir.path().join("secret.txt");
    std::fs::write(&secret, b"not for the web").unwrap();
    std::os::unix::fs::symlink(&secret, ds.join("link.txt")).unwrap();
    std::os::unix::fs::symlink(dir.path(), ds.join("up")).unwrap();
    let served = Served::start(&[&ds]);
    assert_eq!(served.get("/files/ds/MANIFEST").status, 200);
    for path in [
        "/files/ds/link.txt",
        "/files/ds/up/secret.txt",
        "/files/ds/../secret.txt",
        "/files/ds/%2e%2e/secret.txt",
        "/files/ds/..%2fsecret.txt",
        "/files/ds/%2E%2E%2Fsecret.txt",
        "/files/ds/up%2fsecret.txt",
        "/files/ds/.",
        "/files/ds/",
        "/files/%2e%2e/secret.txt",
        "/files/ds/t.f32%00",
    ] {
        let a = served.get(path);
        assert!(
            a.status == 404 || a.status == 400,
            "{path}: {} {}",
            a.status,
            String::from_utf8_lossy(&a.body)
        );
        assert!(!a.body.windows(7).any(|w| w == b"not for"), "{path}");
    }
}

#[test]
fn hostile_ranges_are_capped_and_large_multipart_answers_are_exact() {
    let dir = tempfile::tempdir().unwrap();
    let ds = dataset(dir.path());
    let big = ds.join("big.bin");
    let bytes: Vec<u8> = (0..(32u32 << 20)).map(|i| (i % 251) as u8).collect();
    std::fs::write(&big, &bytes).unwrap();
    let served = Served::start(&[&ds]);
    let path = "/files/ds/big.bin";
    let len = bytes.len();
    let many = vec!["0-0"; 257].join(",");
    for range in [
        format!("bytes={many}"), // too many
        "bytes=0-,0-,0-".into(), // the object three times over
        "bytes=9-5".into(),      // backwards
        "bytes=-0,5-4".into(),   // malformed
    ] {
        let a = served.ask("GET", path, &[("Range", &range)]);
        assert_eq!(a.status, 200, "{range}");
        assert_eq!(a.body.len(), len, "{range}");
    }
    // Two large overlapping parts, within twice the object: answered from the file.
    let a = served.ask(
        "GET",
        path,
        &[("Range", "bytes=1000-20000000,10000000-30000000")],
    );
    assert_eq!(a.status, 206);
    let kind = a.header("content-type").unwrap().to_string();
    let boundary = kind.split("boundary=").nth(1).unwrap();
    assert_eq!(
        a.header("content-length")
            .unwrap()
            .parse::<usize>()
            .unwrap(),
        a.body.len()
    );
    let mut expect = Vec::new();
    for (from, to) in [(1000usize, 20_000_000usize), (10_000_000, 30_000_000)] {
        expect.extend_from_slice(
            format!(
                "\r\n--{boundary}\r\nContent-Type: application/octet-stream\r\nContent-Range: bytes {from}-{to}/{len}\r\n\r\n"
            )
            .as_bytes(),
        );
        expect.extend_from_slice(&bytes[from..=to]);
    }
    expect.extend_from_slice(format!("\r\n--{boundary}--\r\n").as_bytes());
    assert!(
        a.body == expect,
        "the multipart body differs from the file's bytes"
    );
}
