//! Key encoding speed: nanoseconds per Hilbert encode and decode at the orders fmrh uses (a
//! tree's finest level is at most 17) and at the maximum, 32, plus the Morton key with its
//! non-pointer bounds. Each iteration converts a batch of 4096 random cells; criterion reports
//! time per element.

use criterion::{criterion_group, criterion_main, BenchmarkId, Criterion, Throughput};
use fmrh::curve::{hilbert_decode, hilbert_encode, MortonKey};
use std::hint::black_box;

fn cells(order: u32, n: usize) -> Vec<(u32, u32)> {
    let mut s = 0x1234_5678_9ABC_DEF0u64;
    let mask = if order == 32 {
        u32::MAX
    } else {
        (1u32 << order) - 1
    };
    (0..n)
        .map(|_| {
            s ^= s << 13;
            s ^= s >> 7;
            s ^= s << 17;
            ((s as u32) & mask, ((s >> 32) as u32) & mask)
        })
        .collect()
}

fn bench(c: &mut Criterion) {
    const N: usize = 4096;
    let mut g = c.benchmark_group("hilbert");
    g.throughput(Throughput::Elements(N as u64));
    for order in [6u32, 10, 16, 32] {
        let pts = cells(order, N);
        g.bench_with_input(BenchmarkId::new("encode", order), &pts, |b, pts| {
            b.iter(|| {
                let mut acc = 0u64;
                for &(x, y) in pts {
                    acc ^= hilbert_encode(black_box(order), x, y);
                }
                acc
            })
        });
        let keys: Vec<u64> = pts
            .iter()
            .map(|&(x, y)| hilbert_encode(order, x, y))
            .collect();
        g.bench_with_input(BenchmarkId::new("decode", order), &keys, |b, keys| {
            b.iter(|| {
                let mut acc = 0u32;
                for &d in keys {
                    let (x, y) = hilbert_decode(black_box(order), d);
                    acc ^= x ^ y;
                }
                acc
            })
        });
    }
    g.finish();

    let mut g = c.benchmark_group("morton");
    g.throughput(Throughput::Elements(N as u64));
    let pts = cells(16, N);
    g.bench_function("key_and_bounds_16", |b| {
        b.iter(|| {
            let mut acc = 0u64;
            for &(x, y) in &pts {
                let k = MortonKey::from_node(black_box(16), x, y);
                acc ^= k.bounds(64 << 16).left;
            }
            acc
        })
    });
    g.finish();
}

criterion_group!(benches, bench);
criterion_main!(benches);
