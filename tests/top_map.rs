//! The overhead map (`fmrh::render::top`, `fmrh render --top`) is drawn in metres on the
//! ground, north up: a geographic tile keeps its true shape (as wide as its parallels, as
//! high as its meridian, narrower at its north edge than at its south, by the ellipsoid's
//! degree lengths computed here from the textbook series, not fmrh's formula); a grid of
//! oblong samples is drawn oblong; the scale bar is a round length and as long as it says;
//! the north arrow points where the grid's CRS puts true north (the meridian convergence of
//! a UTM grid, against the closed-form formula), hollow when nothing says. Before issue 40
//! the map was drawn in samples: a one-degree tile at 43° N came out 1.37 times too wide.

mod common;

use fmrh::heightfield::Georeference;
use fmrh::render::top::{round_length, TopMap, SCALE_COLOUR};
use fmrh::render::{top, MapGround, Surface};
use fmrh::scene::{reconstruct, Camera, SceneOptions, Terrain, WorldFrame};
use fmrh::store::{Store, WriteOptions};
use fmrh::Heightfield;
use glam::DVec3;

/// What the map's background is where no terrain lies.
const BACKGROUND: [u8; 3] = [250, 250, 250];

/// Metres in a degree of longitude and of latitude at latitude `phi` (degrees) on the
/// WGS 84 ellipsoid, by the usual series (accurate to a centimetre).
fn degree_m(phi: f64) -> (f64, f64) {
    let p = phi.to_radians();
    let lon = 111_412.84 * p.cos() - 93.5 * (3.0 * p).cos() + 0.118 * (5.0 * p).cos();
    let lat =
        111_132.92 - 559.82 * (2.0 * p).cos() + 1.175 * (4.0 * p).cos() - 0.0023 * (6.0 * p).cos();
    (lon, lat)
}

/// Gentle hills (the map's colours do not matter here, only where terrain is).
fn hills(w: u32, h: u32) -> Heightfield {
    Heightfield::from_fn(w, h, |x, y| {
        50.0 * ((x as f32) * 0.1).sin() * ((y as f32) * 0.13).cos()
    })
    .unwrap()
}

/// The overhead map of all of `field` seen by a camera high above sample `(col, row)`,
/// `side` pixels on its longer side, the ground laid out as `field`'s georeference says
/// (or as `ground` overrides).
fn map_of(field: Heightfield, side: u32, ground: Option<MapGround>) -> TopMap {
    let spacing = field.metadata.spacing_m;
    let georef = field.metadata.georeference.clone();
    let (w, h) = (field.width(), field.height());
    let store = Store::from_bytes(common::bytes_of(&field, 17, &WriteOptions::default())).unwrap();
    let terrain = Terrain::with_spacing(&store, spacing).unwrap();
    let frame = WorldFrame::new(spacing);
    // Straight down from high above the middle: the eye is inside the window.
    let centre = frame.point(f64::from(w) / 2.0, f64::from(h) / 2.0, 0.0);
    let camera = Camera::looking_at(centre + DVec3::new(0.0, 1.0, 20_000.0), centre);
    let scene = terrain.scene(&camera, &SceneOptions::new(4.0)).unwrap();
    let window = store.domain().data_rect();
    let rec = reconstruct(&store, &scene, window).unwrap();
    let surface = Surface {
        window,
        heights: &rec.values,
        blocks: &scene.blocks,
        frame,
    };
    let ground = ground.unwrap_or_else(|| {
        MapGround::of(
            georef.as_ref(),
            f64::from(w - 1) / 2.0,
            f64::from(h - 1) / 2.0,
        )
    });
    top(&surface, &camera, side, ground).unwrap()
}

/// The first and last x of row `y` that show terrain (not the background).
fn drawn_span(map: &TopMap, y: u32) -> (u32, u32) {
    let xs: Vec<u32> = (0..map.image.width)
        .filter(|&x| map.image.pixel(x, y) != BACKGROUND)
        .collect();
    (*xs.first().unwrap(), *xs.last().unwrap())
}

/// A one-degree geographic tile (N43E006, 15″ samples) with its georeference and the
/// spacing an SRTM reader gives it.
fn geographic_tile() -> Heightfield {
    let mut f = hills(241, 241);
    f.metadata.georeference = Some(Georeference {
        crs: Some("EPSG:4326".into()),
        origin: [6.0, 44.0],
        step: [1.0 / 240.0, -1.0 / 240.0],
    });
    f.metadata.spacing_m = Some(fmrh::crs::geographic_spacing(
        [1.0 / 240.0, 1.0 / 240.0],
        43.5,
    ));
    f
}

#[test]
fn a_geographic_tile_keeps_its_true_shape() {
    let map = map_of(geographic_tile(), 1000, None);
    assert_eq!(map.north_deg, Some(0.0));
    // Samples are cells: the tile spans 241/240 of a degree each way.
    let span = 241.0 / 240.0;
    let (_, lat_m) = degree_m(43.5);
    let high_m = span * lat_m;
    // As high as its meridian: the longer side.
    assert_eq!(map.image.height, 1000);
    let mpp = map.metres_per_pixel;
    assert!(
        (mpp * 1000.0 / high_m - 1.0).abs() < 1e-3,
        "{mpp} m a pixel for a tile {high_m} m high"
    );
    // Each row as wide as its parallel: the widest is the south edge.
    let south = 43.0 - 0.5 / 240.0;
    let want_w = span * degree_m(south).0 / mpp;
    assert!(
        (f64::from(map.image.width) - want_w).abs() <= 1.0,
        "{} pixels wide, the south edge is {want_w}",
        map.image.width
    );
    // Rows clear of the panels, near the north and the south: their drawn widths are their
    // latitudes' (a pixel of rounding at each end).
    for y in [120u32, 500, 900] {
        let lat = 44.0 + 0.5 / 240.0 - (f64::from(y) + 0.5) * mpp / lat_m;
        let want = span * degree_m(lat).0 / mpp;
        let (x0, x1) = drawn_span(&map, y);
        let got = f64::from(x1 - x0 + 1);
        assert!(
            (got - want).abs() <= 2.0,
            "row {y} (latitude {lat:.3}): {got} pixels drawn, {want:.1} wanted"
        );
        // Centred on the middle meridian.
        let middle = f64::from(x0 + x1 + 1) / 2.0;
        assert!(
            (middle - f64::from(map.image.width) / 2.0).abs() <= 1.5,
            "row {y}: {middle}"
        );
    }
    let north = drawn_span(&map, 120);
    let south = drawn_span(&map, 900);
    assert!(
        north.1 - north.0 + 6 < south.1 - south.0,
        "the north is not narrower: {north:?} {south:?}"
    );
}

#[test]
fn a_grid_of_oblong_samples_is_drawn_oblong() {
    let mut f = hills(129, 65);
    f.metadata.spacing_m = Some([30.0, 10.0]);
    let map = map_of(f, 1000, None);
    // 3,870 m by 650 m; in samples it would be 1000 × 504.
    assert_eq!((map.image.width, map.image.height), (1000, 168));
    assert!((map.metres_per_pixel - 3.87).abs() < 1e-9);
    assert_eq!(map.north_deg, None, "nothing says where north is");
}

#[test]
fn the_scale_bar_is_a_round_length_as_long_as_it_says() {
    for (side, field) in [(1000, geographic_tile()), (600, hills(257, 257))] {
        let map = map_of(field, side, None);
        let m = map.scale_bar_m;
        let unit = 10f64.powf(m.log10().floor());
        assert!(
            [1.0, 2.0, 5.0]
                .iter()
                .any(|k| (m - k * unit).abs() < 1e-9 * m),
            "{m} m is not a round length"
        );
        let (x, y, len) = map.scale_bar_px;
        assert!(
            (len as f64 * map.metres_per_pixel - m).abs() <= map.metres_per_pixel,
            "{len} pixels of {} m are not {m} m",
            map.metres_per_pixel
        );
        // Between a tenth and a quarter of the picture's width, drawn where it says.
        let width = f64::from(map.image.width);
        assert!(
            len as f64 >= width / 10.0 && len as f64 <= width / 4.0 + 1.0,
            "{len}"
        );
        for dx in 0..len {
            assert_eq!(map.image.pixel((x + dx) as u32, y as u32), SCALE_COLOUR);
        }
    }
    assert_eq!(round_length(59_750.0), 50_000.0);
    assert_eq!(round_length(999.0), 500.0);
    assert_eq!(round_length(1.0), 1.0);
    assert_eq!(round_length(0.3), 0.2);
    assert_eq!(round_length(4.99), 2.0);
    assert_eq!(round_length(1000.0), 1000.0);
    assert_eq!(round_length(1e-3), 1e-3);
}

/// The middle of the north arrow's dark pixels, relative to its panel's middle.
fn arrow_lean(map: &TopMap) -> (f64, f64, usize) {
    let size = fmrh::render::top::ARROW_LENGTH as u32 + 12;
    let (x0, y0) = (map.image.width - 8 - size, 8);
    let (mut sx, mut sy, mut n) = (0.0, 0.0, 0usize);
    for y in y0..y0 + size {
        for x in x0..x0 + size {
            if map.image.pixel(x, y) == SCALE_COLOUR {
                sx += f64::from(x) + 0.5 - (f64::from(x0) + f64::from(size) / 2.0);
                sy += f64::from(y) + 0.5 - (f64::from(y0) + f64::from(size) / 2.0);
                n += 1;
            }
        }
    }
    (sx / n as f64, sy / n as f64, n)
}

#[test]
fn the_north_arrow_points_to_true_north() {
    // A UTM zone 10 N grid (central meridian 123° W) far east of its central meridian, at
    // E 810 km, N 5,100 km (about 119° W, 46° N): grid north is east of true north by the
    // convergence γ = atan(tan(λ − λ0) · sin φ), so true north is γ anticlockwise from up.
    let mut f = hills(201, 201);
    f.metadata.spacing_m = Some([30.0, 30.0]);
    f.metadata.georeference = Some(Georeference {
        crs: Some("EPSG:32610".into()),
        origin: [807_000.0, 5_103_000.0],
        step: [30.0, -30.0],
    });
    let centre = [807_000.0 + 100.0 * 30.0, 5_103_000.0 - 100.0 * 30.0];
    let [lon, lat] = fmrh::crs::Crs::parse("EPSG:32610")
        .unwrap()
        .to_lon_lat(centre[0], centre[1])
        .unwrap();
    assert!(
        (lon + 119.0).abs() < 0.2 && (lat - 46.0).abs() < 0.2,
        "{lon} {lat}"
    );
    let gamma = ((lon + 123.0).to_radians().tan() * lat.to_radians().sin())
        .atan()
        .to_degrees();
    let map = map_of(f, 400, None);
    let north = map.north_deg.expect("the CRS says where north is");
    assert!(
        (north + gamma).abs() < 0.01,
        "true north {north}° from up; the convergence is {gamma}°"
    );
    assert!(north < -2.5, "{north}");

    // The arrow is drawn that way: its filled head pulls its dark pixels towards its tip.
    let up = map_of(
        hills(65, 65),
        400,
        Some(MapGround::Grid {
            north_deg: Some(0.0),
        }),
    );
    let east = map_of(
        hills(65, 65),
        400,
        Some(MapGround::Grid {
            north_deg: Some(90.0),
        }),
    );
    let unknown = map_of(hills(65, 65), 400, None);
    let (ux, uy, un) = arrow_lean(&up);
    let (ex, ey, _) = arrow_lean(&east);
    assert!(
        uy < -2.0 && ux.abs() < 0.5,
        "pointing up: leans ({ux}, {uy})"
    );
    assert!(
        ex > 2.0 && ey.abs() < ex / 2.0,
        "pointing east: leans ({ex}, {ey})"
    );
    // Hollow when north is not known: fewer dark pixels, the same shaft.
    let (_, _, hollow) = arrow_lean(&unknown);
    assert!(hollow + 10 < un, "hollow {hollow}, filled {un}");
}

/// `fmrh render --top` of the bundled SRTM tile N43E006 (3″, 1201 × 1201): 512 pixels high
/// and as wide as the tile's south edge, not square; the summary says so.
#[test]
fn fmrh_render_top_draws_an_srtm_tile_in_metres() {
    let dir = tempfile::tempdir().unwrap();
    let file = dir.path().join("n43.fmrh");
    let hgt = common::bundled_dir().join("srtm3-pyhgtmap/N43E006.hgt.gz");
    let out = common::fmrh(&["build", hgt.to_str().unwrap(), "-o", file.to_str().unwrap()]);
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let png = dir.path().join("top.png");
    // Above the tile's middle (40 km east, 55 km south of its north-west corner).
    let out = common::fmrh(&[
        "render",
        file.to_str().unwrap(),
        "--eye",
        "40000,55000,30000",
        "--target",
        "40000,55100,0",
        "--tau",
        "4",
        "--top",
        "--size",
        "512",
        "-o",
        png.to_str().unwrap(),
    ]);
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let said = String::from_utf8_lossy(&out.stderr);
    assert!(
        said.contains("north up") && said.contains("scale bar"),
        "{said}"
    );
    let decoder = png::Decoder::new(std::io::BufReader::new(std::fs::File::open(&png).unwrap()));
    let info = decoder.read_info().unwrap();
    let (w, h) = (info.info().width, info.info().height);
    let want_w = 512.0 * degree_m(43.0 - 0.5 / 1200.0).0 / degree_m(43.5).1;
    assert_eq!(h, 512);
    assert!(
        (f64::from(w) - want_w).abs() <= 1.0,
        "{w} x {h}: the tile is {want_w:.1} pixels wide"
    );
}
