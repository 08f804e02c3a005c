//! The flat frame against the ellipsoid, on one SRTM tile (the bundled N43E006, 1° at 43.5° N):
//! the same cameras, placed in both frames, and what each scene selects.
//!
//! A flat camera at world `(x, y, z)` is the globe camera at longitude `lon0 + x / dx · dlon`,
//! latitude `lat0 + y / dy · dlat` and height `z` (the flat frame's spacing is the tile's at
//! its middle latitude); its target likewise. Each row is an eye `D` km south of the tile's
//! south edge, `H` m up, looking at the tile's centre, tau 1 px. The columns:
//!
//! * blocks each scene selects, and how many they share (same level and position);
//! * `flat hidden`: blocks the flat scene selects that the globe shows are wholly below the
//!   horizon (the flat frame has none);
//! * `drop m`: the tile centre's height above the plane tangent to the ellipsoid below the
//!   eye, less its height in the flat frame: how far the ground has fallen away from the
//!   flat frame's plane there (`-d² / 2R` to first order);
//! * `dist err`: the flat frame's distance to the tile's centre against the true one.
//!
//! `cargo bench --bench globe_vs_flat` (bundled data only). Timings are not the point here.

use std::collections::BTreeSet;
use std::path::PathBuf;

use fmrh::globe;
use fmrh::scene::{Camera, SceneOptions, Terrain};
use glam::DVec3;

fn main() {
    let dir = tempfile::tempdir().expect("temp dir");
    let dem = PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("data/srtm3-pyhgtmap/N43E006.hgt.gz");
    let field = fmrh::ingest::load(&dem, &fmrh::ingest::IngestOptions::default()).expect("N43E006");
    let file = dir.path().join("n43.fmrh");
    fmrh::create(&file, field, &fmrh::CreateOptions::default()).expect("build");
    let store = fmrh::store::Store::open(&file).expect("open");
    let flat = Terrain::new(&store).expect("flat");
    let on_globe = Terrain::on_globe(&store).expect("globe");
    let fr = flat.frame();
    let g = store
        .header()
        .metadata
        .georeference
        .clone()
        .expect("georeferenced");
    let (w, h) = (
        store.domain().data_rect().col1,
        store.domain().data_rect().row1,
    );
    let to_globe = |p: DVec3| {
        let lon = g.origin[0] + p.x / fr.dx * g.step[0];
        let lat = g.origin[1] + p.y / fr.dy * g.step[1];
        globe::ecef_point(lon, lat, p.z)
    };
    let centre = DVec3::new(w as f64 / 2.0 * fr.dx, h as f64 / 2.0 * fr.dy, 500.0);
    println!(
        "{:>7} {:>7} | {:>6} {:>6} {:>6} | {:>11} | {:>9} {:>9}",
        "D km", "H m", "flat", "globe", "shared", "flat hidden", "drop m", "dist err"
    );
    for (d_km, h_m) in [
        (0.0, 3000.0),
        (10.0, 3000.0),
        (30.0, 3000.0),
        (100.0, 3000.0),
        (100.0, 10_000.0),
        (200.0, 10_000.0),
        (300.0, 10_000.0),
        (500.0, 10_000.0),
        (1000.0, 10_000.0),
        (1000.0, 100_000.0),
        (2000.0, 300_000.0),
    ] {
        let eye = DVec3::new(centre.x, h as f64 * fr.dy + d_km * 1000.0, h_m);
        let flat_cam = Camera::looking_at(eye, centre);
        let mut globe_cam = Camera::looking_at(to_globe(eye), to_globe(centre));
        globe_cam.up = DVec3::from(globe::up(g.origin[0] + 0.5, g.origin[1] - 0.5));
        let options = SceneOptions::new(1.0);
        let a = flat.scene(&flat_cam, &options).expect("flat scene");
        let b = on_globe.scene(&globe_cam, &options).expect("globe scene");
        let key = |s: &fmrh::scene::Scene| -> BTreeSet<(u8, u32, u32)> {
            s.blocks.iter().map(|b| (b.level, b.x, b.y)).collect()
        };
        let (ka, kb) = (key(&a), key(&b));
        let view = globe_cam.view().expect("view");
        let hidden = a
            .blocks
            .iter()
            .filter(|blk| on_globe.hidden(&view, &blk.rect(), blk.max_height))
            .count();
        // Distances to the centre in both frames.
        let flat_d = (centre - eye).length();
        let true_d = (to_globe(centre) - to_globe(eye)).length();
        let drop = {
            // Height of the centre above the plane tangent at the eye's foot.
            let foot = to_globe(DVec3::new(eye.x, eye.y, 0.0));
            let up = foot.normalize();
            (to_globe(centre) - foot).dot(up) - centre.z
        };
        println!(
            "{:>7.0} {:>7.0} | {:>6} {:>6} {:>6} | {:>11} | {:>9.1} {:>8.3}%",
            d_km,
            h_m,
            ka.len(),
            kb.len(),
            ka.intersection(&kb).count(),
            hidden,
            drop,
            (flat_d - true_d) / true_d * 100.0
        );
    }
}
