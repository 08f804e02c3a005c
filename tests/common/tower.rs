//! The asymmetric scene the camera tests look at (issue 40): flat ground, an 800 m tower in
//! the east, a 300 m ridge in the north-west, seen from the south looking north. In fmrh's
//! flat frame x is east and y is south, so a camera that puts the tower on the left of its
//! picture is mirrored.

#![allow(dead_code)]

use fmrh::scene::Camera;
use fmrh::Heightfield;
use glam::DVec3;

pub const SIDE: u32 = 257;
pub const SPACING: f64 = 10.0;
/// Columns and rows (first and last, inclusive) of the tower (east of the middle) and the
/// ridge (north-west).
pub const TOWER: [u32; 4] = [180, 100, 220, 140];
pub const RIDGE: [u32; 4] = [20, 20, 80, 60];
pub const TOWER_M: f32 = 800.0;
pub const RIDGE_M: f32 = 300.0;
/// The camera of [`camera`] as the CLI and the viewer take it.
pub const EYE: &str = "1280,4000,1500";
pub const TARGET: &str = "1280,1200,0";

fn inside(r: [u32; 4], x: u32, y: u32) -> bool {
    (r[0]..=r[2]).contains(&x) && (r[1]..=r[3]).contains(&y)
}

/// Flat ground, with the tower and the ridge where asked.
pub fn field(tower: bool, ridge: bool) -> Heightfield {
    let mut f = Heightfield::from_fn(SIDE, SIDE, |x, y| {
        if tower && inside(TOWER, x, y) {
            TOWER_M
        } else if ridge && inside(RIDGE, x, y) {
            RIDGE_M
        } else {
            0.0
        }
    })
    .unwrap();
    f.metadata.spacing_m = Some([SPACING, SPACING]);
    f
}

/// South of the scene, above its middle column, looking north, on a `viewport`.
pub fn camera(viewport: [u32; 2]) -> Camera {
    Camera {
        viewport,
        ..Camera::looking_at(
            DVec3::new(1280.0, 4000.0, 1500.0),
            DVec3::new(1280.0, 1200.0, 0.0),
        )
    }
}

/// The world point at the middle of a feature's top.
pub fn top_of(r: [u32; 4], h: f32) -> DVec3 {
    DVec3::new(
        f64::from(r[0] + r[2]) / 2.0 * SPACING,
        f64::from(r[1] + r[3]) / 2.0 * SPACING,
        f64::from(h),
    )
}

/// `fmrh::create` of `field` (blocks of 17) at `path`.
pub fn container(field: Heightfield, path: &std::path::Path) {
    let options = fmrh::CreateOptions {
        block_size: 17,
        ..fmrh::CreateOptions::default()
    };
    fmrh::create(path, field, &options).unwrap();
}

/// The three containers a side test diffs: both features, no tower, no ridge, in `dir`.
pub fn containers(dir: &std::path::Path) -> [std::path::PathBuf; 3] {
    [
        ("both", true, true),
        ("no-tower", false, true),
        ("no-ridge", true, false),
    ]
    .map(|(name, tower, ridge)| {
        let file = dir.join(format!("{name}.fmrh"));
        container(field(tower, ridge), &file);
        file
    })
}
