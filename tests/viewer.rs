//! The viewer in a real browser: headless Chromium (Debian's, driven by playwright-core from
//! tests/js) loads the page `fmrh serve` serves for Puget Sound 1k, waits for the first
//! scene, takes a screenshot, flies forward and moves the tolerance slider. Checked: the
//! screenshot shows terrain (not a blank sky), every stat the page shows is the server's
//! scene JSON for the page's own query, that JSON is what `fmrh scene` says for the same
//! camera, the page asked again when its camera moved, and a looser tolerance drew no more
//! blocks within it; and the same for a two-tile dataset, whose first view draws both
//! tiles. Run by name (`.ci/run` installs Chromium and playwright-core); without
//! them it fails saying what to install.

mod common;

use std::path::Path;
use std::process::Command;

use common::serve::{puget, Served};
use common::{fmrh, ok_json};

/// What `fmrh::render`'s sky and the page's clear colour are not: terrain pixels.
const SKY: [u8; 3] = [158, 191, 224];

/// The browser's report of one step.
struct Step {
    query: String,
    shown: serde_json::Value,
    scenes: u64,
}

fn step(v: &serde_json::Value) -> Step {
    Step {
        query: v["query"].as_str().expect("the page's query").to_string(),
        shown: v["shown"].clone(),
        scenes: v["scenes"].as_u64().unwrap(),
    }
}

/// A number the page printed, with thousands separators and a unit, as f64.
fn number(text: &str) -> f64 {
    let digits: String = text
        .chars()
        .filter(|c| c.is_ascii_digit() || *c == '.' || *c == '-')
        .collect();
    digits
        .parse()
        .unwrap_or_else(|_| panic!("not a number: {text}"))
}

/// Checks every stat the page shows against the server's scene JSON for its query, and
/// that JSON against `fmrh scene` for the same camera. Returns the JSON.
fn check_step(served: &Served, file: &Path, s: &Step) -> serde_json::Value {
    let api = served.get(&format!("/api/scene?{}", s.query));
    assert_eq!(api.status, 200, "{}", String::from_utf8_lossy(&api.body));
    let api = api.json();
    let shown = &s.shown;
    assert_eq!(
        number(shown["blocks"].as_str().unwrap()),
        api["blocks"].as_f64().unwrap()
    );
    assert_eq!(
        number(shown["payload_bytes"].as_str().unwrap()),
        api["payload_bytes"].as_f64().unwrap()
    );
    let levels: Vec<String> = api["levels"]
        .as_object()
        .unwrap()
        .iter()
        .map(|(l, n)| format!("{l}:{n}"))
        .collect();
    assert_eq!(shown["levels"].as_str().unwrap(), levels.join(" "));
    assert_eq!(
        shown["max_screen_error_px"].as_str().unwrap(),
        format!("{:.3} px", api["max_screen_error_px"].as_f64().unwrap())
    );
    assert_eq!(
        shown["max_error_m"].as_str().unwrap(),
        format!("{:.3} m", api["max_error_m"].as_f64().unwrap())
    );
    assert!(number(shown["schedule_us"].as_str().unwrap()) > 0.0);

    // The same camera through the CLI.
    let param = |k: &str| {
        s.query
            .split('&')
            .find_map(|p| p.strip_prefix(&format!("{k}=")))
            .unwrap_or_else(|| panic!("no {k} in {}", s.query))
            .replace("%2C", ",")
    };
    let (eye, target, tau, viewport) = (
        param("eye"),
        param("target"),
        param("tau"),
        param("viewport"),
    );
    let cli = ok_json(&fmrh(&[
        "scene",
        file.to_str().unwrap(),
        "--eye",
        &eye,
        "--target",
        &target,
        "--tau",
        &tau,
        "--fov",
        &param("fov"),
        "--viewport",
        &viewport,
        "--json",
    ]));
    assert_eq!(api["blocks"], cli["stats"]["blocks"]);
    assert_eq!(api["payload_bytes"], cli["stats"]["bytes"]);
    assert_eq!(api["max_screen_error_px"], cli["stats"]["max_screen_error"]);
    api
}

/// Runs tests/js/viewer-check.mjs in Chromium on `url`, the screenshot to `shot`: the
/// page's report of its three steps.
fn browse(url: &str, shot: &Path) -> serde_json::Value {
    let js = Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/js");
    assert!(
        js.join("node_modules/playwright-core").is_dir(),
        "playwright-core is missing: run `npm ci --prefix tests/js` (.ci/run does)"
    );
    let chromium = std::env::var("CHROMIUM").unwrap_or_else(|_| "/usr/bin/chromium".into());
    assert!(
        Path::new(&chromium).exists(),
        "Chromium is missing at {chromium}: `apt-get install chromium` (.ci/run does), or \
         set CHROMIUM"
    );
    let run = Command::new("node")
        .arg(js.join("viewer-check.mjs"))
        .arg(url)
        .arg(shot)
        .env("CHROMIUM", &chromium)
        .output()
        .expect("node runs (Node.js is needed for the browser test)");
    assert!(
        run.status.success(),
        "the browser check failed:\n{}",
        String::from_utf8_lossy(&run.stderr)
    );
    let report: serde_json::Value = serde_json::from_slice(&run.stdout).expect("JSON");
    assert!(
        !report["renderer"].as_str().unwrap_or("").is_empty(),
        "{report}"
    );
    report
}

/// Asserts that the screenshot `shot` shows shaded terrain: most of the view right of the
/// panel is not sky, in many colours.
fn assert_terrain(shot: &Path) {
    let (share, colours) = terrain_in(shot);
    assert!(
        share > 0.5,
        "only {:.1} % of the view is terrain",
        share * 100.0
    );
    assert!(colours > 100, "{colours} colours: a flat, unshaded picture");
}

/// The share of the view right of the panel that is not sky, and its distinct colours.
fn terrain_in(shot: &Path) -> (f64, usize) {
    let decoder = png::Decoder::new(std::io::BufReader::new(std::fs::File::open(shot).unwrap()));
    let mut reader = decoder.read_info().unwrap();
    let mut buf = vec![0; reader.output_buffer_size().unwrap()];
    let info = reader.next_frame(&mut buf).unwrap();
    assert_eq!((info.width, info.height), (960, 600));
    let channels = info.color_type.samples();
    let (mut terrain, mut total) = (0usize, 0usize);
    let mut colours = std::collections::HashSet::new();
    // Right of the panel (which covers x < 300).
    for y in 0..info.height as usize {
        for x in 300..info.width as usize {
            let i = (y * info.width as usize + x) * channels;
            let px = [buf[i], buf[i + 1], buf[i + 2]];
            total += 1;
            let sky = px.iter().zip(SKY).all(|(a, b)| a.abs_diff(b) <= 3);
            if !sky {
                terrain += 1;
                colours.insert(px);
            }
        }
    }
    (terrain as f64 / total as f64, colours.len())
}

#[test]
fn the_viewer_draws_terrain_and_shows_the_servers_scene() {
    let dir = tempfile::tempdir().unwrap();
    let file = puget(dir.path());
    let served = Served::start(&[&file]);
    let shot = dir.path().join("viewer.png");
    let url = format!(
        "{}/#item=ps1k.fmrh&eye=60000,175000,9000&target=80000,90000,0&tau=1",
        served.base()
    );
    let report = browse(&url, &shot);

    // Every step's stats are the server's, and the server's are the CLI's.
    let first = step(&report["first"]);
    let moved = step(&report["moved"]);
    let tau4 = step(&report["tau4"]);
    assert!(
        first
            .query
            .contains("eye=60000.000%2C175000.000%2C9000.000"),
        "{}",
        first.query
    );
    let api_first = check_step(&served, &file, &first);
    let api_moved = check_step(&served, &file, &moved);
    let api_tau4 = check_step(&served, &file, &tau4);
    assert!(api_first["blocks"].as_u64().unwrap() > 10, "{api_first}");

    // Flying asked for new scenes from a new eye; the slider for one at 4 px.
    assert!(moved.scenes > first.scenes && tau4.scenes > moved.scenes);
    let eye = |q: &str| {
        q.split('&')
            .find(|p| p.starts_with("eye="))
            .unwrap()
            .to_string()
    };
    assert_ne!(eye(&moved.query), eye(&first.query));
    assert_eq!(eye(&tau4.query), eye(&moved.query));
    assert!(tau4.query.contains("tau=4"), "{}", tau4.query);
    assert!(api_tau4["max_screen_error_px"].as_f64().unwrap() <= 4.0);
    // A looser tolerance is a coarser cut of the same tree for the same camera.
    assert!(api_tau4["blocks"].as_u64().unwrap() <= api_moved["blocks"].as_u64().unwrap());

    // The screenshot: terrain in it, shaded (many colours).
    assert_terrain(&shot);
    if let Ok(keep) = std::env::var("FMRH_VIEWER_SCREENSHOT") {
        std::fs::copy(&shot, keep).unwrap();
    }
}

/// A dataset of two tiles (the bundled DEM twice, side by side), shaded by height: the page
/// draws a scene across both tiles and shows the server's stats for it.
#[test]
fn the_viewer_flies_a_dataset_across_its_tiles() {
    let dir = tempfile::tempdir().unwrap();
    std::fs::copy(
        common::bundled_dir().join("puget-sound-1k/ps_height_1k.png"),
        dir.path().join("a.png"),
    )
    .unwrap();
    let layout = dir.path().join("layout.csv");
    std::fs::write(&layout, "a.png,0,0\na.png,1024,0\n").unwrap();
    let ds = dir.path().join("pair");
    let out = fmrh(&[
        "dataset",
        "build",
        "--layout",
        layout.to_str().unwrap(),
        "--seam",
        "first",
        "--z-scale",
        "0.1",
        "--spacing",
        "160",
        "-o",
        ds.to_str().unwrap(),
    ]);
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let served = Served::start(&[&ds]);
    let shot = dir.path().join("pair.png");
    // No camera in the address: the page's own first view of the item.
    let report = browse(
        &format!("{}/#item=pair&colour=shaded", served.base()),
        &shot,
    );
    for name in ["first", "moved", "tau4"] {
        let s = step(&report[name]);
        let api = check_step(&served, &ds, &s);
        if name == "first" {
            let tiles: std::collections::BTreeSet<u64> = api["list"]
                .as_array()
                .unwrap()
                .iter()
                .map(|b| b["tile"].as_u64().expect("a dataset block names its tile"))
                .collect();
            assert_eq!(tiles.len(), 2, "the first view sees both tiles: {tiles:?}");
        }
    }
    assert_terrain(&shot);
}
