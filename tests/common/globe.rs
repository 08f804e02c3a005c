//! Helpers for the tests on the globe: visibility from the WGS 84 formulas, and containers
//! built from the bundled geographic grids.

use std::path::{Path, PathBuf};

use fmrh::globe;
use fmrh::Heightfield;
use glam::DVec3;

/// Whether `p` (ECEF) is above the horizon from `eye`, a point below the ellipsoid counting
/// as on it (Cesium's convention).
pub fn above_horizon(eye: DVec3, p: DVec3) -> bool {
    let (lon, lat, h) = globe::geodetic(p);
    let q = globe::ecef_point(lon, lat, h.max(0.0));
    !globe::scaled_point_hidden(
        DVec3::from(globe::scaled(eye.to_array())),
        DVec3::from(globe::scaled(q.to_array())),
    )
}

/// The real DEM `rel` (bundled, else in `../shared/data`) read and built with the default
/// options into `dir/name.fmrh`: the file and the heightfield it holds.
pub fn container(dir: &Path, name: &str, rel: &str) -> (PathBuf, Heightfield) {
    let field =
        fmrh::ingest::load(&super::data(rel), &fmrh::ingest::IngestOptions::default()).unwrap();
    let file = dir.join(format!("{name}.fmrh"));
    fmrh::create(&file, field.clone(), &fmrh::CreateOptions::default()).unwrap();
    (file, field)
}
