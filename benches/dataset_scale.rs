//! The issue-16 scale benchmark: a dataset of 64 tiles of 4097² (1.07 × 10⁹ samples), the
//! Puget Sound 4k DEM mirrored into a 32769² mosaic by `benches/dataset/make_mosaic.py` and
//! built by `fmrh dataset build` (`benches/dataset/run.sh` does both, then runs this). It
//! prints tables, measured side by side in one run:
//!
//! * opening the dataset: time and bytes;
//! * scenes at tau 1, 2 and 4 for a low and a high camera, cold (the dataset opened anew
//!   for each run), selection and loading included, against the all-finest-blocks baseline
//!   of the same tiles, and the clusters' selection against a plain top-down traversal;
//! * a 600-frame fly-through: per-frame schedule and load time (median, p99) and bytes
//!   loaded per frame after the first, on the default pool, on one thread, and with the
//!   prefetcher loading ahead of the camera at 60 frames a second;
//! * the selection alone over the same frames: the exact frustum region against the
//!   scheduler's coarser one (issue 44), checked to give the same blocks.
//!
//! `FMRH_SCALE_DATASET` names the dataset (default `/tmp/fmrh-scale/ds`). Nothing it reads is
//! committed.

use std::path::PathBuf;
use std::time::Instant;

use glam::DVec3;

use fmrh::dataset::{Dataset, DatasetScheduler};
use fmrh::scene::{
    baseline, load_blocks, Camera, Mode, SceneOptions, ScheduleOptions, Terrain, PAYLOAD_GAP,
};

fn median(mut v: Vec<f64>) -> f64 {
    v.sort_by(f64::total_cmp);
    v[v.len() / 2]
}

fn camera(eye: [f64; 3], target: [f64; 3]) -> Camera {
    Camera::looking_at(DVec3::from(eye), DVec3::from(target))
}

/// One cold scene: open, select, load. Returns (select s, load s, blocks, samples, bytes read).
fn cold_scene(dir: &std::path::Path, cam: &Camera, tau: f64) -> (f64, f64, u64, u64, u64) {
    let ds = Dataset::open(dir).expect("the dataset opens");
    let t0 = Instant::now();
    let scene = ds
        .scene(
            cam,
            &SceneOptions {
                tau,
                mode: Mode::View,
                window: None,
                gap: 4,
            },
            None,
        )
        .unwrap();
    let t1 = Instant::now();
    let loaded = ds.load(&scene).unwrap();
    let t2 = Instant::now();
    let schedule: u64 = scene.tiles.iter().map(|t| t.reads.bytes()).sum();
    (
        (t1 - t0).as_secs_f64(),
        (t2 - t1).as_secs_f64(),
        scene.stats.blocks,
        scene.stats.samples,
        loaded.bytes() + schedule + ds.manifest_reads().bytes(),
    )
}

/// The all-finest baseline over the tiles the scene meets, cold: (select+load s, blocks,
/// samples, bytes read); and the plain traversal's selection time against the clusters'.
fn baselines(dir: &std::path::Path, cam: &Camera, tau: f64) -> (f64, u64, u64, u64, f64, f64) {
    let ds = Dataset::open(dir).unwrap();
    let frame = ds.frame(None).unwrap();
    let tiles = ds.scene_tiles(cam, None, &frame).unwrap();
    let (mut secs, mut blocks, mut samples, mut bytes) = (0.0, 0u64, 0u64, 0u64);
    let (mut traversal, mut clusters) = (0.0, 0.0);
    for t in &tiles {
        let store = ds.open_tile(t).unwrap();
        let terrain = Terrain::with_spacing(&store, Some([frame.dx, frame.dy])).unwrap();
        let r = t.rect();
        let shift = DVec3::new(r.col0 as f64 * frame.dx, r.row0 as f64 * frame.dy, 0.0);
        let local = Camera {
            eye: cam.eye - shift,
            target: cam.target - shift,
            ..*cam
        };
        let before = store.read_stats();
        let t0 = Instant::now();
        let all = baseline::all_finest(&terrain, &local, None).unwrap();
        load_blocks(&store, &all, PAYLOAD_GAP).unwrap();
        secs += t0.elapsed().as_secs_f64();
        blocks += all.len() as u64;
        let b = u64::from(store.domain().block_size());
        samples += all.len() as u64 * b * b;
        bytes += store.read_stats().since(&before).bytes();
        let t1 = Instant::now();
        let walked = baseline::traversal(&terrain, &local, tau, None).unwrap();
        traversal += t1.elapsed().as_secs_f64();
        let t2 = Instant::now();
        let scene = terrain.scene(&local, &SceneOptions::new(tau)).unwrap();
        clusters += t2.elapsed().as_secs_f64();
        assert_eq!(
            walked.len(),
            scene.blocks.len(),
            "the traversal and the clusters disagree"
        );
    }
    (secs, blocks, samples, bytes, traversal, clusters)
}

fn main() {
    let dir = PathBuf::from(
        std::env::var("FMRH_SCALE_DATASET").unwrap_or_else(|_| "/tmp/fmrh-scale/ds".into()),
    );
    if !dir.join("MANIFEST").exists() {
        eprintln!(
            "{}: no dataset. Run `bash benches/dataset/run.sh` (it makes the 1.07e9-sample mosaic and builds it), or set FMRH_SCALE_DATASET.",
            dir.display()
        );
        std::process::exit(2);
    }
    let ds = Dataset::open(&dir).unwrap();
    let grid = ds.grid();
    let tiles = ds.tile_count();
    let total: u64 = ds
        .tiles()
        .unwrap()
        .iter()
        .map(|t| std::fs::metadata(ds.tile_path(t)).unwrap().len())
        .sum::<u64>()
        + std::fs::metadata(dir.join("MANIFEST")).unwrap().len();
    let samples = (grid.col1 + 1) * (grid.row1 + 1);
    println!(
        "dataset {}: {tiles} tiles, {} x {} = {samples} samples, {total} bytes ({:.4} x raw f32)",
        dir.display(),
        grid.col1 + 1,
        grid.row1 + 1,
        total as f64 / (4 * samples) as f64
    );

    // Opening.
    let mut times = Vec::new();
    let mut bytes = 0;
    for _ in 0..50 {
        let t = Instant::now();
        let d = Dataset::open(&dir).unwrap();
        times.push(t.elapsed().as_secs_f64() * 1e6);
        bytes = d.open_reads().bytes();
    }
    println!("\nopen: median {:.1} us, {bytes} bytes in 3 reads (the manifest's slots and head; no tile)", median(times));

    let [dx, dy] = ds.spacing_m().unwrap_or([1.0, 1.0]);
    let (w, h) = ((grid.col1 as f64) * dx, (grid.row1 as f64) * dy);
    let cams = [
        (
            "low",
            camera(
                [0.5 * w, 0.5 * h, 1500.0],
                [0.5 * w + 30000.0, 0.5 * h + 10000.0, 0.0],
            ),
        ),
        (
            "high",
            camera([0.5 * w, 1.25 * h, 0.45 * w], [0.5 * w, 0.5 * h, 0.0]),
        ),
    ];
    println!(
        "\nscenes, cold (dataset opened for each run), view mode, 1024x768, 60 deg: median of 3"
    );
    println!("| camera | tau | tiles | blocks | samples | bytes read | select ms | load ms | all-finest blocks | all-finest bytes | all-finest ms | samples ratio | bytes ratio | time ratio |");
    println!("|---|---|---|---|---|---|---|---|---|---|---|---|---|---|");
    let mut traversal_rows = Vec::new();
    for (name, cam) in &cams {
        for tau in [1.0, 2.0, 4.0] {
            let runs: Vec<_> = (0..3).map(|_| cold_scene(&dir, cam, tau)).collect();
            let sel = median(runs.iter().map(|r| r.0 * 1e3).collect());
            let load = median(runs.iter().map(|r| r.1 * 1e3).collect());
            let (_, _, blocks, samples, bytes) = runs[0];
            let (bsecs, bblocks, bsamples, bbytes, trav, clus) = baselines(&dir, cam, tau);
            let d = Dataset::open(&dir).unwrap();
            let met = d
                .scene_tiles(cam, None, &d.frame(None).unwrap())
                .unwrap()
                .len();
            println!(
                "| {name} | {tau} | {met} | {blocks} | {samples} | {bytes} | {sel:.2} | {load:.2} | {bblocks} | {bbytes} | {:.1} | {:.1}x | {:.1}x | {:.1}x |",
                bsecs * 1e3,
                bsamples as f64 / samples.max(1) as f64,
                bbytes as f64 / bytes.max(1) as f64,
                bsecs * 1e3 / (sel + load)
            );
            traversal_rows.push((name.to_string(), tau, trav * 1e3, clus * 1e3));
        }
    }
    println!("\nselection alone, warm tiles: clusters (index range scans) against a plain top-down traversal of the node table");
    println!("| camera | tau | traversal ms | clusters ms | ratio |");
    println!("|---|---|---|---|---|");
    for (name, tau, t, c) in traversal_rows {
        println!("| {name} | {tau} | {t:.2} | {c:.2} | {:.1}x |", t / c);
    }

    // A 600-frame fly-through at 3 km, across the mosaic.
    let frames: Vec<Camera> = (0..600)
        .map(|i| {
            let t = f64::from(i) / 599.0;
            let x = 0.02 * w + t * 0.96 * w;
            let y = 0.5 * h + 0.15 * h * (t * std::f64::consts::TAU).sin();
            camera([x, y, 3000.0], [x + 20000.0, y + 5000.0, 500.0])
        })
        .collect();
    println!("\nfly-through, 600 frames at 3 km altitude across the mosaic (view mode)");
    println!("(schedule: the frame's wall time to choose tiles, select their scenes and evict; load: its wall time to read and decode what it lacks)");
    println!("| tau | threads | 60 fps | prefetch | schedule us median | p99 | load us median | p99 | bytes loaded, first frame | bytes loaded per later frame (mean) | prefetch hits | tiles opened |");
    println!("|---|---|---|---|---|---|---|---|---|---|---|---|");
    for tau in [1.0, 2.0, 4.0] {
        for (threads, paced, prefetch) in [
            (0, false, false),
            (1, false, false),
            (0, true, false),
            (0, true, true),
        ] {
            fly(&dir, &frames, tau, threads, paced, prefetch);
        }
    }

    // The selection alone, per frame, over the tiles each frame meets (opened and warm):
    // the exact region (`Terrain::scene`) against the scheduler's (`Terrain::scene_blocks`),
    // one thread, the same blocks (checked).
    let frame = ds.frame(None).unwrap();
    let all = ds.tiles().unwrap();
    let stores: Vec<_> = all.iter().map(|t| ds.open_tile(t).unwrap()).collect();
    let plan: Vec<Vec<usize>> = frames
        .iter()
        .map(|cam| {
            ds.scene_tiles(cam, None, &frame)
                .unwrap()
                .iter()
                .filter_map(|t| all.iter().position(|u| u.index == t.index))
                .collect()
        })
        .collect();
    println!("\nselection alone over the fly-through's frames, one thread, warm tiles: the exact frustum region against the scheduler's coarser one (same blocks)");
    println!("| tau | exact us median | p99 | scheduler's us median | p99 | ratio (medians) |");
    println!("|---|---|---|---|---|---|");
    for tau in [1.0, 2.0, 4.0] {
        let options = SceneOptions::new(tau);
        let mut times = [Vec::new(), Vec::new()];
        for (cam, tiles) in frames.iter().zip(&plan) {
            let mut scenes = [Vec::new(), Vec::new()];
            for (k, time) in times.iter_mut().enumerate() {
                let t = Instant::now();
                for &i in tiles {
                    let terrain =
                        Terrain::with_spacing(&stores[i], Some([frame.dx, frame.dy])).unwrap();
                    let local = fmrh::dataset::in_tile(cam, &all[i].rect(), &frame);
                    scenes[k].push(if k == 0 {
                        terrain.scene(&local, &options).unwrap().blocks
                    } else {
                        terrain.scene_blocks(&local, &options).unwrap().blocks
                    });
                }
                time.push(t.elapsed().as_secs_f64() * 1e6);
            }
            assert_eq!(scenes[0], scenes[1], "the scheduler's selection differs");
        }
        let [exact, coarse] = times.map(|mut v| {
            v.sort_by(f64::total_cmp);
            (v[v.len() / 2], v[v.len() * 99 / 100])
        });
        println!(
            "| {tau} | {:.1} | {:.1} | {:.1} | {:.1} | {:.2}x |",
            exact.0,
            exact.1,
            coarse.0,
            coarse.1,
            exact.0 / coarse.0
        );
    }
}

/// One fly-through row: `threads` 0 is the pool's default. `paced`: frames at 60 a second,
/// the thread idle for the rest of each 16.7 ms (the dataset's prefetch thread works then).
/// With `prefetch` the whole predicted view is warmed ahead of the camera.
fn fly(
    dir: &std::path::Path,
    frames: &[Camera],
    tau: f64,
    threads: usize,
    paced: bool,
    prefetch: bool,
) {
    let pool = rayon::ThreadPoolBuilder::new()
        .num_threads(threads)
        .build()
        .unwrap();
    let d = Dataset::open(dir).unwrap();
    let options = ScheduleOptions {
        prefetch,
        cache_radius: if prefetch { 1e9 } else { 0.0 },
        ..ScheduleOptions::new(tau)
    };
    let (sched, load, loaded, hits) = pool.install(|| {
        let mut s = DatasetScheduler::new(&d, options).unwrap();
        let (mut sched, mut load, mut loaded, mut hits) = (Vec::new(), Vec::new(), Vec::new(), 0);
        for cam in frames {
            let started = Instant::now();
            let f = s.frame(cam).unwrap();
            sched.push(f.stats.schedule_ns as f64 / 1e3);
            load.push(f.stats.load_ns as f64 / 1e3);
            loaded.push(f.stats.loaded_bytes);
            hits += f.stats.prefetch_hits;
            if paced {
                let pace = std::time::Duration::from_micros(16_667);
                std::thread::sleep(pace.saturating_sub(started.elapsed()));
            }
        }
        (sched, load, loaded, hits)
    });
    let p = |mut v: Vec<f64>| {
        v.sort_by(f64::total_cmp);
        (v[v.len() / 2], v[v.len() * 99 / 100])
    };
    let ((sm, s99), (lm, l99)) = (p(sched), p(load));
    let later = loaded[1..].iter().sum::<u64>() as f64 / (loaded.len() - 1) as f64;
    println!(
        "| {tau} | {} | {} | {} | {sm:.1} | {s99:.1} | {lm:.1} | {l99:.1} | {} | {later:.0} | {hits} | {} |",
        pool.current_num_threads(),
        if paced { "yes" } else { "no" },
        if prefetch { "whole view" } else { "off" },
        loaded[0],
        d.tiles_opened()
    );
}
