//! Scenes on the globe (`Terrain::on_globe`): a geographic container's samples on the WGS 84
//! ellipsoid, cameras in Earth-centred Earth-fixed metres. For random containers anywhere
//! (over a pole, across the antimeridian, ordinary ones) and random cameras (on the ground,
//! low, from orbit, straight down or at the horizon), with distances and visibility computed
//! here from the WGS 84 formulas:
//!
//! * **one cover of what is seen**: every sample whose point (at its height) is inside the
//!   frustum and above the horizon lies in exactly one scene block, and no sample in two;
//! * **the tolerance holds at true 3D distances**: each block's `e*` seen from the eye's
//!   distance to the nearest of its grid points (their real heights, in ECEF) is within
//!   `tau` pixels;
//! * **nothing wholly below the horizon is kept**: every block's shell (its footprint up to
//!   its highest height, lifted by the margin `globe::horizon_lattice` declares for it) has
//!   a point above the horizon on a lattice of 49 x 49, while everything culled was below
//!   it (the first property).
//!
//! The same properties hold on the bundled whole-Earth grid (ETOPO1 at 0.5°, pole rows and
//! both antimeridian columns) for cameras anywhere, over the poles and from orbit.
//!
//! A horizon the test is blind to would fail the first property (a visible sample with no
//! block); a frame that measured distances on the flat grid would fail the second from
//! orbit.

mod common;

use fmrh::globe;
use fmrh::heightfield::Georeference;
use fmrh::scene::{load_blocks, Camera, SceneOptions, Terrain, PAYLOAD_GAP};
use fmrh::Heightfield;
use glam::DVec3;
use proptest::prelude::*;

/// Where a test container lies.
#[derive(Clone, Copy, Debug)]
enum Place {
    /// Its north-west sample at (lon, lat), 0.01° steps.
    Anywhere(f64, f64),
    /// Row 0 on the north pole, all longitudes, down to 80° N.
    NorthPole,
    /// From 179.5° E across the antimeridian to 180.5° (-179.5°), at `lat`.
    Antimeridian(f64),
}

fn place() -> impl Strategy<Value = Place> {
    prop_oneof![
        3 => (-180.0f64..179.0, -80.0f64..85.0).prop_map(|(lon, lat)| Place::Anywhere(lon, lat)),
        1 => Just(Place::NorthPole),
        1 => (-60.0f64..60.0).prop_map(Place::Antimeridian),
    ]
}

/// A geographic field of `w x h` samples at `place`, and the centre of its area.
fn field_at(place: Place, seed: u64) -> (Heightfield, f64, f64) {
    let (w, h, origin, step) = match place {
        Place::Anywhere(lon, lat) => (101, 81, [lon, lat], [0.01, -0.01]),
        Place::NorthPole => (129, 65, [0.0, 90.0], [360.0 / 128.0, -10.0 / 64.0]),
        Place::Antimeridian(lat) => (101, 61, [179.5, lat], [0.01, -0.01]),
    };
    let mut f = common::fields::make(w, h, common::fields::Character::Hills, 0.0, seed);
    // Hills of ±100 m on a 1,000 m plateau.
    let samples: Vec<f32> = f.samples().iter().map(|v| v * 5.0 + 1000.0).collect();
    let mut g = Heightfield::new(w, h, samples).unwrap();
    g.metadata = f.metadata.clone();
    g.metadata.georeference = Some(Georeference {
        crs: Some("EPSG:4326".into()),
        origin,
        step,
    });
    f = g;
    let centre_lon = origin[0] + step[0] * f64::from(w - 1) / 2.0;
    let centre_lat = origin[1] + step[1] * f64::from(h - 1) / 2.0;
    (f, centre_lon, centre_lat)
}

/// The ECEF point of sample `(col, row)` of `f` at its height.
fn sample_point(f: &Heightfield, col: u32, row: u32) -> DVec3 {
    let g = f.metadata.georeference.as_ref().unwrap();
    let lon = g.origin[0] + f64::from(col) * g.step[0];
    let lat = (g.origin[1] + f64::from(row) * g.step[1]).clamp(-90.0, 90.0);
    let z = f.samples()[(row * f.width() + col) as usize];
    globe::ecef_point(lon, lat, f64::from(z))
}

/// A camera: offsets of the eye from the data's centre in degrees, its height (log-uniform,
/// 30 m to 30,000 km, or 1.3 to 10 km over the data) and how it looks: at a data sample (chosen by two fractions), or along
/// a heading and pitch.
#[derive(Clone, Copy, Debug)]
struct Cam {
    dlon: f64,
    dlat: f64,
    log_h: f64,
    look: Look,
}

#[derive(Clone, Copy, Debug)]
enum Look {
    At(f64, f64),
    Along(f64, f64),
}

fn camera() -> impl Strategy<Value = Cam> {
    let look = prop_oneof![
        3 => (0.0f64..1.0, 0.0f64..1.0).prop_map(|(a, b)| Look::At(a, b)),
        1 => (0.0f64..360.0, -90.0f64..5.0).prop_map(|(h, p)| Look::Along(h, p)),
    ];
    // Anywhere from beside the data to far beyond its horizon, or low over it.
    let eye = prop_oneof![
        (-8.0f64..8.0, -8.0f64..8.0, 1.5f64..7.5),
        (-0.6f64..0.6, -0.6f64..0.6, 3.1f64..4.0),
    ];
    (eye, look).prop_map(|((dlon, dlat, log_h), look)| Cam {
        dlon,
        dlat,
        log_h,
        look,
    })
}

proptest! {
    #![proptest_config(ProptestConfig { cases: 128, ..ProptestConfig::default() })]
    #[test]
    fn globe_scenes_cover_what_is_seen_within_tau(
        place in place(), seed in 0u64..1000,
        cam in camera(),
        tau in 0.5f64..4.0,
    ) {
        let (field, lon, lat) = field_at(place, seed);
        let dir = tempfile::tempdir().unwrap();
        let file = dir.path().join("g.fmrh");
        fmrh::create(&file, field.clone(), &fmrh::CreateOptions { block_size: 17, ..fmrh::CreateOptions::default() }).unwrap();
        let store = fmrh::store::Store::open(&file).unwrap();
        let terrain = Terrain::on_globe(&store).unwrap();
        let h = 10f64.powf(cam.log_h);
        let cam_lat = (lat + cam.dlat).clamp(-89.9, 89.9);
        let camera = match cam.look {
            Look::Along(heading, pitch) => {
                Camera::on_globe(cam_lat, lon + cam.dlon, h, heading, pitch)
            }
            Look::At(a, b) => {
                let eye = globe::ecef_point(lon + cam.dlon, cam_lat, h);
                let col = (a * f64::from(field.width() - 1)) as u32;
                let row = (b * f64::from(field.height() - 1)) as u32;
                let mut c = Camera::looking_at(eye, sample_point(&field, col, row));
                c.up = DVec3::from(globe::up(lon + cam.dlon, cam_lat));
                c
            }
        };
        check_scene(&field, &store, &terrain, &camera, tau, &format!("{place:?}"))?;
    }
}

/// The bundled whole-Earth grid (ETOPO1 at 0.5°: row 0 the north pole, row 360 the south
/// pole, columns -180° to +180°) and a container of it, built once for every case.
fn whole_earth() -> &'static (tempfile::TempDir, std::path::PathBuf, Heightfield) {
    static EARTH: std::sync::OnceLock<(tempfile::TempDir, std::path::PathBuf, Heightfield)> =
        std::sync::OnceLock::new();
    EARTH.get_or_init(|| {
        let dir = tempfile::tempdir().unwrap();
        let (file, field) = common::globe::container(
            dir.path(),
            "earth",
            "etopo1-pybacktrack/etopo1-bed-0.5deg.tif",
        );
        (dir, file, field)
    })
}

/// A camera anywhere around the Earth: over the poles, across the antimeridian, from orbit
/// (up to 40,000 km) down to 100 m, looking straight down, along a heading and pitch, or at
/// a point of the globe near it.
fn earth_camera() -> impl Strategy<Value = (f64, f64, f64, Look)> {
    let lat = prop_oneof![4 => -90.0f64..=90.0, 1 => 88.0f64..=90.0, 1 => -90.0f64..=-88.0];
    let lon = prop_oneof![4 => -180.0f64..=180.0, 1 => 178.0f64..=180.0, 1 => -180.0f64..=-178.0];
    let look = prop_oneof![
        1 => Just(Look::Along(0.0, -90.0)),
        2 => (0.0f64..360.0, -90.0f64..10.0).prop_map(|(h, p)| Look::Along(h, p)),
        // A point up to 40° away in longitude and latitude.
        2 => (-40.0f64..40.0, -40.0f64..40.0).prop_map(|(a, b)| Look::At(a, b)),
    ];
    (lat, lon, 2.0f64..7.6, look)
}

proptest! {
    #![proptest_config(ProptestConfig { cases: 64, ..ProptestConfig::default() })]
    /// The properties on the whole Earth: one cover of what is seen wherever the camera is
    /// (the grid's pole rows and its two antimeridian columns included), within tau at true
    /// distances, nothing below the horizon.
    #[test]
    fn whole_earth_scenes_cover_what_is_seen_within_tau(
        (lat, lon, log_h, look) in earth_camera(),
        tau in 0.5f64..4.0,
    ) {
        let (_, file, field) = whole_earth();
        let store = fmrh::store::Store::open(file).unwrap();
        let terrain = Terrain::on_globe(&store).unwrap();
        let h = 10f64.powf(log_h);
        let lat_eye = lat.clamp(-89.999, 89.999);
        let camera = match look {
            Look::Along(heading, pitch) => {
                Camera::on_globe(lat_eye, lon, h, heading, pitch)
            }
            Look::At(dlon, dlat) => {
                let eye = globe::ecef_point(lon, lat_eye, h);
                let target = globe::ecef_point(lon + dlon, (lat + dlat).clamp(-90.0, 90.0), 0.0);
                let mut c = Camera::looking_at(eye, target);
                // Any up not along the view.
                let fwd = (target - eye).normalize_or_zero();
                let up = DVec3::from(globe::up(lon, lat_eye));
                c.up = if fwd.cross(up).length() > 1e-3 { up } else { DVec3::X.cross(fwd).normalize_or(DVec3::Y) };
                c
            }
        };
        if camera.view().is_err() {
            return Ok(()); // a degenerate camera (target at the eye): refused, not a scene
        }
        check_scene(field, &store, &terrain, &camera, tau, &format!("eye {lat},{lon},{h}"))?;
    }
}

/// Over the north pole the whole pole row is seen and owned by one block per sample; over
/// the antimeridian both of the grid's edge columns (the same meridian, -180° and +180°) are
/// seen and drawn; from orbit a hemisphere is seen, the other culled.
#[test]
fn whole_earth_over_the_pole_and_the_antimeridian() {
    let (_, file, field) = whole_earth();
    let store = fmrh::store::Store::open(file).unwrap();
    let terrain = Terrain::on_globe(&store).unwrap();
    let down = |lat: f64, lon: f64, h: f64| Camera::on_globe(lat, lon, h, 0.0, -90.0);
    let owner = |scene: &fmrh::scene::Scene, col: u64, row: u64| {
        scene
            .blocks
            .iter()
            .filter(|b| b.col0 <= col && col <= b.col1 && b.row0 <= row && row <= b.row1)
            .count()
    };
    let (w, h) = (u64::from(field.width()), u64::from(field.height()));
    let pole = down(89.999, 0.0, 3_000_000.0);
    let seen = check_scene(field, &store, &terrain, &pole, 1.0, "pole").unwrap();
    let scene = terrain.scene(&pole, &SceneOptions::new(1.0)).unwrap();
    assert!(seen > 1000, "{seen}");
    for col in 0..w {
        assert!(owner(&scene, col, 0) >= 1, "pole sample {col} not drawn");
    }
    assert!(
        (0..w).all(|c| owner(&scene, c, h - 1) == 0),
        "the south pole is hidden"
    );

    let anti = down(10.0, 180.0, 2_000_000.0);
    let seen = check_scene(field, &store, &terrain, &anti, 1.0, "antimeridian").unwrap();
    let scene = terrain.scene(&anti, &SceneOptions::new(1.0)).unwrap();
    assert!(seen > 100, "{seen}");
    assert!(owner(&scene, 0, 160) >= 1 && owner(&scene, w - 1, 160) >= 1);

    let orbit = down(43.5, 6.5, 20_000_000.0);
    let seen = check_scene(field, &store, &terrain, &orbit, 1.0, "orbit").unwrap();
    let total = (w.div_ceil(2) + 1) * (h.div_ceil(2) + 1);
    assert!(
        seen as u64 > total / 4 && (seen as u64) < total * 3 / 4,
        "{seen} of {total}"
    );
}

/// Checks the three properties of the module doc for `camera`'s scene over `store` (built
/// from `field`); returns how many of the samples it looked at are seen.
fn check_scene(
    field: &Heightfield,
    store: &fmrh::store::Store,
    terrain: &Terrain<'_, fmrh::store::FileSource>,
    camera: &Camera,
    tau: f64,
    what: &str,
) -> Result<usize, TestCaseError> {
    let eye = camera.eye;
    let view = camera.view().unwrap();
    let scene = terrain.scene(camera, &SceneOptions::new(tau)).unwrap();
    let data = store.domain().data_rect();
    // A scheduler's selection (a coarser region, horizon culling as always) is the same.
    let selected = terrain
        .scene_blocks(camera, &SceneOptions::new(tau))
        .unwrap();
    prop_assert_eq!(&selected.blocks, &scene.blocks, "{}", what);

    // One cover of what is seen.
    let (w, hgt) = (field.width(), field.height());
    let mut seen = 0;
    for row in (0..hgt).step_by(2).chain([hgt - 1]) {
        for col in (0..w).step_by(2).chain([w - 1]) {
            let (c, r) = (u64::from(col), u64::from(row));
            // Owned: the half-open footprint, plus the data's last column and row.
            let owners = scene
                .blocks
                .iter()
                .filter(|b| {
                    let x = c >= b.col0 && (c < b.col1 || (c == b.col1 && b.col1 == data.col1));
                    let y = r >= b.row0 && (r < b.row1 || (r == b.row1 && b.row1 == data.row1));
                    x && y
                })
                .count();
            prop_assert!(owners <= 1, "sample {col},{row} in {owners} blocks");
            let p = sample_point(field, col, row);
            let in_frustum = view
                .planes
                .iter()
                .all(|pl| pl.normal.dot(p) + pl.offset >= 0.0);
            if in_frustum && common::globe::above_horizon(eye, p) {
                seen += 1;
                prop_assert_eq!(
                    owners,
                    1,
                    "visible sample {},{} ({:?}) in no block",
                    col,
                    row,
                    what
                );
            }
        }
    }

    // The tolerance at true 3D distances, to the blocks' real grid points.
    let loaded = load_blocks(store, &scene.blocks, PAYLOAD_GAP).unwrap();
    let d = *store.domain();
    let g = field.metadata.georeference.clone().unwrap();
    for (b, l) in scene.blocks.iter().zip(&loaded) {
        let s = d.stride(b.level);
        let mut nearest = f64::INFINITY;
        for j in 0..l.height {
            for i in 0..l.width {
                let (c, r) = (b.col0 + u64::from(i) * s, b.row0 + u64::from(j) * s);
                if c > data.col1 || r > data.row1 {
                    continue;
                }
                let z = l.heights[(j * l.width + i) as usize];
                let lon = g.origin[0] + c as f64 * g.step[0];
                let lat = (g.origin[1] + r as f64 * g.step[1]).clamp(-90.0, 90.0);
                nearest = nearest.min((globe::ecef_point(lon, lat, f64::from(z)) - eye).length());
            }
        }
        let px = if b.error == 0.0 {
            0.0
        } else {
            b.error * view.lambda / nearest
        };
        prop_assert!(
            px <= tau * (1.0 + 1e-9),
            "block {} level {}: {px} px at {nearest} m",
            b.key,
            b.level
        );

        // Not wholly below the horizon: its shell's top has a visible point.
        let (lon_a, lat_a) = (
            g.origin[0] + b.col0 as f64 * g.step[0],
            g.origin[1] + b.row0 as f64 * g.step[1],
        );
        let (lon_b, lat_b) = (
            g.origin[0] + b.col1 as f64 * g.step[0],
            g.origin[1] + b.row1 as f64 * g.step[1],
        );
        let Some((_, lift)) =
            globe::horizon_lattice(lon_a, lon_b, lat_a, lat_b, f64::from(b.max_height))
        else {
            continue; // too large a cell to be culled at all
        };
        let n = 48;
        let top = f64::from(b.max_height).max(0.0) + lift;
        let visible = (0..=n).any(|i| {
            (0..=n).any(|j| {
                let lon = lon_a + (lon_b - lon_a) * f64::from(i) / f64::from(n);
                let lat =
                    (lat_a + (lat_b - lat_a) * f64::from(j) / f64::from(n)).clamp(-90.0, 90.0);
                common::globe::above_horizon(eye, globe::ecef_point(lon, lat, top))
            })
        });
        prop_assert!(
            visible,
            "block {} level {} is wholly below the horizon",
            b.key,
            b.level
        );
    }
    // Seen samples mean blocks; none seen from far beyond the horizon can still leave
    // blocks only when their shells peek above it (checked above).
    if seen > 0 {
        prop_assert!(!scene.blocks.is_empty());
    }
    Ok(seen)
}

/// The bundled SRTM tile N43E006 as a container under `dir`.
fn n43(dir: &std::path::Path) -> std::path::PathBuf {
    common::globe::container(dir, "n43", "srtm3-pyhgtmap/N43E006.hgt.gz").0
}

/// From orbit above the data the far side is culled and the scene is the coarsest block; from
/// the ground the scene is fine near the eye.
#[test]
fn orbit_and_ground_views_of_a_real_tile() {
    let dir = tempfile::tempdir().unwrap();
    let store = fmrh::store::Store::open(&n43(dir.path())).unwrap();
    let terrain = Terrain::on_globe(&store).unwrap();
    let scene_at = |lat, lon, h, heading, pitch| {
        let c = Camera::on_globe(lat, lon, h, heading, pitch);
        terrain.scene(&c, &SceneOptions::new(1.0)).unwrap()
    };
    let orbit = scene_at(43.5, 6.5, 20_000_000.0, 0.0, -90.0);
    assert_eq!(orbit.blocks.len(), 1);
    assert_eq!(orbit.blocks[0].level, 0);
    // The antipode's sky: the tile is below the horizon.
    let far = scene_at(-43.5, -173.5, 400_000.0, 0.0, -90.0);
    assert!(far.blocks.is_empty());
    let ground = scene_at(43.1, 6.5, 2500.0, 0.0, -10.0);
    let finest = store.domain().finest_level();
    assert!(ground.blocks.iter().any(|b| b.level == finest));
    assert!(ground.stats.max_screen_error <= 1.0);
}

/// For nearby cameras the flat frame and the globe agree: on N43E006, with eyes up to 30 km
/// south of the tile at 3 km, at least 85 % of the larger scene's blocks are in both, and
/// wherever two blocks of the two scenes overlap their levels differ by at most one (the
/// flat frame's one spacing against the true one, 1.7 % apart across the tile's degree of
/// latitude, moves a few blocks by a level). `benches/globe_vs_flat.rs` tabulates where the
/// flat frame breaks for distant cameras.
#[test]
fn flat_and_globe_scenes_agree_nearby() {
    let dir = tempfile::tempdir().unwrap();
    let store = fmrh::store::Store::open(&n43(dir.path())).unwrap();
    let flat = Terrain::new(&store).unwrap();
    let on_globe = Terrain::on_globe(&store).unwrap();
    let fr = flat.frame();
    let g = store.header().metadata.georeference.clone().unwrap();
    let data = store.domain().data_rect();
    let to_globe = |p: DVec3| {
        let lon = g.origin[0] + p.x / fr.dx * g.step[0];
        let lat = g.origin[1] + p.y / fr.dy * g.step[1];
        globe::ecef_point(lon, lat, p.z)
    };
    let centre = DVec3::new(
        data.col1 as f64 / 2.0 * fr.dx,
        data.row1 as f64 / 2.0 * fr.dy,
        500.0,
    );
    for d_km in [0.0, 10.0, 30.0] {
        let eye = DVec3::new(centre.x, data.row1 as f64 * fr.dy + d_km * 1000.0, 3000.0);
        let a = flat
            .scene(&Camera::looking_at(eye, centre), &SceneOptions::new(1.0))
            .unwrap();
        let mut c = Camera::looking_at(to_globe(eye), to_globe(centre));
        c.up = DVec3::from(globe::up(6.5, 43.5));
        let b = on_globe.scene(&c, &SceneOptions::new(1.0)).unwrap();
        let ids = |s: &fmrh::scene::Scene| -> std::collections::BTreeSet<(u8, u32, u32)> {
            s.blocks.iter().map(|b| (b.level, b.x, b.y)).collect()
        };
        let shared = ids(&a).intersection(&ids(&b)).count();
        let larger = a.blocks.len().max(b.blocks.len());
        assert!(
            shared as f64 >= 0.85 * larger as f64,
            "{d_km} km: {shared} shared of {} and {}",
            a.blocks.len(),
            b.blocks.len()
        );
        for x in &a.blocks {
            for y in &b.blocks {
                let overlap =
                    x.col0 < y.col1 && y.col0 < x.col1 && x.row0 < y.row1 && y.row0 < x.row1;
                if overlap {
                    assert!(
                        x.level.abs_diff(y.level) <= 1,
                        "{d_km} km: levels {} and {}",
                        x.level,
                        y.level
                    );
                }
            }
        }
    }
}

/// `fmrh scene --eye-geo LAT,LON,H --look HEADING,PITCH` (and `--globe` with ECEF
/// `--eye`/`--target`) gives the library's globe scene; what cannot be placed on the globe
/// is refused with a clear error and a non-zero exit.
#[test]
fn the_cli_takes_cameras_on_the_globe() {
    let dir = tempfile::tempdir().unwrap();
    let dem = common::data("srtm3-pyhgtmap/N43E006.hgt.gz");
    let file = dir.path().join("n43.fmrh");
    let built = common::fmrh(&[
        "build",
        dem.to_str().unwrap(),
        "-o",
        file.to_str().unwrap(),
        "-q",
    ]);
    assert!(built.status.success());
    let f = file.to_str().unwrap();
    let run = |args: &[&str]| common::fmrh(&[&["scene", f][..], args].concat());
    let json = |o: &std::process::Output| -> serde_json::Value {
        assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
        serde_json::from_slice(&o.stdout).unwrap()
    };
    let geo = json(&run(&[
        "--eye-geo",
        "43.1,6.5,2500",
        "--look",
        "0,-10",
        "--tau",
        "1",
        "--json",
    ]));
    let (eye, target, up) = globe::look(43.1, 6.5, 2500.0, 0.0, -10.0);
    let store = fmrh::store::Store::open(&file).unwrap();
    let mut c = Camera::looking_at(eye, target);
    c.up = up;
    let scene = Terrain::on_globe(&store)
        .unwrap()
        .scene(&c, &SceneOptions::new(1.0))
        .unwrap();
    let blocks = geo["blocks"].as_array().unwrap();
    assert_eq!(blocks.len(), scene.blocks.len());
    for (j, b) in blocks.iter().zip(&scene.blocks) {
        assert_eq!(j["key"].as_u64(), Some(b.key));
    }
    // The same camera as ECEF vectors.
    let v = |p: DVec3| format!("{},{},{}", p.x, p.y, p.z);
    let ecef = json(&run(&[
        "--globe",
        "--eye",
        &v(eye),
        "--target",
        &v(target),
        "--up",
        &v(up),
        "--tau",
        "1",
        "--json",
    ]));
    assert_eq!(ecef["blocks"], geo["blocks"]);
    // Refusals.
    let bad = run(&["--eye-geo", "95,6.5,100", "--tau", "1"]);
    assert!(!bad.status.success() && String::from_utf8_lossy(&bad.stderr).contains("latitude"));
    let both = run(&[
        "--eye-geo",
        "43,6.5,100",
        "--eye",
        "0,0,0",
        "--target",
        "1,1,1",
        "--tau",
        "1",
    ]);
    assert!(!both.status.success());
    let look_alone = run(&[
        "--eye", "0,0,0", "--target", "1,1,1", "--look", "0,-10", "--tau", "1",
    ]);
    assert!(
        !look_alone.status.success()
            && String::from_utf8_lossy(&look_alone.stderr).contains("eye-geo"),
        "{}",
        String::from_utf8_lossy(&look_alone.stderr)
    );
    let mut field = common::fields::make(64, 64, common::fields::Character::Hills, 0.0, 1);
    field.metadata.spacing_m = Some([10.0, 10.0]);
    let plain = dir.path().join("plain.fmrh");
    fmrh::create(&plain, field, &fmrh::CreateOptions::default()).unwrap();
    let r = common::fmrh(&[
        "scene",
        plain.to_str().unwrap(),
        "--eye-geo",
        "43,6.5,100",
        "--tau",
        "1",
    ]);
    assert!(!r.status.success() && String::from_utf8_lossy(&r.stderr).contains("georeference"));
    // `fmrh mesh` meshes a globe scene (tests/gltf.rs checks its vertices); `fmrh render`
    // does not draw one yet, and says so.
    let glb = dir.path().join("x.glb");
    let m = common::fmrh(&[
        "mesh",
        f,
        "--eye-geo",
        "43.1,6.5,2500",
        "--tau",
        "1",
        "-o",
        glb.to_str().unwrap(),
    ]);
    assert!(m.status.success(), "{}", String::from_utf8_lossy(&m.stderr));
    assert!(glb.exists());
    let png = dir.path().join("x.png");
    let r = common::fmrh(&[
        "render",
        f,
        "--eye-geo",
        "43.1,6.5,2500",
        "--tau",
        "1",
        "-o",
        png.to_str().unwrap(),
    ]);
    assert!(!r.status.success() && String::from_utf8_lossy(&r.stderr).contains("flat-frame"));
    assert!(!png.exists());
}

/// `fmrh fly --geo` replays a path of cameras on the globe (latitude, longitude, height,
/// heading, pitch) from orbit to the ground through the frame scheduler: each frame shows
/// exactly the blocks of that camera's scene on the globe, loads only what the frame before
/// did not hold, and a malformed line or a flat-frame option is refused.
#[test]
fn a_geographic_path_flies_from_orbit_to_the_ground() {
    let dir = tempfile::tempdir().unwrap();
    let file = n43(dir.path());
    let heights = [2.0e7, 5.0e6, 1.0e6, 2.0e5, 5.0e4, 1.0e4, 3.0e3, 1.0e3];
    let lines: Vec<String> = heights
        .iter()
        .enumerate()
        .map(|(i, h)| format!("43.3,6.4,{h},30,{}", -90.0 + 8.0 * i as f64))
        .collect();
    let path = dir.path().join("orbit.csv");
    std::fs::write(
        &path,
        format!("lat,lon,h,heading,pitch\n{}\n", lines.join("\n")),
    )
    .unwrap();
    let out = common::ok_json(&common::fmrh(&[
        "fly",
        file.to_str().unwrap(),
        "--path",
        path.to_str().unwrap(),
        "--geo",
        "--tau",
        "1",
        "--json",
    ]));
    let frames = out["frames"].as_array().unwrap();
    assert_eq!(frames.len(), heights.len());
    // The library's scheduler and scenes, frame by frame.
    let store = std::sync::Arc::new(fmrh::store::Store::open(&file).unwrap());
    let options = fmrh::scene::ScheduleOptions {
        globe: true,
        ..fmrh::scene::ScheduleOptions::new(1.0)
    };
    let mut scheduler =
        fmrh::scene::Scheduler::new(std::sync::Arc::clone(&store), options).unwrap();
    let terrain = Terrain::on_globe(&store).unwrap();
    let mut held = std::collections::BTreeSet::new();
    for (i, h) in heights.iter().enumerate() {
        let c = Camera::on_globe(43.3, 6.4, *h, 30.0, -90.0 + 8.0 * i as f64);
        let scene = terrain.scene(&c, &SceneOptions::new(1.0)).unwrap();
        let want: std::collections::BTreeSet<(u8, u32, u32)> =
            scene.blocks.iter().map(|b| (b.level, b.x, b.y)).collect();
        assert!(!want.is_empty(), "frame {i} sees the tile");
        let f = scheduler.frame(&c).unwrap();
        let got: std::collections::BTreeSet<(u8, u32, u32)> = f
            .load
            .iter()
            .chain(&f.keep)
            .map(|b| (b.level, b.x, b.y))
            .collect();
        assert_eq!(got, want, "frame {i}");
        let loaded: std::collections::BTreeSet<(u8, u32, u32)> =
            f.load.iter().map(|b| (b.level, b.x, b.y)).collect();
        assert!(loaded.is_disjoint(&held), "frame {i} loads what it held");
        held = got;
        let j = &frames[i];
        assert_eq!(j["visible"].as_u64(), Some(want.len() as u64), "frame {i}");
        assert_eq!(j["loaded"].as_u64(), Some(f.stats.loaded), "frame {i}");
        assert!(j["max_screen_error"].as_f64().unwrap() <= 1.0);
    }
    // Refusals: a line that is not five numbers, a latitude off the globe, --spacing.
    for (text, extra) in [
        ("43.3,6.4,1000,30\n", None),
        ("95,6.4,1000,30,-20\n", None),
        ("43.3,6.4,1000,30,-20\n", Some("90")),
    ] {
        std::fs::write(&path, text).unwrap();
        let mut args = vec![
            "fly",
            file.to_str().unwrap(),
            "--path",
            path.to_str().unwrap(),
            "--geo",
            "--tau",
            "1",
        ];
        if let Some(s) = extra {
            args.extend(["--spacing", s]);
        }
        let r = common::fmrh(&args);
        assert_eq!(r.status.code(), Some(2), "{text}");
    }
}
