//! `fmrh serve`'s terrain for web maps (`/NAME/terrain-rgb.json`,
//! `/NAME/terrain-rgb/Z/X/Y.png`), read back with a decoder written here from the two
//! encodings' public definitions (Mapbox terrain-RGB: `−10000 + (R·65536 + G·256 + B)·0.1`;
//! Terrarium: `R·256 + G + B/256 − 32768`) and Web Mercator's formulas:
//!
//! * the TileJSON names the encoding, tile size, zoom range and the data's bounds, and its
//!   tile address carries the state's version;
//! * on the bundled SRTM tile N43E006, at every pixel of tiles at several zooms, in both
//!   encodings and both sizes, the height is within the tile's bound (its smallest pixel on
//!   the ground: the blocks it is cut from are within it) plus half the encoding's step of
//!   the source's own surface at the pixel's centre (each sample cell's two triangles, as
//!   fmrh's surface draws them, so the bound holds between samples too), and a pixel is
//!   transparent exactly when its centre is off the data;
//! * answers carry an `ETag` (a matching `If-None-Match` gets `304`) and CORS headers;
//! * bad requests (a zoom past the deepest or past Web Mercator's, a column past the
//!   zoom, a tile off the data, another extension, an unknown encoding, size or
//!   parameter) get 4xx.

mod common;

use common::serve::Served;

const EQUATOR_M: f64 = 40_075_016.686;

/// Longitude and latitude (degrees) of the point `(fx, fy)` tiles from tile `z/x/y`'s
/// north-west corner.
fn lon_lat(z: u32, x: u32, y: u32, fx: f64, fy: f64) -> [f64; 2] {
    let n = f64::from(1u32 << z);
    let lon = (f64::from(x) + fx) / n * 360.0 - 180.0;
    let m = std::f64::consts::PI * (1.0 - 2.0 * (f64::from(y) + fy) / n);
    [lon, m.sinh().atan().to_degrees()]
}

/// The tile holding `(lon, lat)` at zoom `z`.
fn tile_of(z: u32, lon: f64, lat: f64) -> (u32, u32) {
    let n = f64::from(1u32 << z);
    let x = ((lon + 180.0) / 360.0 * n) as u32;
    let r = lat.to_radians();
    let y = ((1.0 - (r.tan() + 1.0 / r.cos()).ln() / std::f64::consts::PI) / 2.0 * n) as u32;
    (x, y)
}

fn decode(encoding: &str, px: &[u8]) -> Option<f64> {
    if px[3] == 0 {
        return None;
    }
    let (r, g, b) = (f64::from(px[0]), f64::from(px[1]), f64::from(px[2]));
    Some(match encoding {
        "mapbox" => -10_000.0 + (r * 65_536.0 + g * 256.0 + b) * 0.1,
        _ => r * 256.0 + g + b / 256.0 - 32_768.0,
    })
}

/// N43E006 (1201², 3", north-west sample at 6° E, 44° N) drawn between its samples as
/// each cell's two triangles, split from north-west to south-east: `None` off the data.
fn source_at(samples: &[f32], lon: f64, lat: f64) -> Option<f64> {
    let step = 1.0 / 1200.0;
    let (u, v) = ((lon - 6.0) / step, (44.0 - lat) / step);
    if !(0.0..=1200.0).contains(&u) || !(0.0..=1200.0).contains(&v) {
        return None;
    }
    let (i, j) = ((u as usize).min(1199), (v as usize).min(1199));
    let (fu, fv) = (u - i as f64, v - j as f64);
    let at = |i: usize, j: usize| f64::from(samples[j * 1201 + i]);
    let (nw, ne, sw, se) = (at(i, j), at(i + 1, j), at(i, j + 1), at(i + 1, j + 1));
    Some(if fu >= fv {
        (1.0 - fu) * nw + (fu - fv) * ne + fv * se
    } else {
        (1.0 - fv) * nw + (fv - fu) * sw + fu * se
    })
}

#[test]
fn served_tiles_hold_the_source_within_their_pixel() {
    let dir = tempfile::tempdir().unwrap();
    let dem = common::bundled_dir().join("srtm3-pyhgtmap/N43E006.hgt.gz");
    let file = dir.path().join("n6.fmrh");
    common::fmrh_ok(&[
        "build",
        "-q",
        dem.to_str().unwrap(),
        "-o",
        file.to_str().unwrap(),
    ]);
    let source = common::load_dem(&dem);
    let samples = source.samples();
    let served = Served::start(&[&file]);

    let tj = served.get("/n6.fmrh/terrain-rgb.json");
    assert_eq!(tj.status, 200);
    assert_eq!(tj.header("access-control-allow-origin"), Some("*"));
    let tj = tj.json();
    assert_eq!(tj["encoding"], "mapbox");
    assert_eq!(tj["tileSize"], 256);
    assert_eq!(tj["scheme"], "xyz");
    let bounds: Vec<f64> = tj["bounds"]
        .as_array()
        .unwrap()
        .iter()
        .map(|v| v.as_f64().unwrap())
        .collect();
    for (got, want) in bounds.iter().zip([6.0, 43.0, 7.0, 44.0]) {
        assert!((got - want).abs() < 1e-9, "bounds {bounds:?}");
    }
    // 3" at 43.5° N is 67 m east-west: zoom 11's 256 px pixels (55 m) are the first finer.
    let maxzoom = tj["maxzoom"].as_u64().unwrap() as u32;
    assert_eq!(maxzoom, 11);
    let version = tj["version"].as_str().unwrap().to_string();
    let template = tj["tiles"][0].as_str().unwrap();
    assert!(
        template.ends_with(&format!(
            "/n6.fmrh/terrain-rgb/{{z}}/{{x}}/{{y}}.png?v={version}"
        )),
        "{template}"
    );
    let tj512 = served
        .get("/n6.fmrh/terrain-rgb.json?encoding=terrarium&size=512")
        .json();
    assert_eq!(tj512["encoding"], "terrarium");
    assert_eq!(tj512["tileSize"], 512);
    assert_eq!(tj512["maxzoom"], 10);

    let mut checked = 0usize;
    for (z, encoding, size, lon, lat) in [
        (11, "mapbox", 256u32, 6.5, 43.5),
        (10, "terrarium", 512, 6.93, 43.02),
        (8, "mapbox", 256, 6.2, 43.9),
        (5, "terrarium", 256, 6.5, 43.5),
    ] {
        let (x, y) = tile_of(z, lon, lat);
        let path = format!(
            "/n6.fmrh/terrain-rgb/{z}/{x}/{y}.png?encoding={encoding}&size={size}&v={version}"
        );
        let a = served.get(&path);
        assert_eq!(
            a.status,
            200,
            "{path}: {}",
            String::from_utf8_lossy(&a.body)
        );
        assert_eq!(a.header("content-type"), Some("image/png"));
        assert_eq!(a.header("cache-control"), Some("public, max-age=86400"));
        let etag = a.header("etag").unwrap().to_string();
        let again = served.ask("GET", &path, &[("If-None-Match", &etag)]);
        assert_eq!(again.status, 304);
        assert!(again.body.is_empty());

        let mut reader = png::Decoder::new(std::io::Cursor::new(&a.body))
            .read_info()
            .unwrap();
        let mut buf = vec![0; reader.output_buffer_size().unwrap()];
        let info = reader.next_frame(&mut buf).unwrap();
        assert_eq!((info.width, info.height), (size, size));
        assert_eq!(info.color_type, png::ColorType::Rgba);
        // The tile's bound: its smallest pixel on the ground, at its poleward edge.
        let north = lon_lat(z, x, y, 0.0, 0.0)[1];
        let bound = EQUATOR_M * north.to_radians().cos() / (f64::from(1u32 << z) * f64::from(size));
        let half_step = if encoding == "mapbox" {
            0.05
        } else {
            0.5 / 256.0
        };
        let (mut worst, mut opaque, mut clear) = (0.0f64, 0, 0);
        for j in 0..size {
            for i in 0..size {
                let k = ((j * size + i) * 4) as usize;
                let [plon, plat] = lon_lat(
                    z,
                    x,
                    y,
                    (f64::from(i) + 0.5) / f64::from(size),
                    (f64::from(j) + 0.5) / f64::from(size),
                );
                let want = source_at(samples, plon, plat);
                match (decode(encoding, &buf[k..k + 4]), want) {
                    (Some(h), Some(s)) => {
                        let d = (h - s).abs();
                        assert!(
                            d <= bound + half_step + 1e-6,
                            "{path}: pixel ({i}, {j}) at {plon}, {plat} is {h} m where the source is {s} m (bound {bound} m)"
                        );
                        worst = worst.max(d);
                        opaque += 1;
                    }
                    (None, None) => clear += 1,
                    (got, want) => panic!("{path}: pixel ({i}, {j}) at {plon}, {plat}: {got:?} where the source has {want:?}"),
                }
            }
        }
        assert!(opaque > 0, "{path}: no pixel on the data");
        eprintln!("{path}: {opaque} pixels on the data, {clear} off it; largest |pixel - source| {worst:.2} m within a bound of {bound:.1} m");
        checked += opaque;
    }
    // 172,648 pixels lie on the data in these four tiles.
    assert!(checked > 150_000, "{checked}");
}

#[test]
fn bad_requests_get_4xx() {
    let dir = tempfile::tempdir().unwrap();
    let dem = common::bundled_dir().join("srtm3-pyhgtmap/N43E006.hgt.gz");
    let file = dir.path().join("n6.fmrh");
    common::fmrh_ok(&[
        "build",
        "-q",
        dem.to_str().unwrap(),
        "-o",
        file.to_str().unwrap(),
    ]);
    let mut field = common::fields::make(40, 30, common::fields::Character::Hills, 0.0, 1);
    field.metadata.spacing_m = Some([10.0, 10.0]);
    let plain = dir.path().join("plain.fmrh");
    fmrh::create(&plain, field, &fmrh::CreateOptions::default()).unwrap();
    let served = Served::start(&[&file, &plain]);
    let (x, y) = tile_of(8, 6.5, 43.5);
    for (path, status, says) in [
        (
            format!("/n6.fmrh/terrain-rgb/12/{x}/{y}.png"),
            404,
            "past the deepest",
        ),
        (
            format!("/n6.fmrh/terrain-rgb/30/{x}/{y}.png"),
            400,
            "zoom 30",
        ),
        (
            "/n6.fmrh/terrain-rgb/2/4/0.png".to_string(),
            400,
            "columns and rows 0..4",
        ),
        (
            "/n6.fmrh/terrain-rgb/8/0/0.png".to_string(),
            404,
            "no data in this tile",
        ),
        (format!("/n6.fmrh/terrain-rgb/8/{x}/{y}.webp"), 404, "PNG"),
        (
            format!("/n6.fmrh/terrain-rgb/8/{x}/{y}.png?encoding=rgb"),
            400,
            "encoding `rgb`",
        ),
        (
            format!("/n6.fmrh/terrain-rgb/8/{x}/{y}.png?size=300"),
            400,
            "size `300`",
        ),
        (
            format!("/n6.fmrh/terrain-rgb/8/{x}/{y}.png?colour=red"),
            400,
            "unknown parameter",
        ),
        (
            format!("/n6.fmrh/terrain-rgb/8/{x}.png"),
            400,
            "expected terrain-rgb/Z/X/Y.png",
        ),
        (
            "/n6.fmrh/terrain-rgb/a/b/c.png".to_string(),
            400,
            "expected",
        ),
        ("/nope/terrain-rgb.json".to_string(), 404, ""),
        (
            "/plain.fmrh/terrain-rgb.json".to_string(),
            404,
            "no georeference",
        ),
    ] {
        let a = served.get(&path);
        assert_eq!(
            a.status,
            status,
            "{path}: {}",
            String::from_utf8_lossy(&a.body)
        );
        assert!(
            String::from_utf8_lossy(&a.body).contains(says),
            "{path}: {}",
            String::from_utf8_lossy(&a.body)
        );
    }
    let pre = served.ask(
        "OPTIONS",
        &format!("/n6.fmrh/terrain-rgb/8/{x}/{y}.png"),
        &[],
    );
    assert_eq!(pre.status, 204);
    assert_eq!(pre.header("access-control-allow-origin"), Some("*"));
}
