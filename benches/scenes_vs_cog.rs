//! Bytes per scene against a Cloud-Optimized GeoTIFF, at equal error: the same cameras and
//! tolerances answered by fmrh (view-dependent scene, its blocks loaded and decoded) and by
//! a COG reader that knows every tile's true error (issue 15's yardstick).
//!
//! **The COG** is made the standard way, from the same samples fmrh stores:
//! `gdal_translate -of COG -co COMPRESS=DEFLATE -co PREDICTOR=2|3 -co OVERVIEWS=AUTO` (Int16
//! for integer sources, as a GIS user would keep them). GDAL is only run here, never linked.
//!
//! **The COG reader** (written here, with the `tiff` crate): for every tile of every level
//! (the full resolution and each overview) it measures, once, the tile's true error: the
//! largest `|source - bilinear(tile)|` over the valid source samples of the tile's
//! footprint, the tile sampled on its own (pixel-is-area, edges clamped to the tile, as a
//! tile-at-a-time renderer draws it). A scene is then chosen as fmrh chooses one: from the
//! coarsest level down, a tile that meets the frustum is kept when its error covers at most
//! `tau` pixels at its distance (the same `View::screen_error`, the same boxes: footprint by
//! the source's height range), else replaced by the finer level's tiles under it. Its bytes
//! are the COG's metadata prefix (every IFD and tile index, up to the first tile) and the
//! chosen tiles; its reads, one for the prefix and one per run of touching tiles.
//!
//! **fmrh** opens the container (lean), schedules the view-dependent scene and loads its
//! blocks with touching payloads in one read (`scene::load_blocks`, gap 0), from a `pread`
//! file. Both answers meet `tau` everywhere (fmrh's errors are measured, the COG tiles' too).
//! Times are wall-clock, warm (best of 5), for open + select + read + decode; the COG's
//! decode is the `tiff` crate's DEFLATE and predictor.
//!
//! `cargo bench --bench scenes_vs_cog` (needs gdal-bin; the large DEMs need `../shared/data`).

#[path = "common/cog.rs"]
mod cog;
#[path = "common/dems.rs"]
mod dems;

use std::time::Instant;

use cog::{cog_decode, cog_reads, cog_scene, make_cog};
use fmrh::scene::{load_blocks, SceneOptions, Terrain, TerrainFrame, WorldFrame};
use fmrh::store::Store;

fn main() {
    let dir = tempfile::tempdir().expect("temp dir");
    println!(
        "| dataset | camera | tau | fmrh blocks | fmrh reads | fmrh bytes | fmrh max px | COG tiles | COG reads | COG bytes | COG max px | fmrh/COG bytes | fmrh us | COG us |"
    );
    println!("|---|---|---|---|---|---|---|---|---|---|---|---|---|---|");
    let mut ratios = Vec::new();
    for dem in dems::dems() {
        let name = dem.name;
        let Some(cog) = make_cog(dir.path(), name, &dem.source) else {
            continue;
        };
        let path = dem.build(dir.path());
        let frame = WorldFrame::new(Some(dem.spacing));
        for (cam_name, cam) in dem.cameras() {
            let view = cam.view().expect("camera");
            for tau in [0.5, 1.0, 2.0, 4.0] {
                let fmrh_run = || {
                    let store = Store::open(&path).expect("opens");
                    let terrain = Terrain::new(&store).expect("terrain");
                    let scene = terrain.scene(&cam, &SceneOptions::new(tau)).expect("scene");
                    load_blocks(&store, &scene.blocks, 0).expect("loads");
                    let r = store.open_reads();
                    let all = store.read_stats();
                    (
                        scene.blocks.len(),
                        r.reads() + all.reads(),
                        r.bytes() + all.bytes(),
                        scene.stats.max_screen_error,
                    )
                };
                let (blocks, reads, bytes, px) = fmrh_run();
                let fmrh_us = (0..5)
                    .map(|_| {
                        let t = Instant::now();
                        fmrh_run();
                        t.elapsed().as_secs_f64() * 1e6
                    })
                    .fold(f64::INFINITY, f64::min);
                let (tiles, cog_px) = cog_scene(&cog, TerrainFrame::Flat(frame), &view, tau);
                let (cog_bytes, cog_calls) = cog_reads(&cog, &tiles);
                let cog_us = (0..5)
                    .map(|_| {
                        let t = Instant::now();
                        let chosen = cog_scene(&cog, TerrainFrame::Flat(frame), &view, tau).0;
                        cog_decode(&cog, &chosen);
                        t.elapsed().as_secs_f64() * 1e6
                    })
                    .fold(f64::INFINITY, f64::min);
                let ratio = bytes as f64 / cog_bytes as f64;
                ratios.push(ratio);
                println!(
                    "| {name} | {cam_name} | {tau} | {blocks} | {reads} | {bytes} | {px:.2} | {} | {cog_calls} | {cog_bytes} | {cog_px:.2} | {ratio:.2} | {fmrh_us:.0} | {cog_us:.0} |",
                    tiles.len()
                );
            }
        }
    }
    ratios.sort_by(f64::total_cmp);
    if !ratios.is_empty() {
        println!(
            "\nfmrh bytes / COG bytes: median {:.2}, worst {:.2}, best {:.2}, {} of {} scenes at or below 1",
            ratios[ratios.len() / 2],
            ratios[ratios.len() - 1],
            ratios[0],
            ratios.iter().filter(|&&r| r <= 1.0).count(),
            ratios.len()
        );
    }
}
