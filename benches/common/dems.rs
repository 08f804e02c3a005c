//! The DEMs and cameras the read benchmarks share (`scene_reads`, `scenes_vs_cog`,
//! `speed_vs_error`): Puget Sound 1k (bundled), Puget Sound 4k and the mostly-sea SRTM1 tile
//! S46W066 (`../shared/data`, skipped with a note when absent), each with its ground
//! spacing, built into a container, and three cameras scaled to the terrain.

#![allow(dead_code)]

use std::path::{Path, PathBuf};

use glam::DVec3;

use fmrh::ingest::{load, IngestOptions};
use fmrh::model::{BuildOptions, Model};
use fmrh::scene::Camera;
use fmrh::store::{write_file, WriteOptions};
use fmrh::Heightfield;

/// A DEM, its spacing filled in, and where the cameras go.
pub struct Dem {
    pub name: &'static str,
    pub source: Heightfield,
    /// Metres east and south between samples.
    pub spacing: [f64; 2],
    /// Metres across.
    pub extent: f64,
    /// Its highest height.
    pub ground: f64,
}

impl Dem {
    pub fn new(name: &'static str, mut source: Heightfield, spacing: f64) -> Dem {
        if source.metadata.spacing_m.is_none() {
            source.metadata.spacing_m = Some([spacing, spacing]);
        }
        let s = source.metadata.spacing_m.unwrap_or([spacing, spacing]);
        let ground = source
            .samples()
            .iter()
            .filter(|v| !v.is_nan())
            .fold(0.0f32, |a, &b| a.max(b));
        Dem {
            name,
            extent: f64::from(source.width()) * s[0],
            ground: f64::from(ground),
            spacing: s,
            source,
        }
    }

    /// Builds its container (lossless, defaults) in `dir`.
    pub fn build(&self, dir: &Path) -> PathBuf {
        self.build_with(dir, "", &WriteOptions::default())
    }

    /// Builds its container in `dir` with `options`, named with `suffix`.
    pub fn build_with(&self, dir: &Path, suffix: &str, options: &WriteOptions) -> PathBuf {
        let model = Model::build(self.source.clone(), &BuildOptions::default()).expect("builds");
        let path = dir.join(format!("{}{suffix}.fmrh", self.name));
        write_file(&model, &self.source.metadata, &path, options, true).expect("writes");
        path
    }

    /// The cameras: from far above, an oblique view across, and a low pass.
    pub fn cameras(&self) -> Vec<(&'static str, Camera)> {
        let (e, g) = (self.extent, self.ground);
        vec![
            (
                "overview",
                Camera::looking_at(
                    DVec3::new(0.5 * e, 1.4 * e, 0.5 * e),
                    DVec3::new(0.5 * e, 0.5 * e, 0.0),
                ),
            ),
            (
                "oblique",
                Camera::looking_at(
                    DVec3::new(0.1 * e, 0.9 * e, g + 0.04 * e),
                    DVec3::new(0.6 * e, 0.4 * e, 0.0),
                ),
            ),
            (
                "low",
                Camera::looking_at(
                    DVec3::new(0.4 * e, 0.6 * e, g + 300.0),
                    DVec3::new(0.7 * e, 0.5 * e, g * 0.5),
                ),
            ),
        ]
    }
}

/// The DEMs: Puget Sound 1k always, the shared ones when `../shared/data` has them.
pub fn dems() -> Vec<Dem> {
    let root = PathBuf::from(env!("CARGO_MANIFEST_DIR"));
    let puget = load(
        &root.join("data/puget-sound-1k/ps_height_1k.png"),
        &IngestOptions {
            z_scale: 0.1,
            ..Default::default()
        },
    )
    .expect("bundled Puget Sound 1k");
    let mut out = vec![Dem::new("puget-1k", puget, 160.0)];
    for (name, rel, spacing) in [
        ("puget-4k", "puget-sound-4k-jpg/ps_height_4k_jpg.f32", 40.0),
        ("S46W066", "srtm1-asmyasnikov/S46W066.f32", 30.0),
    ] {
        match load(
            &root.join("../shared/data").join(rel),
            &IngestOptions::default(),
        ) {
            Ok(hf) => out.push(Dem::new(name, hf, spacing)),
            Err(e) => eprintln!("skipping {name}: {e} (../shared/data)"),
        }
    }
    out
}
