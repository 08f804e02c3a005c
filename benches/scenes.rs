//! Scene scheduling cost on Puget Sound 1k (160 m spacing) and 4k (40 m) from a warm mapping, at
//! tau = 0.5, 1, 2, 4 px: uniform mode, view-dependent mode, and the two naive baselines of
//! `fmrh::scene::baseline` (every finest block of the view; the FMRH walked from the root
//! without clusters). Each is timed twice: selection alone (the block list with payload
//! references), and selection plus loading (every payload read and CRC-checked), which is
//! what a frame waits for. The harness prints blocks and bytes of each answer first; every
//! method is measured in the same run so the ratios are side by side.

use std::path::PathBuf;

use criterion::{criterion_group, criterion_main, Criterion};
use glam::DVec3;

use fmrh::ingest::{load, IngestOptions};
use fmrh::model::{BuildOptions, Model};
use fmrh::scene::{baseline, Camera, Mode, SceneBlock, SceneOptions, Terrain};
use fmrh::store::Store;
use fmrh::store::{write_file, Source, WriteOptions};

fn data(rel: &str) -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR"))
        .join("../shared/data")
        .join(rel)
}

fn load_all<S: Source>(store: &Store<S>, blocks: &[SceneBlock]) -> u64 {
    blocks
        .iter()
        .map(|b| {
            let p = b.payload;
            store.payload(p).unwrap().len() as u64
        })
        .sum()
}

/// The cameras: an oblique view across the whole terrain, and a low pass over the
/// mountains in the south-east.
fn cameras() -> Vec<(&'static str, Camera)> {
    vec![
        (
            "oblique",
            Camera::looking_at(
                DVec3::new(20_000.0, 180_000.0, 6_000.0),
                DVec3::new(80_000.0, 80_000.0, 500.0),
            ),
        ),
        (
            "low",
            Camera::looking_at(
                DVec3::new(60_000.0, 150_000.0, 2_500.0),
                DVec3::new(110_000.0, 110_000.0, 1_500.0),
            ),
        ),
    ]
}

/// A container of `rel` (a `../shared/data` `.f32`) at `spacing` metres, mapped.
fn open(dir: &std::path::Path, rel: &str, spacing: f64) -> Store<fmrh::store::MmapSource> {
    let mut hf = load(&data(rel), &IngestOptions::default()).expect("real data (../shared/data)");
    hf.metadata.spacing_m = Some([spacing, spacing]);
    let path = dir.join("bench.fmrh");
    let model = Model::build(hf.clone(), &BuildOptions::default()).unwrap();
    write_file(&model, &hf.metadata, &path, &WriteOptions::default(), true).unwrap();
    // SAFETY: the file is private to this benchmark and never written while mapped.
    unsafe { Store::open_mapped(&path) }.unwrap()
}

fn bench_store<S: Source>(
    c: &mut Criterion,
    group: &str,
    store: &Store<S>,
    cams: &[(&str, Camera)],
) {
    let terrain = Terrain::new(store).unwrap();
    let mut g = c.benchmark_group(group);
    for (name, cam) in cams {
        let cam = *cam;
        for tau in [0.5, 1.0, 2.0, 4.0] {
            let uniform = SceneOptions {
                mode: Mode::Uniform,
                ..SceneOptions::new(tau)
            };
            let view = SceneOptions::new(tau);
            let answers = [
                ("uniform", terrain.scene(&cam, &uniform).unwrap().blocks),
                ("view", terrain.scene(&cam, &view).unwrap().blocks),
                (
                    "all_finest",
                    baseline::all_finest(&terrain, &cam, None).unwrap(),
                ),
                (
                    "traversal",
                    baseline::traversal(&terrain, &cam, tau, None).unwrap(),
                ),
            ];
            for (method, blocks) in &answers {
                eprintln!(
                    "{group} {name} tau {tau}: {method:>10} {:>5} blocks {:>9} bytes",
                    blocks.len(),
                    load_all(store, blocks)
                );
            }
            let id = |m: &str, what: &str| format!("{name}/tau{tau}/{m}/{what}");
            g.bench_function(id("uniform", "select"), |b| {
                b.iter(|| terrain.scene(&cam, &uniform).unwrap().blocks.len())
            });
            g.bench_function(id("view", "select"), |b| {
                b.iter(|| terrain.scene(&cam, &view).unwrap().blocks.len())
            });
            g.bench_function(id("all_finest", "select"), |b| {
                b.iter(|| baseline::all_finest(&terrain, &cam, None).unwrap().len())
            });
            g.bench_function(id("traversal", "select"), |b| {
                b.iter(|| {
                    baseline::traversal(&terrain, &cam, tau, None)
                        .unwrap()
                        .len()
                })
            });
            g.bench_function(id("uniform", "load"), |b| {
                b.iter(|| load_all(store, &terrain.scene(&cam, &uniform).unwrap().blocks))
            });
            g.bench_function(id("view", "load"), |b| {
                b.iter(|| load_all(store, &terrain.scene(&cam, &view).unwrap().blocks))
            });
            g.bench_function(id("all_finest", "load"), |b| {
                b.iter(|| load_all(store, &baseline::all_finest(&terrain, &cam, None).unwrap()))
            });
            g.bench_function(id("traversal", "load"), |b| {
                b.iter(|| {
                    load_all(
                        store,
                        &baseline::traversal(&terrain, &cam, tau, None).unwrap(),
                    )
                })
            });
        }
    }
    g.finish();
}

/// The same τ = 1 view scene (selection and loading) from the three ways to read a file:
/// a mapping, positioned reads (`Store::open`), and a snapshot of a `Container` (the
/// live, transactional file); and what opening the file costs each way.
fn bench_sources(c: &mut Criterion, path: &std::path::Path) {
    let (_, cam) = cameras()[0];
    let view = SceneOptions::new(1.0);
    let mut g = c.benchmark_group("scene_puget_1k_sources");
    fn both<S: Source>(
        g: &mut criterion::BenchmarkGroup<'_, criterion::measurement::WallTime>,
        name: &str,
        store: &Store<S>,
        cam: &Camera,
        view: &SceneOptions,
    ) {
        let terrain = Terrain::new(store).unwrap();
        g.bench_function(format!("{name}/select"), |b| {
            b.iter(|| terrain.scene(cam, view).unwrap().blocks.len())
        });
        g.bench_function(format!("{name}/load"), |b| {
            b.iter(|| load_all(store, &terrain.scene(cam, view).unwrap().blocks))
        });
    }
    // SAFETY: the file is private to this benchmark, and the container below only reads it.
    let mapped = unsafe { Store::open_mapped(path) }.unwrap();
    both(&mut g, "mmap", &mapped, &cam, &view);
    let pread = Store::open(path).unwrap();
    both(&mut g, "pread", &pread, &cam, &view);
    // Opening: slots, registration (format §11.6) and the check of every metadata page.
    g.bench_function("pread/open", |b| {
        b.iter(|| Store::open(path).unwrap().txn_id())
    });
    g.bench_function("mmap/open", |b| {
        // SAFETY: as above.
        b.iter(|| unsafe { Store::open_mapped(path) }.unwrap().txn_id())
    });
    let container = fmrh::store::Container::open(path).unwrap();
    let snapshot = container.read().unwrap();
    both(&mut g, "snapshot", &snapshot, &cam, &view);
    g.finish();
}

fn bench(c: &mut Criterion) {
    let dir = tempfile::tempdir().unwrap();
    let store = open(dir.path(), "puget-sound-1k/ps_height_1k.f32", 160.0);
    bench_store(c, "scene_puget_1k", &store, &cameras());
    drop(store);
    bench_sources(c, &dir.path().join("bench.fmrh"));
    // The same terrain at 40 m (4096², 8-bit JPEG heights: fine for cost, not precision):
    // 16x the blocks, two more levels.
    let store = open(dir.path(), "puget-sound-4k-jpg/ps_height_4k_jpg.f32", 40.0);
    bench_store(c, "scene_puget_4k", &store, &cameras()[..1]);
}

criterion_group! {
    name = benches;
    config = Criterion::default().sample_size(30).measurement_time(std::time::Duration::from_secs(1)).warm_up_time(std::time::Duration::from_millis(300));
    targets = bench
}
criterion_main!(benches);
