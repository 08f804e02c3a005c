//! The viewer in a real browser: headless Chromium (Debian's, driven by playwright-core from
//! tests/js) loads the page `fmrh serve` serves for Puget Sound 1k, waits for the first
//! scene, takes a screenshot, flies forward, moves the tolerance slider and picks TINs.
//! Checked: the screenshot shows terrain (not a blank sky), every stat the page shows is
//! the server's scene JSON for the page's own query, that JSON is what `fmrh scene` says
//! for the same camera, the page asked again when its camera moved, a looser tolerance
//! drew no more blocks within it, and the page drew the triangles of the server's mesh,
//! grid or TIN; and the same for a two-tile dataset, whose first view draws both tiles.
//! Run by name (`.ci/run` installs Chromium and playwright-core); without them it fails
//! saying what to install.

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
    let report = node("viewer-check.mjs", &[url, shot.to_str().unwrap()]);
    assert!(
        !report["renderer"].as_str().unwrap_or("").is_empty(),
        "{report}"
    );
    report
}

/// Runs a script of tests/js in Node with Chromium, and returns the JSON it prints.
fn node(script: &str, args: &[&str]) -> serde_json::Value {
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
        .arg(js.join(script))
        .args(args)
        .env("CHROMIUM", &chromium)
        .output()
        .expect("node runs (Node.js is needed for the browser test)");
    assert!(
        run.status.success(),
        "the browser check failed:\n{}",
        String::from_utf8_lossy(&run.stderr)
    );
    serde_json::from_slice(&run.stdout).expect("JSON")
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

/// Whether a pixel is the sky's colour.
fn is_sky(px: &[u8]) -> bool {
    px.iter().zip(SKY).all(|(a, b)| a.abs_diff(b) <= 3)
}

/// The page's panel covers the canvas left of this x, in CSS pixels.
const PANEL: usize = 300;

/// A 960 × 600 screenshot's width, height and RGB samples.
fn screenshot(shot: &Path) -> (usize, usize, Vec<u8>) {
    let decoder = png::Decoder::new(std::io::BufReader::new(std::fs::File::open(shot).unwrap()));
    let mut reader = decoder.read_info().unwrap();
    let mut buf = vec![0; reader.output_buffer_size().unwrap()];
    let info = reader.next_frame(&mut buf).unwrap();
    assert_eq!((info.width, info.height), (960, 600));
    let channels = info.color_type.samples();
    let rgb = buf[..info.buffer_size()]
        .chunks_exact(channels)
        .flat_map(|px| [px[0], px[1], px[2]])
        .collect();
    (960, 600, rgb)
}

/// The share of the view right of the panel that is not sky, and its distinct colours.
fn terrain_in(shot: &Path) -> (f64, usize) {
    let (width, height, rgb) = screenshot(shot);
    let (mut terrain, mut total) = (0usize, 0usize);
    let mut colours = std::collections::HashSet::new();
    // Right of the panel (which covers x < 300).
    for y in 0..height {
        for x in PANEL..width {
            let i = (y * width + x) * 3;
            let px = [rgb[i], rgb[i + 1], rgb[i + 2]];
            total += 1;
            if !is_sky(&px) {
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

    // The mesh select: TINs within 5 m, same camera and tolerance; the page drew the
    // triangles the server's mesh for its query holds, and the grid's before it.
    let tin = step(&report["tin"]);
    check_step(&served, &file, &tin);
    assert_eq!(eye(&tin.query), eye(&tau4.query));
    assert!(
        tin.query.contains("max_error=5") && !tin.query.contains("cracks="),
        "{}",
        tin.query
    );
    for (name, s) in [("tau4", &tau4), ("tin", &tin)] {
        let glb = served.get(&format!("/api/mesh?{}", s.query));
        assert_eq!(glb.status, 200);
        let (json, _) = common::gltf::chunks(&glb.body);
        let indices: u64 = json["meshes"]
            .as_array()
            .unwrap()
            .iter()
            .map(|m| {
                let a = m["primitives"][0]["indices"].as_u64().unwrap() as usize;
                json["accessors"][a]["count"].as_u64().unwrap()
            })
            .sum();
        assert_eq!(
            report[name]["triangles"].as_u64(),
            Some(indices / 3),
            "{name}"
        );
        let budget = &json["scenes"][0]["extras"]["fmrh"]["tin_max_error_m"];
        assert_eq!(budget.as_f64(), (name == "tin").then_some(5.0), "{name}");
    }

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

/// One camera for every picture (issue 40): the viewer, looking north at the asymmetric
/// scene of `common::tower`, draws the tower on the right and the ridge on the left, where
/// `View::project` (the camera of `fmrh render`, `fmrh mesh` and the selection) puts them.
/// Checked twice: the page's own transformation (`fmrhViewer.project`, what its shader
/// does) against `View::project`, and the pixels where screenshots with and without each
/// feature differ: the tower alone and the ridge alone, each against flat ground (shaded
/// by height, a feature's colour depends on the container's height range; the ground, the
/// lowest height in each, is drawn alike in all).
#[test]
fn the_viewer_draws_each_feature_on_the_side_the_camera_puts_it() {
    use common::tower::{self, RIDGE, RIDGE_M, TOWER, TOWER_M};
    let dir = tempfile::tempdir().unwrap();
    let [_, ridge_only, tower_only] = tower::containers(dir.path());
    let flat = dir.path().join("flat.fmrh");
    tower::container(tower::field(false, false), &flat);
    let files = [flat, tower_only, ridge_only];
    let served = Served::start(&[&files[0], &files[1], &files[2]]);
    // The page's canvas and field of view.
    let camera = fmrh::scene::Camera {
        fov_y_deg: 60.0,
        ..tower::camera([960, 600])
    };
    let view = camera.view().unwrap();
    let tops = [top_of_json(TOWER, TOWER_M), top_of_json(RIDGE, RIDGE_M)];
    let points = serde_json::to_string(&tops).unwrap();
    let mut shots = Vec::new();
    for file in &files {
        let name = file.file_name().unwrap().to_str().unwrap();
        let shot = file.with_extension("png");
        let url = format!(
            "{}/#item={name}&eye={}&target={}&tau=1&colour=shaded",
            served.base(),
            tower::EYE,
            tower::TARGET
        );
        let report = node("viewer-shot.mjs", &[&url, shot.to_str().unwrap(), &points]);
        for (i, top) in tops.iter().enumerate() {
            let at = glam::DVec3::new(top[0], top[1], top[2]);
            let [x, y, _] = view.project(at).unwrap();
            let page = &report["projected"][i];
            let (px, py) = (page[0].as_f64().unwrap(), page[1].as_f64().unwrap());
            assert!(
                (px - x).abs() < 0.01 && (py - y).abs() < 0.01,
                "{name}: the page puts {top:?} at ({px}, {py}), the camera at ({x}, {y})"
            );
        }
        shots.push(screenshot(&shot));
    }
    // The flat ground's one colour. Its outline against the sky is anti-aliased, and
    // differently when it is cut into other triangles: pixels near the outline (whose 3 × 3
    // neighbourhood in the flat picture is not all sky or all ground) are left out.
    let (width, height, flat_rgb) = &shots[0];
    let mut counts = std::collections::HashMap::new();
    for px in flat_rgb.chunks_exact(3) {
        if !is_sky(px) {
            *counts.entry([px[0], px[1], px[2]]).or_insert(0usize) += 1;
        }
    }
    let ground = counts
        .into_iter()
        .max_by_key(|c| c.1)
        .expect("ground drawn")
        .0;
    let centre = 480.0;
    for (other, top, right, what) in [
        (1, tops[0], true, "the tower"),
        (2, tops[1], false, "the ridge"),
    ] {
        let [px, py, _] = view.project(glam::DVec3::from_array(top)).unwrap();
        assert_eq!(px > centre, right, "{what}: projected at x = {px}");
        let b = &shots[other].2;
        let mut diff = Vec::new();
        for y in 0..*height {
            for x in PANEL..*width {
                let i = (y * width + x) * 3;
                // The 3 × 3 neighbourhood, clamped to the picture.
                let around: Vec<&[u8]> = (y.saturating_sub(1)..=(y + 1).min(height - 1))
                    .flat_map(|v| (x - 1..=(x + 1).min(width - 1)).map(move |u| (u, v)))
                    .map(|(u, v)| &flat_rgb[(v * width + u) * 3..][..3])
                    .collect();
                let outline =
                    !(around.iter().all(|p| is_sky(p)) || around.iter().all(|p| *p == ground));
                if flat_rgb[i..i + 3] != b[i..i + 3] && !outline {
                    diff.push((x as f64 + 0.5, y as f64 + 0.5));
                }
            }
        }
        assert!(diff.len() > 50, "{what}: drawn in {} pixels", diff.len());
        for &(x, _) in &diff {
            assert_eq!(
                x > centre,
                right,
                "{what}: drawn at x = {x}, projected at {px}"
            );
        }
        let lo = |f: fn(&(f64, f64)) -> f64| diff.iter().map(f).fold(f64::MAX, f64::min);
        let hi = |f: fn(&(f64, f64)) -> f64| diff.iter().map(f).fold(f64::MIN, f64::max);
        assert!(
            (lo(|d| d.0)..=hi(|d| d.0)).contains(&px) && (lo(|d| d.1)..=hi(|d| d.1)).contains(&py),
            "{what}: drawn in x {}..{}, y {}..{}; projected at ({px}, {py})",
            lo(|d| d.0),
            hi(|d| d.0),
            lo(|d| d.1),
            hi(|d| d.1)
        );
    }
}

/// The middle of a feature's top, as the page takes a point.
fn top_of_json(r: [u32; 4], h: f32) -> [f64; 3] {
    common::tower::top_of(r, h).to_array()
}
