//! What a terrain application does with fmrh, start to finish, through the crate root only:
//! create a container from a DEM, open it, ask for the blocks one camera needs at a 1-pixel
//! tolerance with their decoded heights, then replace a patch of terrain atomically while the
//! terrain opened before keeps reading its state. CI builds and runs this file as an outside
//! crate would, with fmrh's default features, so it cannot lean on anything internal.
//!
//! ```sh
//! cargo run --release --example terrain_app                 # a synthetic 1025 x 1025 terrain
//! cargo run --release --example terrain_app -- DEM [DX]     # any DEM fmrh reads, DX m apart
//! ```

use std::error::Error;
use std::path::Path;

use fmrh::glam::DVec3;
use fmrh::types::IngestOptions;
use fmrh::{Camera, CreateOptions, Heightfield, Scene, SceneOptions, Terrain};

fn main() -> Result<(), Box<dyn Error>> {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let dir = tempfile::tempdir()?;
    let path = dir.path().join("terrain.fmrh");

    // 1. Create: blocks, measured errors, error levels, one checksummed file, atomically.
    let created = match args.first() {
        Some(dem) => fmrh::build(
            Path::new(dem),
            &path,
            &IngestOptions::default(),
            &CreateOptions::default(),
        )?,
        None => fmrh::create(&path, synthetic(1025)?, &CreateOptions::default())?,
    };
    println!("created {} ({} bytes)", path.display(), created.file_length);

    // 2. Read: the blocks one camera needs, each within 1 pixel, with their heights.
    let mut terrain = Terrain::open(&path)?;
    if let Some(dx) = args.get(1) {
        let dx: f64 = dx.parse()?;
        terrain.set_spacing(Some([dx, dx]))?;
    }
    let info = terrain.info()?;
    let spacing = info.spacing_m.unwrap_or([1.0, 1.0]);
    if info.spacing_m.is_none() {
        terrain.set_spacing(Some(spacing))?;
    }
    let (w, h) = (
        info.width as f64 * spacing[0],
        info.height as f64 * spacing[1],
    );
    let [lo, hi] = info.height_range.unwrap_or([0.0, 0.0]);
    // A low pass over the south edge, looking north across the terrain.
    let camera = Camera::looking_at(
        DVec3::new(0.4 * w, -0.02 * h, f64::from(hi) + 100.0),
        DVec3::new(0.5 * w, 0.6 * h, f64::from(lo)),
    );
    let scene = terrain.scene(&camera, &SceneOptions::new(1.0))?;
    println!(
        "scene: {} blocks, {} heights decoded, largest error {:.3} m ({:.2} px), selected in {} µs",
        scene.blocks.len(),
        scene.blocks.iter().map(|b| b.heights.len()).sum::<usize>(),
        scene.stats.max_error,
        scene.stats.max_screen_error,
        scene.stats.schedule_ns / 1000
    );

    // 3. Write while reading: an edit commits atomically; the terrain opened before keeps
    //    reading the state it opened.
    let before = checksum(&scene);
    let mut edit = terrain.edit()?;
    let pad = Heightfield::from_fn(64, 64, |_, _| lo)?; // a flat pad at the lowest height
    edit.replace(info.width / 2, info.height / 2, pad)?;
    let committed = edit.commit()?;
    println!(
        "committed txn {}: {} blocks and {} grids rewritten",
        committed.txn_id, committed.blocks, committed.grids
    );
    let still = checksum(&terrain.scene(&camera, &SceneOptions::new(1.0))?);
    let mut after = Terrain::open(&path)?;
    after.set_spacing(Some(spacing))?;
    let changed = checksum(&after.scene(&camera, &SceneOptions::new(1.0))?);
    println!(
        "the terrain opened before (txn {}) still draws the same heights: {}; reopened (txn {}) it draws the pad: {}",
        info.txn_id,
        still == before,
        after.info()?.txn_id,
        changed != before
    );
    Ok(())
}

/// A terrain of `n × n` samples 10 m apart: ridges, a valley, and rough ground.
fn synthetic(n: u32) -> fmrh::Result<Heightfield> {
    let mut hf = Heightfield::from_fn(n, n, |x, y| {
        let (u, v) = (x as f32 / n as f32, y as f32 / n as f32);
        let ridges = (u * 9.0).sin() * (v * 7.0).cos() * 180.0;
        let valley = -300.0 * (-(u - 0.5).powi(2) * 40.0).exp();
        let rough = ((x * 13 + y * 7) as f32 * 0.37).sin() * (u * 50.0).cos() * 6.0;
        600.0 + ridges + valley + rough
    })?;
    hf.metadata.spacing_m = Some([10.0, 10.0]);
    Ok(hf)
}

/// Every height a scene's blocks draw, with where they draw it, folded into one number.
fn checksum(scene: &Scene) -> u64 {
    scene.blocks.iter().fold(0xcbf2_9ce4_8422_2325, |h, b| {
        let place = b.rect.col0 ^ b.rect.row0 << 20 ^ u64::from(b.level) << 40;
        b.heights.iter().fold(h ^ place, |h, v| {
            (h ^ u64::from(v.to_bits())).wrapping_mul(0x100_0000_01b3)
        })
    })
}
