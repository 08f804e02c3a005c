//! The command line behaves like its neighbours (`cat`, `gdalinfo`): a closed output pipe ends
//! it quietly, created files honour the umask, what a killed build left is cleaned up by the
//! next build of the same output, SIGTERM and SIGINT remove the file being written, `--json` prints JSON even for an error, the txn id a
//! `replace` reports is the one `info` shows afterwards, `-` is standard output where that
//! makes sense (and refused where it does not), completions and the man page come from the
//! parser, `info` shows the height range and the bounds (in longitude/latitude for projected
//! CRSs too), a build says when it does not know the spacing, and scenes then need
//! `--spacing`.

#![cfg(unix)]

mod common;

use std::os::unix::fs::PermissionsExt;
use std::os::unix::process::ExitStatusExt;
use std::path::{Path, PathBuf};
use std::process::{Command, Stdio};

use common::data;

fn fmrh() -> Command {
    Command::new(env!("CARGO_BIN_EXE_fmrh"))
}

/// Builds `out` from the bundled DEM `input` (a path inside `data/`).
fn build_from(input: &str, out: &Path) {
    let status = fmrh()
        .arg("build")
        .arg(data(input))
        .arg("-o")
        .arg(out)
        .stdout(Stdio::null())
        .stderr(Stdio::null())
        .status()
        .unwrap();
    assert!(status.success());
}

/// Builds `out` from a small bundled DEM.
fn build(out: &Path) {
    build_from("gdal-rs-dem-hills/dem-hills.tiff", out);
}

/// A small container built from a bundled DEM, in `dir`.
fn container(dir: &Path) -> PathBuf {
    let out = dir.join("hills.fmrh");
    build(&out);
    out
}

#[test]
fn a_closed_output_pipe_ends_quietly() {
    let dir = tempfile::tempdir().unwrap();
    let file = container(dir.path());
    let f = file.to_str().unwrap();
    for args in [
        vec!["info", f],
        vec!["info", "--json", f],
        vec!["verify", "--json", f],
        vec!["scan", f, "--cluster", "0", "--hilbert", "0..=1000000"],
        vec![
            "scene",
            f,
            "--eye",
            "100,300,400",
            "--target",
            "150,100,150",
            "--tau",
            "1",
        ],
    ] {
        // A pipe whose reading end is closed before the command writes a byte.
        let (reader, writer) = std::io::pipe().unwrap();
        drop(reader);
        let out = fmrh()
            .args(&args)
            .stdout(writer)
            .stderr(Stdio::piped())
            .output()
            .unwrap();
        let stderr = String::from_utf8_lossy(&out.stderr);
        assert!(!stderr.contains("panicked"), "{args:?}: {stderr}");
        // Killed by SIGPIPE (13), as `cat` is: the shell reports 141.
        assert_eq!(
            out.status.signal(),
            Some(13),
            "{args:?}: {:?} {stderr}",
            out.status
        );
    }
}

#[test]
fn created_files_honour_the_umask() {
    let dir = tempfile::tempdir().unwrap();
    let input = data("gdal-rs-dem-hills/dem-hills.tiff");
    for (umask, mode) in [("022", 0o644), ("077", 0o600), ("002", 0o664)] {
        let out = dir.path().join(format!("u{umask}.fmrh"));
        let script = format!("umask {umask} && exec \"$0\" build \"$1\" -o \"$2\"",);
        let status = Command::new("sh")
            .arg("-c")
            .arg(script)
            .arg(env!("CARGO_BIN_EXE_fmrh"))
            .arg(&input)
            .arg(&out)
            .stderr(Stdio::null())
            .status()
            .unwrap();
        assert!(status.success());
        let got = std::fs::metadata(&out).unwrap().permissions().mode() & 0o777;
        assert_eq!(got, mode, "umask {umask}: mode {got:o}");
    }
}

#[test]
fn the_next_build_removes_what_a_killed_build_left() {
    let dir = tempfile::tempdir().unwrap();
    // What a build of out.fmrh killed with SIGKILL leaves: its temporary file, unlocked.
    let stale = dir.path().join(".out.fmrh.Xk3m9Q.fmrh-tmp");
    std::fs::write(&stale, vec![0u8; 1 << 20]).unwrap();
    // Another output's temporary file is not this build's business.
    let other = dir.path().join(".other.fmrh.Zz9.fmrh-tmp");
    std::fs::write(&other, b"x").unwrap();
    let out = dir.path().join("out.fmrh");
    build(&out);
    assert!(
        !stale.exists(),
        "the killed build's temporary file is still there"
    );
    assert!(other.exists() && out.exists());
    let names: Vec<_> = std::fs::read_dir(dir.path())
        .unwrap()
        .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
        .collect();
    assert_eq!(names.len(), 2, "{names:?}");
}

/// SIGTERM or SIGINT in the middle of a build: the build stops, its temporary file is gone,
/// and the output is either absent or a complete container (had the rename already happened),
/// never half written. The signal is sent the moment the temporary file appears: a 2049² field
/// takes long enough to write that it lands during the write.
#[test]
fn a_signal_during_a_build_leaves_no_temporary_file() {
    let dir = tempfile::tempdir().unwrap();
    let input = dir.path().join("big.f32");
    let side = 2049u32;
    let samples: Vec<u8> = (0..side * side)
        .flat_map(|i| ((((i % side) * 7 + (i / side) * 13) % 1000) as f32).to_le_bytes())
        .collect();
    std::fs::write(&input, samples).unwrap();
    std::fs::write(
        dir.path().join("big.json"),
        format!(r#"{{"width": {side}, "height": {side}, "dtype": "float32"}}"#),
    )
    .unwrap();
    for (signal, name) in [(libc::SIGTERM, "term"), (libc::SIGINT, "int")] {
        let out = dir.path().join(format!("{name}.fmrh"));
        let mut child = fmrh()
            .arg("build")
            .arg(&input)
            .args(["--spacing", "1", "-o"])
            .arg(&out)
            .stdout(Stdio::null())
            .stderr(Stdio::null())
            .spawn()
            .unwrap();
        let temp_exists = || {
            std::fs::read_dir(dir.path()).unwrap().any(|e| {
                e.unwrap()
                    .file_name()
                    .to_string_lossy()
                    .ends_with(".fmrh-tmp")
            })
        };
        let mut signalled = false;
        while child.try_wait().unwrap().is_none() {
            if temp_exists() {
                // SAFETY: kill(2) on our own child's pid, which has not been reaped yet.
                unsafe { libc::kill(child.id() as i32, signal) };
                signalled = true;
                break;
            }
            std::thread::yield_now();
        }
        let status = child.wait().unwrap();
        assert!(signalled, "{name}: the build ended before its write began");
        assert!(!temp_exists(), "{name}: the temporary file is left behind");
        if out.exists() {
            // The rename won the race: then the file must be whole.
            let v = fmrh().arg("verify").arg(&out).output().unwrap();
            assert!(v.status.success(), "{name}: a partial output");
        } else {
            // 128 + the signal, as a shell reports it: SIGTERM 143, SIGINT 130.
            assert_eq!(status.code(), Some(128 + signal), "{name}: {status:?}");
        }
    }
}

#[test]
fn json_output_is_json_even_for_errors() {
    let dir = tempfile::tempdir().unwrap();
    let text = dir.path().join("notes.txt");
    std::fs::write(&text, b"not a container").unwrap();
    let missing = dir.path().join("missing.fmrh");
    for (args, kind, code) in [
        (vec!["verify", "--json", text.to_str().unwrap()], "input", 2),
        // A missing input is the caller's to fix: unusable input, exit 2 (issue 40).
        (
            vec!["info", "--json", missing.to_str().unwrap()],
            "input",
            2,
        ),
        (
            vec!["build", "--json", "--dry-run", text.to_str().unwrap()],
            "input",
            2,
        ),
    ] {
        let out = fmrh().args(&args).output().unwrap();
        assert_eq!(out.status.code(), Some(code), "{args:?}");
        let v: serde_json::Value = serde_json::from_slice(&out.stdout)
            .unwrap_or_else(|e| panic!("{args:?}: not JSON ({e}): {:?}", out.stdout));
        assert_eq!(v["kind"], kind, "{args:?}: {v}");
        assert!(v["error"].as_str().is_some_and(|m| !m.is_empty()));
    }
}

#[test]
fn replace_reports_the_txn_that_info_shows() {
    let dir = tempfile::tempdir().unwrap();
    let file = container(dir.path());
    let patch = dir.path().join("patch.asc");
    std::fs::write(
        &patch,
        "ncols 2\nnrows 2\nxllcorner 0\nyllcorner 0\ncellsize 1\n150 151\n152 153\n",
    )
    .unwrap();
    let json = |args: &[&str]| -> serde_json::Value {
        let out = fmrh().args(args).output().unwrap();
        assert!(
            out.status.success(),
            "{}",
            String::from_utf8_lossy(&out.stderr)
        );
        serde_json::from_slice(&out.stdout).unwrap()
    };
    let f = file.to_str().unwrap();
    let r = json(&[
        "replace",
        f,
        "--at",
        "10,10",
        patch.to_str().unwrap(),
        "--json",
    ]);
    let info = json(&["info", "--json", f]);
    let closed = r["closed_txn"].as_u64().unwrap();
    assert_eq!(closed, r["txn_id"].as_u64().unwrap() + 1, "{r}");
    let shown = info["state"]["txn_id"]
        .as_u64()
        .or_else(|| info["txn_id"].as_u64())
        .unwrap();
    assert_eq!(closed, shown);
}

#[test]
fn completions_and_the_man_page_come_from_the_parser() {
    for shell in ["bash", "zsh", "fish"] {
        let out = fmrh().args(["completions", shell]).output().unwrap();
        assert!(out.status.success(), "{shell}");
        let text = String::from_utf8_lossy(&out.stdout);
        for sub in ["build", "verify", "scene", "replace"] {
            assert!(text.contains(sub), "{shell}: no {sub}");
        }
    }
    // The bash script is valid bash.
    let script = fmrh()
        .args(["completions", "bash"])
        .output()
        .unwrap()
        .stdout;
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("fmrh.bash");
    std::fs::write(&path, script).unwrap();
    assert!(Command::new("bash")
        .arg("-n")
        .arg(&path)
        .status()
        .unwrap()
        .success());
    let man = fmrh().arg("man").output().unwrap();
    assert!(man.status.success());
    let roff = String::from_utf8_lossy(&man.stdout);
    assert!(
        roff.contains(".TH fmrh 1") && roff.contains("replace"),
        "{roff}"
    );
    assert_eq!(
        fmrh()
            .args(["completions", "tcsh"])
            .status()
            .unwrap()
            .code(),
        Some(2)
    );
}

#[test]
fn dash_is_standard_output_where_it_makes_sense() {
    let dir = tempfile::tempdir().unwrap();
    let file = container(dir.path());
    // extract -o -: the raw samples on stdout, the same bytes as the .f32 a file output gets.
    let out = fmrh()
        .arg("extract")
        .arg(&file)
        .args(["-o", "-"])
        .output()
        .unwrap();
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let f32_path = dir.path().join("x.f32");
    let status = fmrh()
        .arg("extract")
        .arg(&file)
        .arg("-o")
        .arg(&f32_path)
        .stderr(Stdio::null())
        .status()
        .unwrap();
    assert!(status.success());
    assert_eq!(out.stdout, std::fs::read(&f32_path).unwrap());
    assert_eq!(out.stdout.len(), 333 * 218 * 4);
    // build -o -: a container needs a file; refused, and no file named "-" appears.
    let out = fmrh()
        .current_dir(dir.path())
        .arg("build")
        .arg(data("gdal-rs-dem-hills/dem-hills.tiff"))
        .args(["-o", "-"])
        .output()
        .unwrap();
    assert_eq!(out.status.code(), Some(2));
    assert!(String::from_utf8_lossy(&out.stderr).contains("standard output"));
    assert!(!dir.path().join("-").exists());
}

#[test]
fn info_shows_the_height_range_and_the_bounds() {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("n43e007.fmrh");
    build_from("srtm3-pyhgtmap/N43E007.hgt.gz", &out);
    let info = fmrh().arg("info").arg("--json").arg(&out).output().unwrap();
    let v: serde_json::Value = serde_json::from_slice(&info.stdout).unwrap();
    // The tile's provenance says -16 .. 2060 m.
    assert_eq!(v["height_range"], serde_json::json!([-16.0, 2060.0]));
    // 1201 samples 3" apart centred on whole degrees: the cells reach 1.5" past 7°E..8°E.
    let half = 1.5 / 3600.0;
    let want = [7.0 - half, 43.0 - half, 8.0 + half, 44.0 + half];
    let got: Vec<f64> = v["georeference"]["lon_lat_bounds"]
        .as_array()
        .unwrap()
        .iter()
        .map(|x| x.as_f64().unwrap())
        .collect();
    for (g, w) in got.iter().zip(want) {
        assert!((g - w).abs() < 1e-9, "{got:?} vs {want:?}");
    }
    let text = fmrh().arg("info").arg(&out).output().unwrap();
    let text = String::from_utf8_lossy(&text.stdout);
    assert!(text.contains("heights     -16 .. 2060 metres"), "{text}");
}

#[test]
fn a_build_without_a_known_spacing_says_so() {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("ps-e.fmrh");
    // An 8-bit palette PNG: no georeference, no spacing.
    let unknown = fmrh()
        .arg("build")
        .arg(data("puget-sound-east-512/ps-e.lg.png"))
        .arg("-o")
        .arg(&out)
        .output()
        .unwrap();
    assert!(unknown.status.success());
    let warning = String::from_utf8_lossy(&unknown.stderr);
    assert!(
        warning.contains("warning") && warning.contains("--spacing"),
        "{warning}"
    );
    let info = fmrh().arg("info").arg(&out).output().unwrap();
    assert!(String::from_utf8_lossy(&info.stdout).contains("spacing     unknown"));
    // Given, no warning.
    let known = fmrh()
        .arg("build")
        .arg(data("puget-sound-east-512/ps-e.lg.png"))
        .args(["--spacing", "30", "--force", "-o"])
        .arg(&out)
        .output()
        .unwrap();
    assert!(known.status.success());
    assert!(!String::from_utf8_lossy(&known.stderr).contains("warning"));
}

/// A scene over a file whose spacing is unknown is refused until `--spacing` says it: a
/// camera in metres over samples of unknown size would see the wrong terrain.
#[test]
fn scenes_over_an_unknown_spacing_need_spacing() {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("ps-e.fmrh");
    build_from("puget-sound-east-512/ps-e.lg.png", &out);
    let scene = |extra: &[&str]| {
        fmrh()
            .arg("scene")
            .arg(&out)
            .args([
                "--eye",
                "256,900,300",
                "--target",
                "256,256,0",
                "--tau",
                "1",
                "--json",
            ])
            .args(extra)
            .output()
            .unwrap()
    };
    let refused = scene(&[]);
    assert_eq!(refused.status.code(), Some(2));
    let err = String::from_utf8_lossy(&refused.stderr);
    assert!(
        err.contains("--spacing") && err.contains("unknown"),
        "{err}"
    );
    let json: serde_json::Value = serde_json::from_slice(&refused.stdout).unwrap();
    assert_eq!(json["kind"], "invalid_argument");
    let in_samples = scene(&["--spacing", "1"]);
    assert!(in_samples.status.success());
    // 30 m apart, the same camera is 30 times nearer in samples: more detail, more blocks.
    let in_metres = scene(&["--spacing", "30"]);
    assert!(in_metres.status.success());
    let blocks = |o: &std::process::Output| {
        let v: serde_json::Value = serde_json::from_slice(&o.stdout).unwrap();
        v["blocks"].as_array().map_or(0, Vec::len)
    };
    assert!(blocks(&in_samples) > 0 && blocks(&in_metres) > 0);
    assert_ne!(blocks(&in_samples), blocks(&in_metres));
    let bad = scene(&["--spacing", "-3"]);
    assert_eq!(bad.status.code(), Some(2));
    // fly the same.
    let path = dir.path().join("path.csv");
    std::fs::write(
        &path,
        "eye_x,eye_y,eye_z,target_x,target_y,target_z\n256,900,300,256,256,0\n256,800,300,256,256,0\n",
    )
    .unwrap();
    let fly = |extra: &[&str]| {
        fmrh()
            .arg("fly")
            .arg(&out)
            .arg("--path")
            .arg(&path)
            .args(["--tau", "1"])
            .args(extra)
            .output()
            .unwrap()
    };
    assert_eq!(fly(&[]).status.code(), Some(2));
    assert!(fly(&["--spacing", "1"]).status.success());
}

/// A projected CRS's bounds are given in longitude and latitude too, through the inverse
/// projection; DTED and a renamed `.hgt` given `--tile` build with their spacing.
#[test]
fn projected_bounds_dted_and_tile_names() {
    let dir = tempfile::tempdir().unwrap();
    let fixtures = Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/fixtures/georef");
    let out = dir.path().join("feet.fmrh");
    let built = fmrh()
        .arg("build")
        .arg(fixtures.join("us_feet.tif"))
        .arg("-o")
        .arg(&out)
        .output()
        .unwrap();
    assert!(built.status.success());
    assert!(!String::from_utf8_lossy(&built.stderr).contains("warning"));
    let info = fmrh().arg("info").arg("--json").arg(&out).output().unwrap();
    let v: serde_json::Value = serde_json::from_slice(&info.stdout).unwrap();
    let spacing = v["spacing_m"][0].as_f64().unwrap();
    assert!(
        (spacing - 100.0 * 1200.0 / 3937.0).abs() < 1e-6,
        "{spacing}"
    );
    // gdaltransform -s_srs EPSG:2927 -t_srs EPSG:4326 puts (1040000, 639600) at
    // 122.9096° W, 47.0621° N and (1040600, 640000) at 122.9071° W, 47.0632° N.
    let b: Vec<f64> = v["georeference"]["lon_lat_bounds"]
        .as_array()
        .expect("lon/lat bounds")
        .iter()
        .map(|x| x.as_f64().unwrap())
        .collect();
    let want = [-122.9096, 47.0621, -122.9071, 47.0632];
    for (g, w) in b.iter().zip(want) {
        assert!((g - w).abs() < 2e-4, "{b:?} vs {want:?}");
    }

    let dted = dir.path().join("dted.fmrh");
    let built = fmrh()
        .arg("build")
        .arg(fixtures.join("n43e007.dt0"))
        .arg("-o")
        .arg(&dted)
        .output()
        .unwrap();
    assert!(
        built.status.success(),
        "{}",
        String::from_utf8_lossy(&built.stderr)
    );
    let info = fmrh()
        .arg("info")
        .arg("--json")
        .arg(&dted)
        .output()
        .unwrap();
    let v: serde_json::Value = serde_json::from_slice(&info.stdout).unwrap();
    assert_eq!(v["source_format"], "dted");
    assert!(v["spacing_m"].is_array());

    let renamed = dir.path().join("my tile.hgt.gz");
    std::fs::copy(data("srtm1-asmyasnikov/S46W066.hgt.gz"), &renamed).unwrap();
    let hgt = dir.path().join("hgt.fmrh");
    let bare = fmrh()
        .arg("build")
        .arg(&renamed)
        .arg("--dry-run")
        .output()
        .unwrap();
    let warning = String::from_utf8_lossy(&bare.stderr);
    assert!(
        warning.contains("warning") && warning.contains("--tile"),
        "{warning}"
    );
    let placed = fmrh()
        .arg("build")
        .arg(&renamed)
        .args(["--tile", "S46W066", "-o"])
        .arg(&hgt)
        .output()
        .unwrap();
    assert!(placed.status.success());
    assert!(!String::from_utf8_lossy(&placed.stderr).contains("warning"));
    let bad = fmrh()
        .arg("build")
        .arg(&renamed)
        .args(["--tile", "S46W", "-o"])
        .arg(&hgt)
        .arg("--force")
        .output()
        .unwrap();
    assert_eq!(bad.status.code(), Some(2));
}
