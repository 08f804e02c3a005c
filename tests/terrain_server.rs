//! `fmrh serve`'s Cesium terrain (`/NAME/layer.json`, `/NAME/Z/X/Y.terrain`), asked as
//! CesiumJS asks and read back by the reference decoder (`common::quantized_mesh`, written
//! from the public specification):
//!
//! * `layer.json` is TileJSON as `CesiumTerrainProvider` reads it, its `available` levels
//!   exactly the tiles that meet the data, down to two levels past the one whose 65² grid
//!   is as fine as the data's samples, and its tiles' addresses carry the state's version;
//! * every tile of the pyramid's deepest three levels (and both roots) decodes; at every
//!   source sample inside it the height it draws is within the error its metadata declares;
//!   two neighbours have the same vertices at the same heights along their common edge; the
//!   header's sphere holds every vertex, its height range every height, and its horizon
//!   occlusion point is above the horizon from any camera that sees a vertex;
//! * answers carry `ETag`, CORS headers, `Vary`, gzip when asked; a matching
//!   `If-None-Match` gets `304` and no body;
//! * after an edit (`Terrain::edit`, a committed replace) the layer's version changes, a
//!   tile the edit did not touch keeps its `ETag`, and a tile over it draws the new heights
//!   under a new one;
//! * the coarse levels are cut ahead at start and after each commit, with every
//!   combination of extensions, the same bytes a server that does not warm cuts on request;
//! * with `--vertical-datum egm96` every height is lifted by the EGM96 undulation, within
//!   the declared error of the source plus `N`; `egm2008` is refused (no grid bundled);
//! * bad requests (unknown names, levels past the deepest, columns past the level, wrong
//!   extensions, `..`, absurd `Accept` headers, a terrain with no georeference) get 4xx.

mod common;

use std::collections::BTreeMap;
use std::io::Read;
use std::path::{Path, PathBuf};

use common::quantized_mesh::{decode, ecef, scaled, visible, Source, Tile};
use common::serve::Served;
use fmrh::heightfield::Georeference;
use fmrh::{CreateOptions, Heightfield, Terrain};

const STEP: f64 = 1.0 / 1200.0;
const CESIUM_ACCEPT: &str = "application/vnd.quantized-mesh;extensions=octvertexnormals-watermask-metadata,application/octet-stream;q=0.9,*/*;q=0.01";

/// A georeferenced field: hills, a cliff and a spike, north-west sample at `lon`, `lat`.
fn field(lon: f64, lat: f64) -> Heightfield {
    let (w, h) = (193u32, 161u32);
    let mut f = Heightfield::from_fn(w, h, |x, y| {
        let (fx, fy) = (f64::from(x), f64::from(y));
        let hills = 300.0 + 120.0 * (fx * 0.07).sin() * (fy * 0.05).cos();
        let cliff = if x > 120 { 400.0 } else { 0.0 };
        let spike = if (x, y) == (60, 40) { 900.0 } else { 0.0 };
        (hills + cliff + spike) as f32
    })
    .unwrap();
    f.metadata.georeference = Some(Georeference {
        crs: Some("EPSG:4326".into()),
        origin: [lon, lat],
        step: [STEP, -STEP],
    });
    f.metadata.spacing_m =
        fmrh::crs::Crs::from_epsg(4326).and_then(|c| c.spacing([STEP, -STEP], lat));
    f
}

fn container(dir: &Path, name: &str, f: &Heightfield) -> PathBuf {
    let path = dir.join(name);
    fmrh::create(
        &path,
        f.clone(),
        &CreateOptions {
            block_size: 33,
            ..CreateOptions::default()
        },
    )
    .unwrap();
    path
}

fn gunzip(bytes: &[u8]) -> Vec<u8> {
    let mut out = Vec::new();
    flate2::read::GzDecoder::new(bytes)
        .read_to_end(&mut out)
        .expect("a gzip body");
    out
}

/// The tiles `available` lists at level `z`.
fn level(available: &serde_json::Value, z: usize) -> Vec<(u32, u32)> {
    let mut out = Vec::new();
    for r in available[z].as_array().unwrap() {
        let g = |k: &str| r[k].as_u64().unwrap() as u32;
        for y in g("startY")..=g("endY") {
            for x in g("startX")..=g("endX") {
                out.push((x, y));
            }
        }
    }
    out
}

fn get_tile(served: &Served, path: &str) -> common::serve::Answer {
    served.ask(
        "GET",
        path,
        &[
            ("Accept", CESIUM_ACCEPT),
            ("Accept-Encoding", "gzip, deflate"),
        ],
    )
}

#[test]
fn a_served_pyramid_keeps_its_promises() {
    let dir = tempfile::tempdir().unwrap();
    let f = field(7.25, 45.4);
    let path = container(dir.path(), "alps.fmrh", &f);
    let source = Source::of(&f);
    let served = Served::start(&[&path]);
    let layer = served.get("/alps.fmrh/layer.json");
    assert_eq!(layer.status, 200);
    assert_eq!(layer.header("access-control-allow-origin"), Some("*"));
    let layer = layer.json();
    assert_eq!(layer["format"], "quantized-mesh-1.0");
    assert_eq!(layer["scheme"], "tms");
    assert_eq!(layer["projection"], "EPSG:4326");
    assert_eq!(layer["tiles"][0], "{z}/{x}/{y}.terrain?v={version}");
    let version = layer["version"].as_str().unwrap().to_string();
    let maxzoom = layer["maxzoom"].as_u64().unwrap() as usize;
    // The data's level is the first whose 65² grid steps are at most the data's; the
    // deepest is `FINER` past it.
    let grid_step = |z: usize| 180.0 / f64::from(1u32 << z) / 64.0;
    let data_level = maxzoom - usize::from(fmrh::export::tileset::FINER);
    assert!(grid_step(data_level) <= STEP && grid_step(data_level - 1) > STEP);
    assert_eq!(
        layer["fmrh"]["data_level"].as_u64(),
        Some(data_level as u64)
    );
    let bounds: Vec<f64> = layer["bounds"]
        .as_array()
        .unwrap()
        .iter()
        .map(|v| v.as_f64().unwrap())
        .collect();
    let available = &layer["available"];
    assert_eq!(available.as_array().unwrap().len(), maxzoom + 1);
    assert_eq!(level(available, 0), vec![(0, 0), (1, 0)]);
    let mut tiles: BTreeMap<(u32, u32, u32), Tile> = BTreeMap::new();
    for z in (maxzoom - 2..=maxzoom).chain([0]) {
        let listed = level(available, z);
        for &(x, y) in &listed {
            let b = common::quantized_mesh::bounds(z as u32, x, y);
            // Listed exactly where the data is.
            if z > 0 {
                assert!(
                    b[0] < bounds[2] && b[2] > bounds[0] && b[1] < bounds[3] && b[3] > bounds[1]
                );
            }
            let answer = get_tile(
                &served,
                &format!("/alps.fmrh/{z}/{x}/{y}.terrain?v={version}"),
            );
            assert_eq!(
                answer.status,
                200,
                "{}",
                String::from_utf8_lossy(&answer.body)
            );
            assert_eq!(answer.header("content-encoding"), Some("gzip"));
            assert_eq!(answer.header("access-control-allow-origin"), Some("*"));
            assert_eq!(
                answer.header("content-type"),
                Some("application/vnd.quantized-mesh;extensions=octvertexnormals-metadata")
            );
            assert_eq!(
                answer.header("cache-control"),
                Some("public, max-age=86400")
            );
            assert!(answer.header("vary").is_some_and(|v| v.contains("Accept")));
            let etag = answer.header("etag").unwrap().to_string();
            // Revalidation.
            let again = served.ask(
                "GET",
                &format!("/alps.fmrh/{z}/{x}/{y}.terrain?v={version}"),
                &[
                    ("Accept", CESIUM_ACCEPT),
                    ("Accept-Encoding", "gzip"),
                    ("If-None-Match", &etag),
                ],
            );
            assert_eq!(again.status, 304);
            assert!(again.body.is_empty());
            let d = decode(&gunzip(&answer.body));
            assert!(d.normals.is_some());
            tiles.insert((z as u32, x, y), Tile::new(z as u32, x, y, d));
        }
    }
    // The roots list every level below them.
    let root = &tiles[&(0, 1, 0)];
    let meta = root.d.metadata.as_ref().unwrap();
    assert_eq!(meta["available"].as_array().unwrap().len(), maxzoom);
    for (&(z, x, y), tile) in &tiles {
        let declared = tile.meta()["error"].as_f64().unwrap();
        let [w, s, e, n] = tile.bounds();
        let mut measured = 0u64;
        for (k, &[lon, lat]) in source.lon_lat.iter().enumerate() {
            if !(lon >= w && lon <= e && lat >= s && lat <= n) {
                continue;
            }
            let truth = f64::from(source.samples[k]);
            let drawn = tile.height_at(lon, lat);
            assert!(
                (drawn - truth).abs() <= declared + 1e-6,
                "tile {z}/{x}/{y} draws {drawn} where the source is {truth}: past its error {declared}"
            );
            measured += 1;
        }
        assert_eq!(tile.meta()["measured_samples"].as_u64(), Some(measured));
        // Header: the sphere holds every vertex, the range every height.
        let d = &tile.d;
        let mut points = Vec::new();
        for k in 0..d.u.len() {
            let lon = w + f64::from(d.u[k]) / 32767.0 * (e - w);
            let lat = s + f64::from(d.v[k]) / 32767.0 * (n - s);
            let h = d.height(k);
            assert!(h >= f64::from(d.min_height) - 1e-6 && h <= f64::from(d.max_height) + 1e-6);
            let p = ecef(lon, lat, h);
            let dist = ((p[0] - d.sphere[0]).powi(2)
                + (p[1] - d.sphere[1]).powi(2)
                + (p[2] - d.sphere[2]).powi(2))
            .sqrt();
            assert!(
                dist <= d.sphere[3] + 1e-3,
                "a vertex outside the bounding sphere"
            );
            points.push(p);
        }
        // The horizon occlusion point is above the horizon whenever a vertex is (Cesium's
        // test), from cameras anywhere from 10 m to 30,000 km up.
        let mut rng =
            common::fields::Rng::new(u64::from(z) << 40 | u64::from(x) << 20 | u64::from(y));
        for _ in 0..40 {
            let (lon, lat) = (-180.0 + 360.0 * rng.unit(), -90.0 + 180.0 * rng.unit());
            let h = 10.0 * 10f64.powf(6.5 * rng.unit());
            let camera = scaled(ecef(lon, lat, h));
            if points.iter().any(|&p| visible(camera, scaled(p))) {
                assert!(
                    visible(camera, d.horizon),
                    "tile {z}/{x}/{y}: occlusion point hidden from {lon},{lat},{h}"
                );
            }
        }
    }
    // Shared edges, east and north neighbours.
    for (&(z, x, y), tile) in &tiles {
        for (dx, dy) in [(1u32, 0u32), (0, 1)] {
            let Some(next) = tiles.get(&(z, x + dx, y + dy)) else {
                continue;
            };
            let along = |t: &Tile, east_edge: bool, at: u16| {
                let d = &t.d;
                let mut v: Vec<(u16, f64)> = (0..d.u.len())
                    .filter(|&k| {
                        if east_edge {
                            d.u[k] == at
                        } else {
                            d.v[k] == at
                        }
                    })
                    .map(|k| (if east_edge { d.v[k] } else { d.u[k] }, d.height(k)))
                    .collect();
                v.sort_by_key(|p| p.0);
                v
            };
            let east = dx == 1;
            let (mine, theirs) = (along(tile, east, 32767), along(next, east, 0));
            assert_eq!(
                mine.iter().map(|p| p.0).collect::<Vec<_>>(),
                theirs.iter().map(|p| p.0).collect::<Vec<_>>(),
                "tiles {z}/{x}/{y} and its neighbour put different vertices on their edge"
            );
            for (a, b) in mine.iter().zip(&theirs) {
                assert!(
                    (a.1 - b.1).abs() <= 1e-6,
                    "heights {} and {} at a shared vertex",
                    a.1,
                    b.1
                );
            }
        }
    }
}

#[test]
fn an_edit_changes_the_tiles_it_touches_and_only_those() {
    let dir = tempfile::tempdir().unwrap();
    let f = field(-122.3, 47.2);
    let path = container(dir.path(), "sound.fmrh", &f);
    let served = Served::start(&[&path]);
    let layer = served.get("/sound.fmrh/layer.json").json();
    let maxzoom = layer["maxzoom"].as_u64().unwrap() as usize;
    let listed = level(&layer["available"], maxzoom);
    let before: BTreeMap<(u32, u32), (String, Vec<u8>)> = listed
        .iter()
        .map(|&(x, y)| {
            let a = get_tile(&served, &format!("/sound.fmrh/{maxzoom}/{x}/{y}.terrain"));
            assert_eq!(a.status, 200);
            (
                (x, y),
                (a.header("etag").unwrap().to_string(), gunzip(&a.body)),
            )
        })
        .collect();
    // Raise a 12 × 12 patch at the data's north-west corner by 250 m.
    let patch = Heightfield::from_fn(12, 12, |x, y| f.get(x, y).unwrap() + 250.0).unwrap();
    let terrain = Terrain::open(&path).unwrap();
    let mut edit = terrain.edit().unwrap();
    edit.replace(0, 0, patch).unwrap();
    edit.commit().unwrap();
    let after_layer = served.get("/sound.fmrh/layer.json").json();
    assert_ne!(
        after_layer["version"], layer["version"],
        "a commit must change the version"
    );
    let g = f.metadata.georeference.clone().unwrap();
    let corner = [g.origin[0] + 5.0 * STEP, g.origin[1] - 5.0 * STEP];
    let (mut changed, mut kept) = (0, 0);
    for (&(x, y), (etag, bytes)) in &before {
        let a = get_tile(&served, &format!("/sound.fmrh/{maxzoom}/{x}/{y}.terrain"));
        assert_eq!(a.status, 200);
        let [w, s, e, n] = common::quantized_mesh::bounds(maxzoom as u32, x, y);
        // Tiles whose grid or neighbours' grids could reach the patch may change.
        let (dw, dh) = (e - w, n - s);
        let near = corner[0] > w - 2.0 * dw
            && corner[0] < e + 2.0 * dw
            && corner[1] > s - 2.0 * dh
            && corner[1] < n + 2.0 * dh;
        let holds = corner[0] >= w && corner[0] <= e && corner[1] >= s && corner[1] <= n;
        if holds {
            assert_ne!(
                a.header("etag").unwrap(),
                etag,
                "the edited tile kept its ETag"
            );
            let t = Tile::new(maxzoom as u32, x, y, decode(&gunzip(&a.body)));
            let old = Tile::new(maxzoom as u32, x, y, decode(bytes));
            let rise = t.height_at(corner[0], corner[1]) - old.height_at(corner[0], corner[1]);
            assert!(
                (rise - 250.0).abs() < 30.0,
                "the tile rose {rise} m where the data rose 250 m"
            );
            changed += 1;
        } else if !near {
            assert_eq!(
                a.header("etag").unwrap(),
                etag,
                "tile {x}/{y}, away from the edit, changed"
            );
            assert_eq!(&gunzip(&a.body), bytes);
            kept += 1;
        }
    }
    assert_eq!(changed, 1);
    assert!(
        kept > 0,
        "no tile was far from the edit: the field is too small for the check"
    );
}

/// Asks tile `path` of `served` with each combination of extensions: per combination,
/// whether the cache held it, its `ETag` and its bytes.
fn every_extension(served: &Served, path: &str) -> Vec<(String, String, Vec<u8>)> {
    [
        None,
        Some("octvertexnormals"),
        Some("metadata"),
        Some("octvertexnormals-metadata"),
    ]
    .iter()
    .map(|ext| {
        let accept = ext.map(|e| format!("application/vnd.quantized-mesh;extensions={e}"));
        let headers: Vec<(&str, &str)> = accept.iter().map(|a| ("Accept", a.as_str())).collect();
        let a = served.ask("GET", path, &headers);
        assert_eq!(a.status, 200, "{path} {ext:?}");
        (
            a.header("x-fmrh-cache").unwrap_or("").to_string(),
            a.header("etag").unwrap().to_string(),
            a.body,
        )
    })
    .collect()
}

/// The coarse levels (up to five above the deepest) are cut ahead, at start and at the
/// first request after a commit, with every combination of extensions: once the server
/// says so (`fmrh: warmed ...`), each of their tiles is answered from the cache, the same
/// bytes and `ETag` a server that does not warm (`--no-warm`) cuts on request; a finer
/// tile is cut when asked.
#[test]
fn coarse_tiles_are_cut_ahead_at_start_and_after_each_commit() {
    let dir = tempfile::tempdir().unwrap();
    let f = field(-122.3, 47.2);
    let path = container(dir.path(), "sound.fmrh", &f);
    let warming = Served::start(&[&path]);
    let line = warming.wait_line("fmrh: warmed");
    let layer = warming.get("/sound.fmrh/layer.json").json();
    let maxzoom = layer["maxzoom"].as_u64().unwrap() as usize;
    let top = maxzoom - 5;
    let version = layer["version"].as_str().unwrap().to_string();
    assert!(
        line.contains(&format!("levels 0..={top}, state {version})")),
        "{line}"
    );
    let check = |warming: &Served, asking: &Served, layer: &serde_json::Value| {
        let mut tiles = 0;
        for z in 0..=top {
            for (x, y) in level(&layer["available"], z) {
                let tile = format!("/sound.fmrh/{z}/{x}/{y}.terrain");
                let warm = every_extension(warming, &tile);
                let cut = every_extension(asking, &tile);
                for (w, c) in warm.iter().zip(&cut) {
                    assert_eq!(w.0, "hit", "{tile}: not cut ahead");
                    assert_eq!(c.0, "miss", "{tile}: --no-warm cut it ahead");
                    assert_eq!((&w.1, &w.2), (&c.1, &c.2), "{tile}");
                }
                tiles += 1;
            }
        }
        tiles
    };
    let asking = Served::start_with(&[&path], &["--no-warm"]);
    let tiles = check(&warming, &asking, &layer);
    assert!(
        line.starts_with(&format!("fmrh: warmed {tiles} tiles")),
        "{line}"
    );
    let (x, y) = level(&layer["available"], top + 1)[0];
    let finer = every_extension(
        &warming,
        &format!("/sound.fmrh/{}/{x}/{y}.terrain", top + 1),
    );
    assert_eq!(finer[0].0, "miss");
    assert_eq!(finer[1].0, "miss", "another extension is another cut");

    // A commit: the first request at the new state starts its warming.
    let patch = Heightfield::from_fn(12, 12, |x, y| f.get(x, y).unwrap() + 250.0).unwrap();
    let terrain = Terrain::open(&path).unwrap();
    let mut edit = terrain.edit().unwrap();
    edit.replace(0, 0, patch).unwrap();
    edit.commit().unwrap();
    let after = warming.get("/sound.fmrh/layer.json").json();
    let (x, y) = level(&after["available"], maxzoom)[0];
    let deep = every_extension(&warming, &format!("/sound.fmrh/{maxzoom}/{x}/{y}.terrain"));
    assert_eq!(deep[0].0, "miss");
    let line = warming.wait_line("fmrh: warmed");
    let version = after["version"].as_str().unwrap();
    assert!(line.contains(&format!("state {version})")), "{line}");
    assert_eq!(check(&warming, &asking, &after), tiles);
}

#[test]
fn bad_requests_get_4xx() {
    let dir = tempfile::tempdir().unwrap();
    let f = field(7.25, 45.4);
    let path = container(dir.path(), "alps.fmrh", &f);
    let mut flat = Heightfield::from_fn(50, 50, |x, _| x as f32).unwrap();
    flat.metadata.georeference = None;
    let plain = container(dir.path(), "plain.fmrh", &flat);
    let served = Served::start(&[&path, &plain]);
    let layer = served.get("/alps.fmrh/layer.json").json();
    let maxzoom = layer["maxzoom"].as_u64().unwrap();
    let status = |p: &str| get_tile(&served, p).status;
    assert_eq!(status("/nothing/layer.json"), 404);
    assert_eq!(status("/nothing/0/0/0.terrain"), 404);
    assert_eq!(
        status(&format!("/alps.fmrh/{}/0/0.terrain", maxzoom + 1)),
        404
    );
    assert_eq!(status("/alps.fmrh/3/16/0.terrain"), 400);
    assert_eq!(status("/alps.fmrh/3/0/8.terrain"), 400);
    assert_eq!(status("/alps.fmrh/999/0/0.terrain"), 400);
    assert_eq!(status("/alps.fmrh/1/0/0.png"), 404);
    assert_eq!(status("/alps.fmrh/a/b/c.terrain"), 400);
    assert_eq!(status("/alps.fmrh/-1/0/0.terrain"), 400);
    assert_eq!(status("/alps.fmrh/../alps.fmrh/layer.json"), 404);
    assert_eq!(status("/alps.fmrh/0/0/0/0.terrain"), 404);
    // A tile of the level with no data under it.
    assert_eq!(status(&format!("/alps.fmrh/{maxzoom}/0/0.terrain")), 404);
    // No georeference: no terrain.
    let p = served.get("/plain.fmrh/layer.json");
    assert_eq!(p.status, 404);
    assert!(String::from_utf8_lossy(&p.body).contains("georeference"));
    for accept in ["image/png", "application/octet-stream;q=0", "", ";;;,,,"] {
        let a = served.ask("GET", "/alps.fmrh/0/0/0.terrain", &[("Accept", accept)]);
        assert_eq!(a.status, 406, "Accept: {accept:?}");
    }
    let long = "a".repeat(8000);
    let a = served.ask("GET", "/alps.fmrh/0/0/0.terrain", &[("Accept", &long)]);
    assert_eq!(a.status, 406);
    // No Accept at all: the tile without extensions.
    let a = served.ask("GET", "/alps.fmrh/0/0/0.terrain", &[]);
    assert_eq!(a.status, 200);
    assert_eq!(
        a.header("content-type"),
        Some("application/vnd.quantized-mesh")
    );
    assert!(decode(&a.body).metadata.is_none());
    assert_eq!(
        served.ask("POST", "/alps.fmrh/0/0/0.terrain", &[]).status,
        405
    );
    let pre = served.ask("OPTIONS", "/alps.fmrh/0/0/0.terrain", &[]);
    assert_eq!(pre.status, 204);
    assert!(pre.header("access-control-allow-methods").is_some());
}

#[test]
fn the_geoid_lifts_heights_onto_the_ellipsoid() {
    let dir = tempfile::tempdir().unwrap();
    // The Alps, where EGM96's undulation is near 50 m.
    let f = field(7.25, 45.4);
    let path = container(dir.path(), "alps.fmrh", &f);
    let source = Source::of(&f);
    let served = Served::start_with(&[&path], &["--vertical-datum", "egm96"]);
    let layer = served.get("/alps.fmrh/layer.json").json();
    assert_eq!(layer["fmrh"]["vertical_datum"], "egm96");
    let maxzoom = layer["maxzoom"].as_u64().unwrap() as usize;
    let mut checked = 0;
    for (x, y) in level(&layer["available"], maxzoom).into_iter().step_by(7) {
        let a = get_tile(&served, &format!("/alps.fmrh/{maxzoom}/{x}/{y}.terrain"));
        assert_eq!(a.status, 200);
        let tile = Tile::new(maxzoom as u32, x, y, decode(&gunzip(&a.body)));
        let error = tile.meta()["error"].as_f64().unwrap();
        let [w, s, e, n] = tile.bounds();
        for (k, &[lon, lat]) in source.lon_lat.iter().enumerate() {
            if lon >= w && lon <= e && lat >= s && lat <= n {
                let n96 = fmrh::geoid::egm96_undulation(lat, lon);
                assert!(
                    (45.0..60.0).contains(&n96),
                    "EGM96 near 7.3 E 45.3 N: {n96}"
                );
                let want = f64::from(source.samples[k]) + n96;
                let drawn = tile.height_at(lon, lat);
                assert!(
                    (drawn - want).abs() <= error + 1e-6,
                    "{drawn} drawn where the source lifted by N is {want} (error {error})"
                );
                checked += 1;
            }
        }
    }
    assert!(checked > 1000, "{checked} samples checked");
    drop(served);
    // EGM2008 heights: no grid of it is bundled, so no terrain, with the reason.
    let told = Served::start_with(&[&path], &["--vertical-datum", "egm2008"]);
    let refused = told.get("/alps.fmrh/layer.json");
    assert_eq!(refused.status, 404);
    assert!(String::from_utf8_lossy(&refused.body).contains("EGM2008"));
}
