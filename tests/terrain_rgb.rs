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
//!   fmrh's surface draws them, so the bound holds between samples too), and a pixel
//!   holds the no-data fill (opaque sea level by default, `?nodata=` a height or
//!   transparent) exactly when its centre is off the data;
//! * answers carry an `ETag` (a matching `If-None-Match` gets `304`) and CORS headers, and
//!   a tile asked again comes from the server's cache, the same bytes;
//! * bad requests (a zoom past the deepest or past Web Mercator's, a column past the
//!   zoom, a tile off the data, another extension, an unknown encoding, size or
//!   parameter) get 4xx.

mod common;

use common::serve::Served;

use common::mercator::{decode, lon_lat, n43e006_at as source_at, rgba, tile_of, EQUATOR_M};

#[test]
fn served_tiles_hold_the_source_within_their_pixel() {
    let dir = tempfile::tempdir().unwrap();
    let dem = common::bundled_dir().join("srtm3-pyhgtmap/N43E006.hgt.gz");
    let file = common::pyramids::n43e006(dir.path());
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
    for (z, encoding, size, nodata, lon, lat) in [
        (11, "mapbox", 256u32, "", 6.5, 43.5),
        (10, "terrarium", 512, "&nodata=transparent", 6.93, 43.02),
        (8, "mapbox", 256, "&nodata=transparent", 6.2, 43.9),
        (5, "terrarium", 256, "", 6.5, 43.5),
        (7, "mapbox", 512, "&nodata=-20.5", 6.5, 43.5),
    ] {
        let (x, y) = tile_of(z, lon, lat);
        let path = format!(
            "/n6.fmrh/terrain-rgb/{z}/{x}/{y}.png?encoding={encoding}&size={size}{nodata}&v={version}"
        );
        // What a pixel off the data holds: opaque sea level by default, else as asked.
        let fill = match nodata {
            "" => Some(0.0),
            "&nodata=-20.5" => Some(-20.5),
            _ => None,
        };
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
        // Cut once, then from the server's cache, the same bytes.
        assert_eq!(a.header("x-fmrh-cache"), Some("miss"), "{path}");
        assert_eq!(again.header("x-fmrh-cache"), Some("hit"), "{path}");
        let third = served.get(&path);
        assert!(third.body == a.body && third.header("etag") == Some(etag.as_str()));

        let (buf, side, colour) = rgba(&a.body);
        assert_eq!(side, size);

        // The tile's bound: its smallest pixel on the ground, at its poleward edge; at the
        // deepest zoom (11 at 256 px, 10 at 512), 0: those tiles hold the data itself.
        let north = lon_lat(z, x, y, 0.0, 0.0)[1];
        let deepest = if size == 256 { 11 } else { 10 };
        let bound = if z == deepest {
            0.0
        } else {
            EQUATOR_M * north.to_radians().cos() / (f64::from(1u32 << z) * f64::from(size))
        };
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
                    (got, None) if got == fill => clear += 1,
                    (Some(h), Some(s)) => {
                        let d = (h - s).abs();
                        assert!(
                            d <= bound + half_step + 1e-6,
                            "{path}: pixel ({i}, {j}) at {plon}, {plat} is {h} m where the source is {s} m (bound {bound} m)"
                        );
                        worst = worst.max(d);
                        opaque += 1;
                    }
                    (got, want) => panic!("{path}: pixel ({i}, {j}) at {plon}, {plat}: {got:?} where the source has {want:?}"),
                }
            }
        }
        assert!(opaque > 0, "{path}: no pixel on the data");
        assert!(z > 9 || clear > 0, "{path}: no pixel off the data");
        // RGBA only when a pixel is transparent; opaque tiles are RGB.
        let transparent = fill.is_none() && clear > 0;
        assert_eq!(
            colour == png::ColorType::Rgba,
            transparent,
            "{path}: {colour:?}"
        );
        eprintln!("{path}: {opaque} pixels on the data, {clear} off it; largest |pixel - source| {worst:.2} m within a bound of {bound:.1} m");
        checked += opaque;
    }
    // Over 170,000 pixels lie on the data in these five tiles.
    assert!(checked > 150_000, "{checked}");
}

#[test]
fn bad_requests_get_4xx() {
    let dir = tempfile::tempdir().unwrap();
    let file = common::pyramids::n43e006(dir.path());
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
            format!("/n6.fmrh/terrain-rgb/8/{x}/{y}.png?nodata=inf"),
            400,
            "nodata `inf`",
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
