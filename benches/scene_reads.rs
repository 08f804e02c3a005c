//! Bytes and read calls per scene, and time, cold and warm: what opening a container and
//! answering a view costs at the source, on Puget Sound 1k (bundled), Puget Sound 4k and
//! the mostly-sea SRTM1 tile S46W066 (`../shared/data`), three cameras each, tau 0.5 to 4.
//!
//! For each row: the blocks of the view-dependent scene and their stored payload bytes (the
//! least any reader of these blocks reads); what opening read; what scheduling read (index
//! and node pages, each once through the page cache); what loading read (payloads coalesced
//! at gaps of 0, 1 KiB and 4 KiB, plus the block-table pages physical blocks need); the read
//! amplification (all bytes over the payload bytes); and the wall time of open + schedule +
//! load + decode from a file read with `pread`, cold (the file dropped from the page cache
//! with `posix_fadvise(DONTNEED)` first) and warm. The last columns are the price of the
//! codec: the warm time of the same scene from a copy of the file whose payloads are stored
//! raw (`WriteOptions::raw_payloads`: nothing to decode, as format 1 stored them), and the
//! ratio; and the same scene from a copy whose blocks are all coded alone
//! (`WriteOptions::against_parents` off, as format 3 coded them): its bytes read and
//! warm time, the price of format 4's blocks coded against their parent's grid. Every
//! configuration runs in the same process, so the ratios are side by side.
//! `cargo bench --bench scene_reads`.

use std::path::{Path, PathBuf};
use std::time::Instant;

#[path = "common/dems.rs"]
mod dems;

use fmrh::scene::{load_blocks, Camera, SceneOptions, Terrain};
use fmrh::store::ReadStats;
use fmrh::store::Store;

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

/// Open, schedule and load from a fresh `pread` store: (open, schedule, load) reads, blocks,
/// payload bytes of the blocks, microseconds.
fn run(
    path: &Path,
    cam: &Camera,
    tau: f64,
    gap: u64,
) -> (ReadStats, ReadStats, ReadStats, usize, u64, f64) {
    let t = Instant::now();
    let store = Store::open(path).expect("opens");
    let open = store.open_reads();
    let terrain = Terrain::new(&store).expect("terrain");
    let scene = terrain.scene(cam, &SceneOptions::new(tau)).expect("scene");
    let scheduled = store.read_stats();
    let loaded = load_blocks(&store, &scene.blocks, gap).expect("loads");
    let us = t.elapsed().as_secs_f64() * 1e6;
    let all = store.read_stats();
    let payload: u64 = scene.blocks.iter().map(|b| u64::from(b.payload.len)).sum();
    assert_eq!(loaded.len(), scene.blocks.len());
    (
        open,
        scheduled,
        all.since(&scheduled),
        scene.blocks.len(),
        payload,
        us,
    )
}

fn main() {
    let dir = tempfile::tempdir().expect("temp dir");
    let raw = fmrh::store::WriteOptions {
        raw_payloads: true,
        ..Default::default()
    };
    let alone = fmrh::store::WriteOptions {
        against_parents: false,
        ..Default::default()
    };
    let sets: Vec<(dems::Dem, PathBuf, PathBuf, PathBuf)> = dems::dems()
        .into_iter()
        .map(|d| {
            let path = d.build(dir.path());
            let raw_path = d.build_with(dir.path(), "-raw", &raw);
            let alone_path = d.build_with(dir.path(), "-alone", &alone);
            (d, path, raw_path, alone_path)
        })
        .collect();
    println!(
        "| dataset | camera | tau | blocks | payload B | open calls/B | schedule calls/B | \
         load calls/B gap 0 | gap 1 KiB | gap 4 KiB | total B (gap 0) | amplification | cold us | warm us | warm us, raw payloads | codec cost | blocks alone: total B | warm us |"
    );
    println!("|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|");
    for (d, path, raw_path, alone_path) in &sets {
        for (cam_name, cam) in d.cameras() {
            for tau in [0.5, 1.0, 2.0, 4.0] {
                let mut cells = Vec::new();
                let mut base = None;
                for gap in [0u64, 1024, 4096] {
                    let (open, sched, load, blocks, payload, _) = run(path, &cam, tau, gap);
                    if base.is_none() {
                        base = Some((open, sched, blocks, payload));
                    }
                    cells.push(load);
                }
                let Some((open, sched, blocks, payload)) = base else {
                    continue;
                };
                evict(path);
                let cold = run(path, &cam, tau, 0).5;
                // Coded and raw, interleaved, so both see the same machine.
                let (mut warm, mut warm_raw, mut warm_alone) =
                    (f64::INFINITY, f64::INFINITY, f64::INFINITY);
                let mut alone_total = 0;
                for _ in 0..5 {
                    warm = warm.min(run(path, &cam, tau, 0).5);
                    let (.., raw_blocks, _, us) = run(raw_path, &cam, tau, 0);
                    assert_eq!(raw_blocks, blocks, "the raw copy schedules the same scene");
                    warm_raw = warm_raw.min(us);
                    let (o, s, l, alone_blocks, _, us) = run(alone_path, &cam, tau, 0);
                    assert_eq!(alone_blocks, blocks, "the copy schedules the same scene");
                    warm_alone = warm_alone.min(us);
                    alone_total = o.bytes() + s.bytes() + l.bytes();
                }
                let total = open.bytes() + sched.bytes() + cells[0].bytes();
                println!(
                    "| {} | {cam_name} | {tau} | {blocks} | {payload} | {}/{} | {}/{} | {}/{} | {}/{} | {}/{} | {total} | {:.2} | {cold:.0} | {warm:.0} | {warm_raw:.0} | {:.2} | {alone_total} | {warm_alone:.0} |",
                    d.name,
                    open.reads(),
                    open.bytes(),
                    sched.reads(),
                    sched.bytes(),
                    cells[0].reads(),
                    cells[0].bytes(),
                    cells[1].reads(),
                    cells[1].bytes(),
                    cells[2].reads(),
                    cells[2].bytes(),
                    total as f64 / payload.max(1) as f64,
                    warm / warm_raw,
                );
            }
        }
    }
    fly_through(&sets[0].1, &sets[0].2, &sets[0].3);
}

/// The decoded-block cache: the Puget Sound 1k orbit (720 frames) through the `Scheduler`,
/// which decodes a block once when it becomes resident, beside a renderer that reads and
/// decodes every visible block each frame, and beside the scheduler on the copy whose
/// payloads are raw (format 1's cost: nothing to decode) and the copy whose blocks are
/// coded alone (format 3's coding).
fn fly_through(path: &Path, raw_path: &Path, alone_path: &Path) {
    let (cameras, decoded, cached) = scheduled_frames(path);
    let (_, decoded_raw, cached_raw) = scheduled_frames(raw_path);
    let (_, decoded_alone, cached_alone) = scheduled_frames(alone_path);
    assert_eq!(decoded, decoded_raw, "the raw copy loads the same blocks");
    assert_eq!(decoded, decoded_alone, "the copy loads the same blocks");
    let (every, uncached) = every_frame(path, &cameras);
    println!(
        "\nfly-through, Puget Sound 1k orbit, {} frames, tau 1: the scheduler decodes {decoded} \
         blocks in all, {cached:.0} us a frame; reading and decoding every visible block each \
         frame decodes {every}, {uncached:.0} us a frame ({:.1}x); the scheduler on raw \
         payloads (nothing to decode), {cached_raw:.0} us a frame ({:.2}x of it); with \
         every block coded alone, {cached_alone:.0} us a frame",
        cameras.len(),
        uncached / cached,
        cached / cached_raw
    );
}

/// The orbit through the `Scheduler` on `path`: the cameras, blocks decoded in all, and
/// microseconds a frame.
fn scheduled_frames(path: &Path) -> (Vec<Camera>, u64, f64) {
    let text = std::fs::read_to_string(
        PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("tests/paths/puget-1k-orbit.csv"),
    )
    .expect("the orbit path");
    let template = Camera::looking_at(glam::DVec3::ZERO, glam::DVec3::X);
    let cameras = fmrh::scene::path::parse(&text, &template).expect("path");
    let store = std::sync::Arc::new(Store::open(path).expect("opens"));
    let t = Instant::now();
    let mut scheduler = fmrh::scene::Scheduler::new(
        std::sync::Arc::clone(&store),
        fmrh::scene::ScheduleOptions::new(1.0),
    )
    .expect("scheduler");
    let mut decoded = 0u64;
    for cam in &cameras {
        decoded += scheduler.frame(cam).expect("frame").stats.loaded;
    }
    let cached = t.elapsed().as_secs_f64() * 1e6 / cameras.len() as f64;
    (cameras, decoded, cached)
}

/// Every frame's visible blocks read and decoded, no cache: blocks decoded in all and
/// microseconds a frame.
fn every_frame(path: &Path, cameras: &[Camera]) -> (u64, f64) {
    let store = Store::open(path).expect("opens");
    let terrain = Terrain::new(&store).expect("terrain");
    let t = Instant::now();
    let mut every = 0u64;
    for cam in cameras {
        let scene = terrain.scene(cam, &SceneOptions::new(1.0)).expect("scene");
        every += load_blocks(&store, &scene.blocks, 0).expect("loads").len() as u64;
    }
    let uncached = t.elapsed().as_secs_f64() * 1e6 / cameras.len() as f64;
    (every, uncached)
}
