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
//! **Time, warm and cold** (issue 44): each scene is also timed whole (open + select +
//! read + decode, best of 5) with the file in the page cache (*warm*) and with its pages
//! dropped by `posix_fadvise(DONTNEED)` before each run (*cold*), for fmrh beside GDAL
//! reading the same COG tiles (`benches/common/cog_times.py`: open, `ReadBlock` per tile;
//! python3-gdal, one process per DEM, its start-up not counted). The `tiff`-crate reader's
//! warm time is kept as its own column. Two tables follow the per-scene one: the ratios of
//! fmrh's time to GDAL's, median and worst, warm and cold.
//!
//! **Before** (optional): with `FMRH_SCENES_BEFORE=DIR`, each DEM's container as an older
//! fmrh built it (`DIR/<dem>.fmrh`, the same model and options, e.g. a 6.2 file whose
//! residuals pco codes) is read by this fmrh beside today's build, the two runs alternated
//! within each best of 5, warm and cold; a table of today's time and bytes over the older
//! file's follows, with the two files' sizes.
//!
//! `cargo bench --bench scenes_vs_cog` (needs gdal-bin and python3-gdal; the large DEMs need
//! `../shared/data`).

#[path = "common/cog.rs"]
mod cog;
#[path = "common/dems.rs"]
mod dems;

use std::path::Path;
use std::process::Command;
use std::time::Instant;

use cog::{cog_decode, cog_reads, cog_scene, make_cog, Cog};
use fmrh::scene::{load_blocks, SceneOptions, Terrain, TerrainFrame, WorldFrame};
use fmrh::store::Store;

const TAUS: [f64; 5] = [0.5, 1.0, 2.0, 4.0, 8.0];

/// Drops the file's pages from the page cache (a cold read), as far as the kernel obliges.
fn evict(path: &Path) {
    if let Ok(f) = std::fs::File::open(path) {
        use std::os::fd::AsRawFd;
        // SAFETY: a plain advisory call on a descriptor we own; it reads no memory of ours.
        unsafe {
            libc::posix_fadvise(f.as_raw_fd(), 0, 0, libc::POSIX_FADV_DONTNEED);
        }
    }
}

/// The best of 5 runs of `run`, in microseconds, each after `before`.
fn best_us(mut before: impl FnMut(), mut run: impl FnMut()) -> f64 {
    (0..5)
        .map(|_| {
            before();
            let t = Instant::now();
            run();
            t.elapsed().as_secs_f64() * 1e6
        })
        .fold(f64::INFINITY, f64::min)
}

/// The best of 5 runs of `a` and of `b`, in microseconds, the two alternated, each run after
/// its `before`.
fn best_pair_us(
    mut before: impl FnMut(usize),
    mut a: impl FnMut(),
    mut b: impl FnMut(),
) -> (f64, f64) {
    let mut best = [f64::INFINITY; 2];
    for _ in 0..5 {
        for (i, slot) in best.iter_mut().enumerate() {
            before(i);
            let t = Instant::now();
            if i == 0 {
                a();
            } else {
                b();
            }
            *slot = slot.min(t.elapsed().as_secs_f64() * 1e6);
        }
    }
    (best[0], best[1])
}

/// The scene of `cam` at `tau` from the container at `path`, opened fresh (lean), its blocks
/// loaded and decoded: (blocks, reads, bytes, max screen error).
fn fmrh_scene(path: &Path, cam: &fmrh::scene::Camera, tau: f64) -> (usize, u64, u64, f64) {
    let store = Store::open(path).expect("opens");
    let terrain = Terrain::new(&store).expect("terrain");
    let scene = terrain.scene(cam, &SceneOptions::new(tau)).expect("scene");
    load_blocks(&store, &scene.blocks, 0).expect("loads");
    let r = store.open_reads();
    let all = store.read_stats();
    (
        scene.blocks.len(),
        r.reads() + all.reads(),
        r.bytes() + all.bytes(),
        scene.stats.max_screen_error,
    )
}

/// GDAL's (warm, cold) microseconds for each scene's tiles of `cog`.
fn gdal_times(dir: &Path, cog: &Cog, scenes: &[Vec<(usize, usize)>]) -> Vec<(f64, f64)> {
    let lists: Vec<Vec<[usize; 3]>> = scenes
        .iter()
        .map(|tiles| {
            tiles
                .iter()
                .map(|&(l, t)| {
                    let (tx, _) = cog.levels[l].tiles_across();
                    [l, t % tx, t / tx]
                })
                .collect()
        })
        .collect();
    let file = dir.join("scenes.json");
    std::fs::write(&file, serde_json::to_vec(&lists).expect("json")).expect("writes");
    let script = Path::new(env!("CARGO_MANIFEST_DIR")).join("benches/common/cog_times.py");
    let out = Command::new("/usr/bin/python3")
        .arg(&script)
        .arg(&cog.path)
        .arg(&file)
        .arg("5")
        .output()
        .expect("python3 runs (python3-gdal)");
    assert!(
        out.status.success(),
        "cog_times.py: {}",
        String::from_utf8_lossy(&out.stderr)
    );
    let v: Vec<serde_json::Value> = serde_json::from_slice(&out.stdout).expect("json");
    v.iter()
        .map(|s| {
            let t = |k: &str| s[k].as_f64().expect("seconds") * 1e6;
            (t("warm"), t("cold"))
        })
        .collect()
}

fn quantiles(mut r: Vec<f64>) -> (f64, f64, f64) {
    r.sort_by(f64::total_cmp);
    (r[r.len() / 2], r[r.len() - 1], r[0])
}

struct Row {
    line: String,
    fmrh_warm: f64,
    fmrh_cold: f64,
}

fn main() {
    let dir = tempfile::tempdir().expect("temp dir");
    println!(
        "| dataset | camera | tau | fmrh blocks | fmrh reads | fmrh bytes | fmrh max px | COG tiles | COG reads | COG bytes | COG max px | fmrh/COG bytes | fmrh us warm | fmrh us cold | GDAL us warm | GDAL us cold | tiff-crate COG us warm | fmrh/GDAL warm | fmrh/GDAL cold |"
    );
    println!("|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|");
    let mut ratios = Vec::new();
    let (mut warm_ratios, mut cold_ratios) = (Vec::new(), Vec::new());
    let before_dir = std::env::var_os("FMRH_SCENES_BEFORE").map(std::path::PathBuf::from);
    // Per scene against the older file: the line, and (warm, cold, bytes) ratios.
    let mut against_before: Vec<(String, [f64; 3])> = Vec::new();
    let mut sizes: Vec<String> = Vec::new();
    for dem in dems::dems() {
        let name = dem.name;
        let Some(cog) = make_cog(dir.path(), name, &dem.source) else {
            continue;
        };
        let path = dem.build(dir.path());
        let before = before_dir
            .as_ref()
            .map(|d| d.join(format!("{name}.fmrh")))
            .filter(|p| p.is_file());
        if let Some(old) = &before {
            let len = |p: &Path| std::fs::metadata(p).expect("a file").len();
            sizes.push(format!(
                "| {name} | {} | {} | {:.3} |",
                len(&path),
                len(old),
                len(&path) as f64 / len(old) as f64
            ));
        }
        let frame = WorldFrame::new(Some(dem.spacing));
        let mut rows: Vec<Row> = Vec::new();
        let mut scenes: Vec<Vec<(usize, usize)>> = Vec::new();
        for (cam_name, cam) in dem.cameras() {
            let view = cam.view().expect("camera");
            for tau in TAUS {
                let fmrh_run = || fmrh_scene(&path, &cam, tau);
                let (blocks, reads, bytes, px) = fmrh_run();
                let (fmrh_warm, fmrh_cold) = match &before {
                    None => (
                        best_us(
                            || {},
                            || {
                                fmrh_run();
                            },
                        ),
                        best_us(
                            || evict(&path),
                            || {
                                fmrh_run();
                            },
                        ),
                    ),
                    Some(old) => {
                        let old_run = || fmrh_scene(old, &cam, tau);
                        let (old_blocks, _, old_bytes, old_px) = old_run();
                        let (w, old_w) = best_pair_us(
                            |_| {},
                            || {
                                fmrh_run();
                            },
                            || {
                                old_run();
                            },
                        );
                        let (c, old_c) = best_pair_us(
                            |i| evict(if i == 0 { &path } else { old }),
                            || {
                                fmrh_run();
                            },
                            || {
                                old_run();
                            },
                        );
                        let r = [w / old_w, c / old_c, bytes as f64 / old_bytes as f64];
                        against_before.push((
                            format!(
                                "| {name} | {cam_name} | {tau} | {blocks} / {old_blocks} | {px:.2} / {old_px:.2} | {bytes} | {old_bytes} | {:.3} | {w:.0} | {old_w:.0} | {:.3} | {c:.0} | {old_c:.0} | {:.3} |",
                                r[2], r[0], r[1]
                            ),
                            r,
                        ));
                        (w, c)
                    }
                };
                let (tiles, cog_px) = cog_scene(&cog, TerrainFrame::Flat(frame), &view, tau);
                let (cog_bytes, cog_calls) = cog_reads(&cog, &tiles);
                let cog_us = best_us(
                    || {},
                    || {
                        let chosen = cog_scene(&cog, TerrainFrame::Flat(frame), &view, tau).0;
                        cog_decode(&cog, &chosen);
                    },
                );
                let ratio = bytes as f64 / cog_bytes as f64;
                ratios.push(ratio);
                rows.push(Row {
                    line: format!(
                        "| {name} | {cam_name} | {tau} | {blocks} | {reads} | {bytes} | {px:.2} | {} | {cog_calls} | {cog_bytes} | {cog_px:.2} | {ratio:.2} | {fmrh_warm:.0} | {fmrh_cold:.0} |",
                        tiles.len()
                    ),
                    fmrh_warm,
                    fmrh_cold,
                });
                scenes.push(tiles);
                // The tiff-crate reader's time goes last on the line.
                rows.last_mut().expect("a row").line += &format!(" {{gdal}} | {cog_us:.0} |");
            }
        }
        let gdal = gdal_times(dir.path(), &cog, &scenes);
        for (row, (gw, gc)) in rows.iter().zip(gdal) {
            let (w, c) = (row.fmrh_warm / gw, row.fmrh_cold / gc);
            warm_ratios.push(w);
            cold_ratios.push(c);
            println!(
                "{} {w:.3} | {c:.3} |",
                row.line.replace("{gdal}", &format!("{gw:.0} | {gc:.0}"))
            );
        }
    }
    if !warm_ratios.is_empty() {
        let (wm, ww, wb) = quantiles(warm_ratios.clone());
        let (cm, cw, cb) = quantiles(cold_ratios.clone());
        println!(
            "\n| fmrh time / GDAL time | median | worst | best | scenes at or below 0.5 | scenes |"
        );
        println!("|---|---|---|---|---|---|");
        for (what, (m, w, b), r) in [
            ("warm", (wm, ww, wb), &warm_ratios),
            ("cold", (cm, cw, cb), &cold_ratios),
        ] {
            println!(
                "| {what} | {m:.3} | {w:.3} | {b:.3} | {} | {} |",
                r.iter().filter(|&&x| x <= 0.5).count(),
                r.len()
            );
        }
    }
    if !against_before.is_empty() {
        println!(
            "\n| dataset | camera | tau | blocks now / before | max px now / before | bytes now | bytes before | bytes ratio | us warm now | us warm before | warm ratio | us cold now | us cold before | cold ratio |"
        );
        println!("|---|---|---|---|---|---|---|---|---|---|---|---|---|---|");
        for (line, _) in &against_before {
            println!("{line}");
        }
        println!("\n| now / before | median | worst | best | scenes |");
        println!("|---|---|---|---|---|");
        for (k, what) in ["warm time", "cold time", "bytes read"].iter().enumerate() {
            let (m, w, b) = quantiles(against_before.iter().map(|(_, r)| r[k]).collect());
            println!(
                "| {what} | {m:.3} | {w:.3} | {b:.3} | {} |",
                against_before.len()
            );
        }
        println!("\n| dataset | file bytes now | file bytes before | now / before |");
        println!("|---|---|---|---|");
        for line in &sizes {
            println!("{line}");
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
