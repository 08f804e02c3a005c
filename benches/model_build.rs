//! Model build time on real DEMs: void mending, every node's error at every level, monotone
//! errors, pruning and the default clusters, from a heightfield already in memory. The input
//! copy made for each run is not timed. Ingest (reading the `.f32`) is timed separately.
//! Puget Sound 4k is the 4096 x 4096 target case (under 5 s on the 2-core machine).

use std::path::PathBuf;

use criterion::{criterion_group, criterion_main, BatchSize, Criterion};
use fmrh::ingest::{load, IngestOptions};
use fmrh::model::{BuildOptions, Model};

fn data(rel: &str) -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR"))
        .join("../shared/data")
        .join(rel)
}

fn bench(c: &mut Criterion) {
    let mut g = c.benchmark_group("model_build");
    g.sample_size(10);
    for (name, rel) in [
        ("puget_1k", "puget-sound-1k/ps_height_1k.json"),
        ("srtm3_N22W160_voids", "srtm3-srtmpy/N22W160.json"),
        ("srtm1_S46W066", "srtm1-asmyasnikov/S46W066.json"),
        ("puget_4k", "puget-sound-4k-jpg/ps_height_4k_jpg.json"),
    ] {
        let hf = load(&data(rel), &IngestOptions::default()).expect("real data (../shared/data)");
        g.bench_function(name, |b| {
            b.iter_batched(
                || hf.clone(),
                |hf| Model::build(hf, &BuildOptions::default()).unwrap(),
                BatchSize::LargeInput,
            )
        });
    }
    g.bench_function("ingest_puget_4k_f32", |b| {
        b.iter(|| {
            load(
                &data("puget-sound-4k-jpg/ps_height_4k_jpg.json"),
                &IngestOptions::default(),
            )
            .unwrap()
        })
    });
    g.finish();
}

criterion_group!(benches, bench);
criterion_main!(benches);
