//! Container figures on real DEMs: range-scan cost per returned node from a warm mapping
//! (Puget Sound 4k, the finest and a middle cluster, windows of several sizes), and the
//! whole build (model + write to a file, fsync included) of Puget Sound 4k. Scan time is
//! reported per scan; divide by the node counts the harness prints to get time per node.

use std::path::PathBuf;

use criterion::{criterion_group, criterion_main, BatchSize, Criterion, Throughput};
use fmrh::curve::HilbertKey;
use fmrh::ingest::{load, IngestOptions};
use fmrh::model::{BuildOptions, Model};
use fmrh::store::Store;
use fmrh::store::{write_file, WriteOptions};

fn data(rel: &str) -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR"))
        .join("../shared/data")
        .join(rel)
}

fn bench(c: &mut Criterion) {
    let hf = load(
        &data("puget-sound-4k-jpg/ps_height_4k_jpg.json"),
        &IngestOptions::default(),
    )
    .expect("real data (../shared/data)");
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("ps4k.fmrh");
    let model = Model::build(hf.clone(), &BuildOptions::default()).unwrap();
    write_file(&model, &hf.metadata, &path, &WriteOptions::default(), true).unwrap();
    // SAFETY: the file is private to this benchmark and never written while mapped.
    let store = unsafe { Store::open_mapped(&path) }.unwrap();
    let finest = store.domain().finest_level();
    let span = HilbertKey::span(finest, 0);

    let mut g = c.benchmark_group("scan_puget_4k");
    for cluster in [0usize, store.clusters().len() / 2] {
        for fraction in [64u64, 8, 1] {
            let (lo, hi) = (span / 3, span / 3 + span / fraction - 1);
            let n = store.scan_hilbert(cluster, lo..=hi).unwrap().count() as u64;
            eprintln!("cluster {cluster}, 1/{fraction} of the curve: {n} nodes");
            g.throughput(Throughput::Elements(n));
            g.bench_function(format!("hilbert_c{cluster}_1of{fraction}"), |b| {
                b.iter(|| {
                    store
                        .scan_hilbert(cluster, lo..=hi)
                        .unwrap()
                        .map(|e| e.unwrap().node)
                        .sum::<u32>()
                })
            });
            g.bench_function(format!("hilbert_records_c{cluster}_1of{fraction}"), |b| {
                b.iter(|| {
                    store
                        .scan_hilbert(cluster, lo..=hi)
                        .unwrap()
                        .map(|e| store.node(e.unwrap().node).unwrap().monotone_error)
                        .sum::<f64>()
                })
            });
        }
        let n = store.clusters()[cluster].nodes().min(200);
        g.throughput(Throughput::Elements(n));
        g.bench_function(format!("codes_c{cluster}_{n}"), |b| {
            b.iter(|| {
                store
                    .scan_codes(cluster, 10..10 + n)
                    .unwrap()
                    .map(|e| e.unwrap().node)
                    .sum::<u32>()
            })
        });
    }
    g.finish();

    let mut g = c.benchmark_group("build_write_puget_4k");
    g.sample_size(10);
    let out = dir.path().join("again.fmrh");
    g.bench_function("model_and_write", |b| {
        b.iter_batched(
            || hf.clone(),
            |hf| {
                let metadata = hf.metadata.clone();
                let model = Model::build(hf, &BuildOptions::default()).unwrap();
                write_file(&model, &metadata, &out, &WriteOptions::default(), true).unwrap()
            },
            BatchSize::LargeInput,
        )
    });
    g.finish();
}

criterion_group!(benches, bench);
criterion_main!(benches);
