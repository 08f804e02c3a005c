//! Block codecs on real DEMs: how much of the raw `f32` each keeps, and how fast blocks
//! encode and decode, on the 65² blocks a container stores (neighbours share an edge, as in
//! `format-spec/model.md`). Beside fmrh's codec (`fmrh::codec`, which picks per block), the
//! general-purpose baselines a COG uses: DEFLATE (flate2, default level) and zstd (level 3) on
//! the raw bytes. Every fmrh block is decoded and compared bit for bit before it is counted.
//!
//!     cargo bench --bench codecs          (needs ../shared/data)
//!
//! Prints one table; times are the median of 5 passes over all blocks of a DEM, in MB of
//! raw `f32` per second, so the ratios between columns are what to read on a noisy machine.

use std::io::Write;
use std::path::PathBuf;
use std::time::Instant;

use fmrh::codec::{self, Encoding};
use fmrh::ingest::{load, IngestOptions};

const BLOCK: usize = 65;

fn data(rel: &str) -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR"))
        .join("../shared/data")
        .join(rel)
}

/// The blocks of a `w × h` grid, stride `BLOCK - 1`, clipped at the edges.
fn blocks(w: usize, h: usize, v: &[f32]) -> Vec<(usize, Vec<f32>)> {
    let mut out = Vec::new();
    for y in (0..h.saturating_sub(1).max(1)).step_by(BLOCK - 1) {
        for x in (0..w.saturating_sub(1).max(1)).step_by(BLOCK - 1) {
            let (bw, bh) = (BLOCK.min(w - x), BLOCK.min(h - y));
            let mut b = Vec::with_capacity(bw * bh);
            for r in 0..bh {
                b.extend_from_slice(&v[(y + r) * w + x..(y + r) * w + x + bw]);
            }
            // Voids as the store keeps them: the canonical NaN.
            for s in &mut b {
                if s.is_nan() {
                    *s = f32::from_bits(codec::VOID_BITS);
                }
            }
            out.push((bw, b));
        }
    }
    out
}

fn median(mut t: Vec<f64>) -> f64 {
    t.sort_by(f64::total_cmp);
    t[t.len() / 2]
}

fn main() {
    let files = [
        ("Puget 1k (0.1 m)", "puget-sound-1k/ps_height_1k.json"),
        (
            "Puget 4k (JPEG)",
            "puget-sound-4k-jpg/ps_height_4k_jpg.json",
        ),
        ("Fuji (Terrain-RGB)", "fuji-terrain-rgb/fuji.json"),
        ("SRTM3 N43E007", "srtm3-pyhgtmap/N43E007.json"),
        ("SRTM3 N22W160 (voids)", "srtm3-srtmpy/N22W160.json"),
        ("SRTM1 S46W066 (sea)", "srtm1-asmyasnikov/S46W066.json"),
        ("St Helens (USGS)", "mount-st-helens-usgs/SainteHelens.json"),
        ("Big Tujunga", "topotoolbox-bigtujunga/bigtujunga.json"),
        ("dem-hills (float)", "gdal-rs-dem-hills/dem_hills.json"),
    ];
    println!(
        "{:<24} {:>6} {:>8} {:>8} {:>8} | {:>9} {:>9} {:>9} | blocks per encoding [raw, const, lattice, pco, predicted]",
        "DEM", "blocks", "deflate", "zstd", "fmrh", "enc MB/s", "dec MB/s", "zstd dec"
    );
    for (name, rel) in files {
        let hf = load(&data(rel), &IngestOptions::default())
            .unwrap_or_else(|e| panic!("{}: {e} (this benchmark needs ../shared/data)", rel));
        let (w, h) = (hf.width() as usize, hf.height() as usize);
        let bs = blocks(w, h, hf.samples());
        let raw: usize = bs.iter().map(|(_, b)| 4 * b.len()).sum();
        let raw_bytes: Vec<Vec<u8>> = bs
            .iter()
            .map(|(_, b)| b.iter().flat_map(|v| v.to_le_bytes()).collect())
            .collect();
        let deflate: usize = raw_bytes
            .iter()
            .map(|r| {
                let mut e =
                    flate2::write::DeflateEncoder::new(Vec::new(), flate2::Compression::default());
                e.write_all(r).expect("deflate");
                e.finish().expect("deflate").len()
            })
            .sum();
        let zstd: Vec<Vec<u8>> = raw_bytes
            .iter()
            .map(|r| zstd::bulk::compress(r, 3).expect("zstd"))
            .collect();
        let mut encoded = Vec::new();
        let mut enc_times = Vec::new();
        for _ in 0..5 {
            let t = Instant::now();
            encoded = bs.iter().map(|(bw, b)| codec::encode(b, *bw)).collect();
            enc_times.push(t.elapsed().as_secs_f64());
        }
        let mut counts = [0usize; 5];
        for e in &encoded {
            counts[Encoding::of(e).expect("an encoding") as usize] += 1;
        }
        let mut out: Vec<Vec<f32>> = bs.iter().map(|(_, b)| vec![0.0; b.len()]).collect();
        let mut dec_times = Vec::new();
        for _ in 0..5 {
            let t = Instant::now();
            for ((e, (bw, _)), o) in encoded.iter().zip(&bs).zip(&mut out) {
                codec::decode(e, *bw, o).expect("decodes");
            }
            dec_times.push(t.elapsed().as_secs_f64());
        }
        for ((_, b), o) in bs.iter().zip(&out) {
            assert!(
                b.iter().zip(o).all(|(a, c)| a.to_bits() == c.to_bits()),
                "{name}: a block did not round-trip"
            );
        }
        let mut zstd_times = Vec::new();
        for _ in 0..5 {
            let t = Instant::now();
            for (z, r) in zstd.iter().zip(&raw_bytes) {
                std::hint::black_box(zstd::bulk::decompress(z, r.len()).expect("zstd"));
            }
            zstd_times.push(t.elapsed().as_secs_f64());
        }
        let fmrh: usize = encoded.iter().map(Vec::len).sum();
        let zstd_len: usize = zstd.iter().map(Vec::len).sum();
        let ratio = |n: usize| n as f64 / raw as f64;
        let speed = |t: Vec<f64>| raw as f64 / median(t) / 1e6;
        println!(
            "{:<24} {:>6} {:>8.3} {:>8.3} {:>8.3} | {:>9.0} {:>9.0} {:>9.0} | {:?}",
            name,
            bs.len(),
            ratio(deflate),
            ratio(zstd_len),
            ratio(fmrh),
            speed(enc_times),
            speed(dec_times),
            speed(zstd_times),
            counts
        );
    }
}
