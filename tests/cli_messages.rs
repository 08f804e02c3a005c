//! The command line says what it did, once, and nothing when told to be quiet (issue 40,
//! point 6): `-q` prints nothing on a successful `build`, `extract`, `dataset build` or
//! `verify` of a valid file (and `verify -q` still reports a damaged one);
//! `replace`'s message names one txn, the one `info` shows; out-of-range camera numbers
//! are "camera coordinates out of range", not "the target must differ from the eye";
//! `--spacing=-10` and `--spacing -10` are values refused with a message, not unknown
//! flags; an empty or reversed scan range is an error, not an empty answer. Every refusal
//! exits 2.

mod common;

use std::path::{Path, PathBuf};

/// Puget Sound 1k (bundled), 160 m, in `dir`, built quietly.
fn container(dir: &Path) -> PathBuf {
    let file = dir.join("ps.fmrh");
    let png = common::bundled_dir().join("puget-sound-1k/ps_height_1k.png");
    let out = common::fmrh(&[
        "build",
        png.to_str().unwrap(),
        "--spacing",
        "160",
        "-q",
        "-o",
        file.to_str().unwrap(),
    ]);
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    assert!(
        out.stdout.is_empty() && out.stderr.is_empty(),
        "build -q said something"
    );
    file
}

#[test]
fn quiet_commands_print_nothing_on_success() {
    let dir = tempfile::tempdir().unwrap();
    let file = container(dir.path());
    let f = file.to_str().unwrap();
    for out_name in ["w.f32", "w.tif"] {
        let o = dir.path().join(out_name);
        let out = common::fmrh(&[
            "extract",
            f,
            "--window",
            "0,0,99,99",
            "-q",
            "-o",
            o.to_str().unwrap(),
        ]);
        assert!(
            out.status.success(),
            "{}",
            String::from_utf8_lossy(&out.stderr)
        );
        assert!(
            out.stdout.is_empty() && out.stderr.is_empty(),
            "extract -q -o {out_name}"
        );
        assert!(o.exists());
        // Without -q it says what it wrote.
        let out = common::fmrh(&[
            "extract",
            f,
            "--window",
            "0,0,99,99",
            "--force",
            "-o",
            o.to_str().unwrap(),
        ]);
        assert!(String::from_utf8_lossy(&out.stderr).contains("wrote"));
    }
    // verify -q: nothing when valid; the report when not.
    let out = common::fmrh(&["verify", "-q", f]);
    assert_eq!(out.status.code(), Some(0));
    assert!(
        out.stdout.is_empty() && out.stderr.is_empty(),
        "verify -q of a valid file"
    );
    let damaged = dir.path().join("damaged.fmrh");
    let mut bytes = std::fs::read(&file).unwrap();
    let at = bytes.len() / 2;
    bytes[at] ^= 0xff;
    std::fs::write(&damaged, bytes).unwrap();
    let out = common::fmrh(&["verify", "-q", damaged.to_str().unwrap()]);
    assert_ne!(out.status.code(), Some(0));
    assert!(
        !out.stdout.is_empty() || !out.stderr.is_empty(),
        "verify -q of a damaged file says why"
    );
    let png = common::bundled_dir().join("puget-sound-1k/ps_height_1k.png");
    let layout = dir.path().join("layout.csv");
    std::fs::write(
        &layout,
        format!("{},0,0\n{},1024,0\n", png.display(), png.display()),
    )
    .unwrap();
    let ds = dir.path().join("ds");
    let out = common::fmrh(&[
        "dataset",
        "build",
        "--layout",
        layout.to_str().unwrap(),
        "--seam",
        "first",
        "--spacing",
        "160",
        "-q",
        "-o",
        ds.to_str().unwrap(),
    ]);
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    assert!(
        out.stdout.is_empty() && out.stderr.is_empty(),
        "dataset build -q"
    );
}

#[test]
fn replace_names_one_txn_the_one_info_shows() {
    let dir = tempfile::tempdir().unwrap();
    let file = container(dir.path());
    let patch = dir.path().join("patch.asc");
    std::fs::write(
        &patch,
        "ncols 2\nnrows 2\nxllcorner 0\nyllcorner 0\ncellsize 1\n150 151\n152 153\n",
    )
    .unwrap();
    let f = file.to_str().unwrap();
    let out = common::fmrh(&["replace", f, "--at", "10,10", patch.to_str().unwrap()]);
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let text = String::from_utf8_lossy(&out.stdout);
    let txns: Vec<&str> = text.split("txn ").skip(1).collect();
    assert_eq!(txns.len(), 1, "one txn named: {text}");
    let named: u64 = txns[0]
        .chars()
        .take_while(char::is_ascii_digit)
        .collect::<String>()
        .parse()
        .unwrap();
    let info = common::fmrh(&["info", "--json", f]);
    let info: serde_json::Value = serde_json::from_slice(&info.stdout).unwrap();
    assert_eq!(Some(named), info["txn_id"].as_u64(), "{text}");
}

/// Runs fmrh, expecting exit 2 and `want` in its message.
fn refused(args: &[&str], want: &str) {
    let out = common::fmrh(args);
    let said = String::from_utf8_lossy(&out.stderr);
    assert_eq!(out.status.code(), Some(2), "{args:?}: {said}");
    assert!(said.contains(want), "{args:?}: {said}");
}

#[test]
fn bad_numbers_and_ranges_are_refused_with_what_is_wrong() {
    let dir = tempfile::tempdir().unwrap();
    let file = container(dir.path());
    let f = file.to_str().unwrap();
    let scene = |eye: &'static str| {
        vec![
            "scene",
            f,
            "--eye",
            eye,
            "--target",
            "80000,90000,0",
            "--tau",
            "1",
        ]
    };
    refused(
        &scene("1e300,1e300,1e300"),
        "camera coordinates out of range",
    );
    refused(&scene("1e13,0,100"), "camera coordinates out of range");
    // Finite and in range but at the target: that message still.
    refused(
        &scene("80000,90000,0"),
        "the target must differ from the eye",
    );
    let png = common::bundled_dir().join("puget-sound-1k/ps_height_1k.png");
    let never = dir.path().join("never.fmrh");
    for spacing in [
        vec!["--spacing=-10"],
        vec!["--spacing", "-10"],
        vec!["--spacing=10,-5"],
    ] {
        let mut args = vec![
            "build",
            png.to_str().unwrap(),
            "-o",
            never.to_str().unwrap(),
        ];
        args.extend(spacing);
        refused(&args, "--spacing");
        assert!(!never.exists());
    }
    for (range, want) in [
        ("5..5", "empty"),
        ("9..=3", "reversed"),
        ("9..3", "reversed"),
    ] {
        refused(&["scan", f, "--cluster", "0", "--hilbert", range], want);
        refused(&["scan", f, "--cluster", "0", "--codes", range], want);
    }
    // A one-element range is fine.
    let out = common::fmrh(&["scan", f, "--cluster", "0", "--codes", "0..=0"]);
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
}
