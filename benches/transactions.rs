//! Commit latency and file growth of transactional replacement on Puget Sound 1k (a real
//! file on the local disk, fsync included): the median and 90th percentile of a commit that
//! replaces one 65x65 block and one 513x513 region at random places, then the file size
//! after N replacements (`FMRH_BENCH_REPLACEMENTS`, default 1000) against the first build.
//! Prints a table; the machines are noisy, so read medians.

use std::path::PathBuf;
use std::time::Instant;

use fmrh::ingest::{load, IngestOptions};
use fmrh::model::{BuildOptions, Model};
use fmrh::store::{write_file, Container, WriteOptions};
use fmrh::Heightfield;

fn data(rel: &str) -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR"))
        .join("../shared/data")
        .join(rel)
}

/// A deterministic generator for patch places and heights.
fn next(state: &mut u64) -> u64 {
    *state = state
        .wrapping_mul(6_364_136_223_846_793_005)
        .wrapping_add(1_442_695_040_888_963_407);
    *state >> 33
}

fn patch(side: u32, seed: u64) -> Heightfield {
    let s = seed as f32;
    Heightfield::from_fn(side, side, |x, y| {
        (100.0 + (x as f32 * 0.05 + s).sin() * 50.0 + (y as f32 * 0.03).cos() * 30.0).round()
    })
    .unwrap()
}

fn percentile(v: &mut [f64], q: f64) -> f64 {
    v.sort_by(f64::total_cmp);
    v[((v.len() - 1) as f64 * q).round() as usize]
}

fn main() {
    let hf = load(
        &data("puget-sound-1k/ps_height_1k.f32"),
        &IngestOptions::default(),
    )
    .expect("real data (../shared/data)");
    let (w, h) = (u64::from(hf.width()), u64::from(hf.height()));
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("ps1k.fmrh");
    let model = Model::build(hf.clone(), &BuildOptions::default()).unwrap();
    write_file(&model, &hf.metadata, &path, &WriteOptions::default(), true).unwrap();
    let first = std::fs::metadata(&path).unwrap().len();
    let container = Container::open(&path).unwrap();
    let mut rng = 7u64;
    println!("Puget Sound 1k, first build {first} bytes");
    println!("| patch | commits | median ms | p90 ms | blocks/commit | grids/commit |");
    println!("|---|---|---|---|---|---|");
    for (side, commits) in [(65u32, 60usize), (513, 20)] {
        let mut times = Vec::new();
        let (mut blocks, mut grids) = (0, 0);
        for _ in 0..commits {
            let c0 = next(&mut rng) % (w - u64::from(side) + 1);
            let r0 = next(&mut rng) % (h - u64::from(side) + 1);
            let p = patch(side, next(&mut rng));
            let mut txn = container.begin_write().unwrap();
            let t = Instant::now();
            txn.replace_region(c0, r0, &p).unwrap();
            let s = txn.commit().unwrap();
            times.push(t.elapsed().as_secs_f64() * 1e3);
            blocks += s.blocks;
            grids += s.grids;
        }
        // The first commit also builds the writer's model from the file: report it apart.
        let warm = &mut times[1..].to_vec();
        println!(
            "| {side}x{side} | {commits} | {:.2} | {:.2} | {} | {} |",
            percentile(warm, 0.5),
            percentile(warm, 0.9),
            blocks / commits as u64,
            grids / commits as u64
        );
    }
    // What the disk's fsync costs alone, beside the commits: a 4 KiB write and a sync.
    let mut syncs = Vec::new();
    {
        use std::io::{Seek, Write};
        let mut f = std::fs::File::create(dir.path().join("sync-probe")).unwrap();
        for _ in 0..60 {
            f.rewind().unwrap();
            f.write_all(&[7u8; 4096]).unwrap();
            let t = Instant::now();
            f.sync_all().unwrap();
            syncs.push(t.elapsed().as_secs_f64() * 1e3);
        }
    }
    println!(
        "one fsync of a 4 KiB write on this disk: median {:.2} ms (a commit makes two)",
        percentile(&mut syncs, 0.5)
    );
    let n: usize = std::env::var("FMRH_BENCH_REPLACEMENTS")
        .ok()
        .and_then(|v| v.parse().ok())
        .unwrap_or(1000);
    for _ in 0..n {
        let c0 = next(&mut rng) % (w - 64);
        let r0 = next(&mut rng) % (h - 64);
        let mut txn = container.begin_write().unwrap();
        txn.replace_region(c0, r0, &patch(65, next(&mut rng)))
            .unwrap();
        txn.commit().unwrap();
    }
    let after = std::fs::metadata(&path).unwrap().len();
    println!(
        "after {n} more 65x65 replacements: {after} bytes = {:.3} x the first build",
        after as f64 / first as f64
    );
}
