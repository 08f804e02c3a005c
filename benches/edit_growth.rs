//! How a container grows under edits, and what compaction gives back (issue 39, point 4):
//! on each DEM of `common/dems.rs` (Puget Sound 1k bundled; Puget Sound 4k and the SRTM1
//! tile S46W066 from `../shared/data`), 1,000 random replacements of square patches of 17² to
//! 129² samples, each the DEM's own samples from another place (`FMRH_BENCH_EDITS` sets the
//! count), one commit each; after every 100, the
//! file's size beside a fresh build of the same samples with the same options (`compact` on
//! a copy), the ratio the issue bounds (goal: at most 1.3x in the steady state).
//! Prints a table per DEM, with the largest the file was since the row before (a commit's
//! length swings as free pages at the end are cut). `FMRH_BENCH_DEM` keeps only the DEMs
//! whose name contains it; `FMRH_BENCH_KEEP=DIR` copies each edited file there at the end
//! (for `fmrh info`); `FMRH_BENCH_VERBOSE=1` prints each commit's summary, and the payload
//! bytes the cleaner moved (`src/store/txn/clean.rs`) in all.

#[path = "common/dems.rs"]
mod dems;

use fmrh::store::{compact, CompactOptions, Container};
use fmrh::Heightfield;

/// A deterministic generator for patch places, sizes and heights.
fn next(state: &mut u64) -> u64 {
    *state = state
        .wrapping_mul(6_364_136_223_846_793_005)
        .wrapping_add(1_442_695_040_888_963_407);
    *state >> 33
}

/// The samples of `source` in the `side²` square at `(c0, r0)`: real terrain moved
/// elsewhere, so that a patch codes as the data does and a fresh build of the edited samples
/// stays about the size of the first (a synthetic patch smoother than the data would shrink
/// it and make every ratio look worse than it is).
fn patch(source: &Heightfield, side: u32, c0: u64, r0: u64) -> Heightfield {
    let w = u64::from(source.width());
    Heightfield::from_fn(side, side, |x, y| {
        source.samples()[((r0 + u64::from(y)) * w + c0 + u64::from(x)) as usize]
    })
    .unwrap()
}

fn main() {
    let edits: usize = std::env::var("FMRH_BENCH_EDITS")
        .ok()
        .and_then(|v| v.parse().ok())
        .unwrap_or(1000);
    let only = std::env::var("FMRH_BENCH_DEM").unwrap_or_default();
    let keep = std::env::var_os("FMRH_BENCH_KEEP");
    let dir = tempfile::tempdir().unwrap();
    for dem in dems::dems().into_iter().filter(|d| d.name.contains(&only)) {
        let path = dem.build(dir.path());
        let built = std::fs::metadata(&path).unwrap().len();
        let (w, h) = (
            u64::from(dem.source.width()),
            u64::from(dem.source.height()),
        );
        println!("\n{}: {} x {}, built {built} bytes", dem.name, w, h);
        println!(
            "| edits | file bytes | x build | fresh build of the same samples | x fresh | largest since last row | x fresh |"
        );
        println!("|---|---|---|---|---|---|---|");
        let (mut peak, mut moved, mut written) = (0u64, 0u64, 0u64);
        let container = Container::open(&path).unwrap();
        let mut rng = 39u64;
        for i in 1..=edits {
            let side = 17 + (next(&mut rng) % 113) as u32;
            let c0 = next(&mut rng) % (w - u64::from(side) + 1);
            let r0 = next(&mut rng) % (h - u64::from(side) + 1);
            let from_c = next(&mut rng) % (w - u64::from(side) + 1);
            let from_r = next(&mut rng) % (h - u64::from(side) + 1);
            let mut txn = container.begin_write().unwrap();
            txn.replace_region(c0, r0, &patch(&dem.source, side, from_c, from_r))
                .unwrap();
            let s = txn.commit().unwrap();
            peak = peak.max(s.file_length);
            moved += s.bytes_moved;
            written += s.pages_written;
            if std::env::var_os("FMRH_BENCH_VERBOSE").is_some() {
                eprintln!(
                    "{i} side {side}: blocks {} grids {} written {} reused {} freed {} moved {} ({} B) length {}",
                    s.blocks, s.grids, s.pages_written, s.pages_reused, s.pages_freed,
                    s.payloads_moved, s.bytes_moved, s.file_length
                );
            }
            if i % 100 == 0 || i == edits {
                let now = std::fs::metadata(&path).unwrap().len();
                // A fresh build of the same state: compaction of a copy (the writer's lock is
                // on the original; the copy is a file of its own).
                let copy = dir.path().join("copy.fmrh");
                std::fs::copy(&path, &copy).unwrap();
                let fresh = compact(&copy, &CompactOptions::default())
                    .unwrap()
                    .bytes_after;
                println!(
                    "| {i} | {now} | {:.2} | {fresh} | {:.2} | {peak} | {:.2} |",
                    now as f64 / built as f64,
                    now as f64 / fresh as f64,
                    peak as f64 / fresh as f64
                );
                peak = 0;
            }
        }
        container.close().unwrap();
        println!(
            "{edits} commits wrote {written} pages; the cleaner moved {moved} payload bytes of them"
        );
        if let Some(keep) = &keep {
            std::fs::copy(
                &path,
                std::path::Path::new(keep).join(format!("{}.fmrh", dem.name)),
            )
            .unwrap();
        }
    }
}
