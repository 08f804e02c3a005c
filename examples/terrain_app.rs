//! What a terrain application does with fmrh, start to finish: create a container from a DEM,
//! open it, ask for the blocks one camera needs at a 1-pixel tolerance and load them, then
//! replace a patch of terrain in a transaction while a reader keeps its snapshot.
//!
//! ```sh
//! cargo run --release --example terrain_app                 # a synthetic 1025 x 1025 terrain
//! cargo run --release --example terrain_app -- DEM [DX]     # any DEM fmrh reads, DX m apart
//! ```

use std::error::Error;
use std::path::PathBuf;

use fmrh::scene::{Camera, Scene, SceneOptions, Terrain};
use fmrh::store::Source;
use fmrh::{Container, CreateOptions, Heightfield, Store};
use glam::DVec3;

fn main() -> Result<(), Box<dyn Error>> {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let mut dem = match args.first() {
        Some(path) => fmrh::ingest::load(&PathBuf::from(path), &Default::default())?,
        None => synthetic(1025)?,
    };
    if let Some(dx) = args.get(1) {
        let dx: f64 = dx.parse()?;
        dem.metadata.spacing_m = Some([dx, dx]);
    }
    let dir = tempfile::tempdir()?;
    let path = dir.path().join("terrain.fmrh");

    // 1. Create: blocks, measured errors, clusters, one checksummed file, written atomically.
    let written = fmrh::create(&path, dem, &CreateOptions::default())?;
    println!("created {} ({} bytes)", path.display(), written.file_length);

    // 2. Read: the blocks one camera needs, each within 1 pixel of screen-space error.
    let store = Store::open(&path)?;
    let d = *store.domain();
    let spacing = store.header().metadata.spacing_m.unwrap_or([1.0, 1.0]);
    let (w, h) = (
        f64::from(d.width()) * spacing[0],
        f64::from(d.height()) * spacing[1],
    );
    let (lo, hi) = Terrain::new(&store)?.height_range();
    // A low pass over the south edge, looking north across the terrain.
    let camera = Camera::looking_at(
        DVec3::new(0.4 * w, -0.02 * h, f64::from(hi) + 100.0),
        DVec3::new(0.5 * w, 0.6 * h, f64::from(lo)),
    );
    let scene = Terrain::new(&store)?.scene(&camera, &SceneOptions::new(1.0))?;
    let loaded = load_blocks(&store, &scene)?;
    println!(
        "scene: {} blocks, {} heights loaded, largest error {:.3} m ({:.2} px), scheduled in {} µs",
        scene.blocks.len(),
        loaded.len(),
        scene.stats.max_error,
        scene.stats.max_screen_error,
        scene.stats.schedule_ns / 1000
    );

    // 3. Write while reading: a snapshot keeps its state while a transaction commits.
    let container = Container::open(&path)?;
    let before = container.read()?;
    let before_sum = checksum(&load_blocks(&*before, &scene)?);
    let pad = Heightfield::from_fn(64, 64, |_, _| lo)?; // a flat pad at the lowest height
    let mut txn = container.begin_write()?;
    txn.replace_region(u64::from(d.width()) / 2, u64::from(d.height()) / 2, &pad)?;
    let summary = txn.commit()?;
    println!(
        "committed txn {}: {} blocks and {} grids rewritten, {} nodes changed",
        summary.txn_id, summary.blocks, summary.grids, summary.nodes_changed
    );
    let after = container.read()?;
    let after_scene = Terrain::new(&*after)?.scene(&camera, &SceneOptions::new(1.0))?;
    let after_sum = checksum(&load_blocks(&*after, &after_scene)?);
    let still = checksum(&load_blocks(&*before, &scene)?);
    println!(
        "the old snapshot (txn {}) still reads the same heights: {}; the new state (txn {}) differs: {}",
        before.txn_id(),
        still == before_sum,
        after.txn_id(),
        after_sum != before_sum
    );
    drop((before, after));
    container.close()?;
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

/// Every height the scene's blocks draw: coarse grids at their level, physical blocks at full
/// resolution (voids replaced by their stand-ins). Each payload is CRC-checked as it is read.
fn load_blocks<S: Source>(store: &Store<S>, scene: &Scene) -> fmrh::Result<Vec<f32>> {
    let finest = store.domain().finest_level();
    let mut heights = Vec::new();
    for b in &scene.blocks {
        if b.level == finest {
            heights.extend(store.block(b.x, b.y)?.view().mended());
        } else if let Some(i) = b.node {
            heights.extend(store.grid(&store.node(i)?)?.view().expanded());
        }
    }
    Ok(heights)
}

fn checksum(heights: &[f32]) -> u64 {
    heights.iter().fold(0xcbf2_9ce4_8422_2325, |h, v| {
        (h ^ u64::from(v.to_bits())).wrapping_mul(0x100_0000_01b3)
    })
}
