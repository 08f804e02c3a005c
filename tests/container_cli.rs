//! The container commands as a user runs them, on a real DEM: `build -o` writes a file that
//! `verify --full` accepts (exit 0), `info --json` describes it, `extract` returns the source
//! bit for bit with a sidecar `build` can read again, and `scan` lists the cluster nodes the
//! library's range scan returns. Damage gives `verify` exit 1 naming the broken invariant. A
//! non-container gives exit 2. A build never clobbers an existing file unless told to, and a
//! failed build leaves nothing behind.

mod common;

use common::{data, fmrh, ok_json};
use serde_json::Value;

#[test]
fn build_info_verify_extract_scan() {
    let dir = tempfile::tempdir().unwrap();
    let src = data("srtm3-srtmpy/N22W160.hgt");
    let f32_src = data("srtm3-srtmpy/N22W160.f32");
    let out = dir.path().join("n22.fmrh");
    let out_s = out.to_str().unwrap();
    let report = ok_json(&fmrh(&[
        "build",
        src.to_str().unwrap(),
        "-o",
        out_s,
        "--json",
    ]));
    assert_eq!(
        report["output"]["file_length"],
        std::fs::metadata(&out).unwrap().len()
    );

    let v = fmrh(&["verify", out_s, "--full", "--json"]);
    let v = ok_json(&v);
    assert_eq!(v["valid"], true);
    assert_eq!(v["checks"].as_array().unwrap().len(), 16);

    let info = ok_json(&fmrh(&["info", out_s, "--json"]));
    assert_eq!(info["width"], 1201);
    assert_eq!(info["void_samples"], 4279);
    assert_eq!(info["nodes"], report["nodes"]);
    assert_eq!(
        info["clusters"].as_array().unwrap().len(),
        report["clusters"].as_array().unwrap().len()
    );

    // Whole extract equals the source; the sidecar reads back.
    let whole = dir.path().join("whole.f32");
    let e = fmrh(&["extract", out_s, "-o", whole.to_str().unwrap()]);
    assert!(e.status.success(), "{}", String::from_utf8_lossy(&e.stderr));
    assert!(std::fs::read(&whole).unwrap() == std::fs::read(&f32_src).unwrap());
    let sidecar: Value =
        serde_json::from_slice(&std::fs::read(dir.path().join("whole.json")).unwrap()).unwrap();
    assert_eq!(sidecar["nodata_count"], 4279);
    let again = ok_json(&fmrh(&[
        "build",
        whole.to_str().unwrap(),
        "--dry-run",
        "--json",
    ]));
    assert_eq!(again["nodes"], report["nodes"]);

    // A window: rows and columns of the source.
    let win = dir.path().join("win.f32");
    let e = fmrh(&[
        "extract",
        out_s,
        "--window",
        "100,200,163,230",
        "-o",
        win.to_str().unwrap(),
    ]);
    assert!(e.status.success());
    let all = std::fs::read(&f32_src).unwrap();
    let mut want = Vec::new();
    for r in 200..=230usize {
        want.extend_from_slice(&all[(r * 1201 + 100) * 4..(r * 1201 + 164) * 4]);
    }
    assert!(std::fs::read(&win).unwrap() == want);

    // Scan agrees with the library.
    let s = ok_json(&fmrh(&[
        "scan",
        out_s,
        "--cluster",
        "0",
        "--codes",
        "10..=24",
        "--json",
    ]));
    let entries = s["entries"].as_array().unwrap();
    assert_eq!(entries.len(), 15);
    let store = fmrh::store::Store::open(&out).unwrap();
    let lib: Vec<u32> = store
        .scan_codes(0, 10..25)
        .unwrap()
        .map(|e| e.unwrap().node)
        .collect();
    let cli: Vec<u32> = entries
        .iter()
        .map(|e| e["node"].as_u64().unwrap() as u32)
        .collect();
    assert_eq!(cli, lib);
    let h = ok_json(&fmrh(&[
        "scan",
        out_s,
        "--cluster",
        "2",
        "--hilbert",
        "0..=40",
        "--json",
    ]));
    let lib: Vec<u32> = store
        .scan_hilbert(2, 0..=40)
        .unwrap()
        .map(|e| e.unwrap().node)
        .collect();
    let cli: Vec<u32> = h["entries"]
        .as_array()
        .unwrap()
        .iter()
        .map(|e| e["node"].as_u64().unwrap() as u32)
        .collect();
    assert_eq!(cli, lib);
    assert!(!lib.is_empty());
}

#[test]
fn damage_and_misuse_get_the_right_exit_codes() {
    let dir = tempfile::tempdir().unwrap();
    let src = data("gdal-rs-dem-hills/dem_hills.f32");
    let out = dir.path().join("hills.fmrh");
    let out_s = out.to_str().unwrap();
    assert!(fmrh(&["build", src.to_str().unwrap(), "-o", out_s, "-q"])
        .status
        .success());
    let clean = std::fs::read(&out).unwrap();

    // An existing file is kept unless --force.
    let again = fmrh(&["build", src.to_str().unwrap(), "-o", out_s]);
    assert_eq!(again.status.code(), Some(2));
    assert!(String::from_utf8_lossy(&again.stderr).contains("--force"));
    assert!(std::fs::read(&out).unwrap() == clean);
    assert!(
        fmrh(&["build", src.to_str().unwrap(), "-o", out_s, "--force", "-q"])
            .status
            .success()
    );

    // A failed build leaves no file and no temporary behind.
    let junk = dir.path().join("junk.png");
    std::fs::write(&junk, b"\x89PNG\r\n\x1a\nnope").unwrap();
    let failed = dir.path().join("failed.fmrh");
    let f = fmrh(&[
        "build",
        junk.to_str().unwrap(),
        "-o",
        failed.to_str().unwrap(),
    ]);
    assert_eq!(f.status.code(), Some(2));
    let names: Vec<String> = std::fs::read_dir(dir.path())
        .unwrap()
        .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
        .collect();
    assert!(
        !names
            .iter()
            .any(|n| n.starts_with("failed") || n.contains(".tmp")),
        "{names:?}"
    );

    // A flipped bit in a payload: verify exits 1 and names I-9.
    let mut bad = clean.clone();
    let n = bad.len();
    bad[n / 2] ^= 0x10;
    let damaged = dir.path().join("damaged.fmrh");
    std::fs::write(&damaged, &bad).unwrap();
    let v = fmrh(&["verify", damaged.to_str().unwrap()]);
    assert_eq!(v.status.code(), Some(1));
    let text = String::from_utf8_lossy(&v.stdout);
    assert!(text.contains("FAILED"), "{text}");
    // Other commands refuse a damaged file with exit 2, or read around the damage.
    let e = fmrh(&[
        "extract",
        damaged.to_str().unwrap(),
        "-o",
        dir.path().join("x.f32").to_str().unwrap(),
    ]);
    assert!(e.status.code() == Some(2) || e.status.success());
    assert!(!String::from_utf8_lossy(&e.stderr).contains("panicked"));

    // Truncated: exit 1 with I-3.
    std::fs::write(&damaged, &clean[..clean.len() - 4096]).unwrap();
    let v = fmrh(&["verify", damaged.to_str().unwrap()]);
    assert_eq!(v.status.code(), Some(1));
    assert!(String::from_utf8_lossy(&v.stdout).contains("I-3"));

    // Not a container: exit 2.
    for bytes in [&b"not a container"[..], &[]] {
        std::fs::write(&damaged, bytes).unwrap();
        let v = fmrh(&["verify", damaged.to_str().unwrap()]);
        assert_eq!(v.status.code(), Some(2));
        assert!(String::from_utf8_lossy(&v.stderr).contains("not an fmrh container"));
    }
    let v = fmrh(&["verify", "/nonexistent.fmrh"]);
    assert_eq!(v.status.code(), Some(2));

    // Bad arguments.
    for args in [
        vec![
            "extract",
            out_s,
            "--window",
            "0,0,9999,3",
            "-o",
            "/tmp/never.f32",
        ],
        vec![
            "extract",
            out_s,
            "--window",
            "1,2,3",
            "-o",
            "/tmp/never.f32",
        ],
        vec!["scan", out_s, "--cluster", "999", "--codes", "0..3"],
        vec!["scan", out_s, "--cluster", "0", "--hilbert", "x..3"],
        vec![
            "build",
            src.to_str().unwrap(),
            "-o",
            "/tmp/never.fmrh",
            "--page-size",
            "3000",
        ],
    ] {
        let o = fmrh(&args);
        assert_eq!(
            o.status.code(),
            Some(2),
            "{args:?}: {}",
            String::from_utf8_lossy(&o.stderr)
        );
    }
    assert!(!std::path::Path::new("/tmp/never.fmrh").exists());
}
