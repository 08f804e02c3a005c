//! Ingest costs memory in proportion to what an input holds, never to what its header claims.
//! A counting global allocator measures the peak heap of each load, one load at a time:
//!
//! * **hostile** inputs (each at most 2 MB, every format, each claiming a grid far larger than
//!   its data) must fail with an error and peak at most 64 MiB;
//! * **real** inputs must peak at most three times their decoded size (the `f32` grid) plus
//!   8 MiB: the grid itself, the format's raw samples, and the file's bytes.

mod common;
#[path = "common/hostile.rs"]
mod hostile;
#[path = "common/tiff.rs"]
mod tiff;

use std::alloc::{GlobalAlloc, Layout, System};
use std::io::Write;
use std::path::Path;
use std::sync::atomic::{AtomicUsize, Ordering};

use common::data;
use fmrh::ingest::{load, IngestOptions};
use tiff::Value;

struct Counting;

static CURRENT: AtomicUsize = AtomicUsize::new(0);
static PEAK: AtomicUsize = AtomicUsize::new(0);

// SAFETY: every call forwards to the system allocator with the caller's arguments; the
// counters are only arithmetic beside it.
unsafe impl GlobalAlloc for Counting {
    unsafe fn alloc(&self, layout: Layout) -> *mut u8 {
        // SAFETY: forwarded with the caller's contract.
        let p = unsafe { System.alloc(layout) };
        if !p.is_null() {
            let now = CURRENT.fetch_add(layout.size(), Ordering::Relaxed) + layout.size();
            PEAK.fetch_max(now, Ordering::Relaxed);
        }
        p
    }

    unsafe fn dealloc(&self, ptr: *mut u8, layout: Layout) {
        // SAFETY: forwarded with the caller's contract.
        unsafe { System.dealloc(ptr, layout) };
        CURRENT.fetch_sub(layout.size(), Ordering::Relaxed);
    }

    unsafe fn realloc(&self, ptr: *mut u8, layout: Layout, new_size: usize) -> *mut u8 {
        // SAFETY: forwarded with the caller's contract.
        let p = unsafe { System.realloc(ptr, layout, new_size) };
        if !p.is_null() {
            if new_size > layout.size() {
                let grow = new_size - layout.size();
                let now = CURRENT.fetch_add(grow, Ordering::Relaxed) + grow;
                PEAK.fetch_max(now, Ordering::Relaxed);
            } else {
                CURRENT.fetch_sub(layout.size() - new_size, Ordering::Relaxed);
            }
        }
        p
    }
}

#[global_allocator]
static ALLOCATOR: Counting = Counting;

const MIB: usize = 1 << 20;

/// Loads `path` and returns the result and the peak heap above what was live before.
fn peak_of(path: &Path) -> (Result<fmrh::Heightfield, fmrh::Error>, usize) {
    let base = CURRENT.load(Ordering::Relaxed);
    PEAK.store(base, Ordering::Relaxed);
    let r = load(path, &IngestOptions::default());
    (r, PEAK.load(Ordering::Relaxed) - base)
}

/// A 16-bit grey PNG whose header claims `w × h` but whose data holds `rows` rows.
fn png_claiming(w: u32, h: u32, rows: usize) -> Vec<u8> {
    let mut ihdr = w.to_be_bytes().to_vec();
    ihdr.extend(h.to_be_bytes());
    ihdr.extend([16, 0, 0, 0, 0]);
    let raw: Vec<u8> = (0..rows)
        .flat_map(|_| std::iter::once(0u8).chain(std::iter::repeat_n(7u8, 2 * w as usize)))
        .collect();
    let mut z = flate2::write::ZlibEncoder::new(Vec::new(), flate2::Compression::best());
    z.write_all(&raw).unwrap();
    let mut png = b"\x89PNG\r\n\x1a\n".to_vec();
    png.extend(hostile::png_chunk(b"IHDR", &ihdr));
    png.extend(hostile::png_chunk(b"IDAT", &z.finish().unwrap()));
    png.extend(hostile::png_chunk(b"IEND", &[]));
    png
}

/// A one-strip GeoTIFF of `w × h` f32 whose strip is `data` under compression `compression`
/// (1 none, 8 deflate).
fn tiff_claiming(w: u32, h: u32, compression: u16, data: &[u8]) -> Vec<u8> {
    tiff::tiff(
        vec![
            (256, Value::Long(vec![w])),
            (257, Value::Long(vec![h])),
            (258, Value::Short(vec![32])),
            (259, Value::Short(vec![compression])),
            (262, Value::Short(vec![1])),
            (277, Value::Short(vec![1])),
            (278, Value::Long(vec![h])),
            (339, Value::Short(vec![3])),
        ],
        &[data.to_vec()],
    )
}

/// A baseline JPEG header claiming `w × h` grey pixels, with little scan data.
fn jpeg_claiming(w: u16, h: u16) -> Vec<u8> {
    let mut j = vec![0xFF, 0xD8];
    // SOF0: length 11, 8-bit, height, width, one component (id 1, 1x1, table 0).
    j.extend([0xFF, 0xC0, 0, 11, 8]);
    j.extend(h.to_be_bytes());
    j.extend(w.to_be_bytes());
    j.extend([1, 1, 0x11, 0]);
    j.extend(std::iter::repeat_n(0u8, 4096));
    j.extend([0xFF, 0xD9]);
    j
}

#[test]
fn ingest_memory_follows_the_data_not_the_header() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let write = |name: &str, bytes: &[u8]| {
        let p = d.join(name);
        std::fs::write(&p, bytes).unwrap();
        assert!(
            bytes.len() <= 2 * MIB,
            "{name}: hostile inputs here are at most 2 MB"
        );
        p
    };
    let mut deflated = flate2::write::ZlibEncoder::new(Vec::new(), flate2::Compression::best());
    deflated.write_all(&[0u8; 1024]).unwrap();
    let deflated = deflated.finish().unwrap();
    let hostile = [
        write("bomb.dem", &hostile::usgs_dem_bomb(1024)),
        write("tall.png", &png_claiming(60_000, 60_000, 3)),
        write("wide.png", &png_claiming(1 << 20, 4000, 1)),
        write("deflate.tif", &tiff_claiming(60_000, 60_000, 8, &deflated)),
        write(
            "raw.tif",
            &tiff_claiming(60_000, 60_000, 1, &[0u8; 1 << 20]),
        ),
        write("big.jpg", &jpeg_claiming(65_000, 65_000)),
        write(
            "big.asc",
            b"ncols 1000000\nnrows 1000000\ncellsize 1\n1 2 3\n",
        ),
        write("big.json", br#"{"width": 65536, "height": 65536}"#),
    ];
    std::fs::write(d.join("big.f32"), [0u8; 1024]).unwrap();
    for path in &hostile {
        let (result, peak) = peak_of(path);
        assert!(
            result.is_err(),
            "{}: a header claiming more than the file holds was accepted",
            path.display()
        );
        assert!(
            peak <= 64 * MIB,
            "{}: peak heap {} MiB for a hostile input of at most 2 MB",
            path.display(),
            peak / MIB
        );
        eprintln!(
            "hostile {:<12} peak {:>8} KiB",
            path.file_name().unwrap().to_string_lossy(),
            peak / 1024
        );
    }
    // The bundled samples: every format but JPEG and integer GeoTIFF, which the large-data
    // suite's ingest tests cover.
    for real in [
        "puget-sound-1k/ps_height_1k.png",
        "puget-sound-east-512/ps-e.lg.png",
        "puget-sound-east-512/ps-e_lg.f32",
        "srtm1-asmyasnikov/S46W066.hgt.gz",
        "srtm3-pyhgtmap/N43E007.hgt.gz",
        "mount-st-helens-usgs/SainteHelens.dem",
        "gdal-rs-dem-hills/dem-hills.tiff",
    ] {
        let path = data(real);
        let (result, peak) = peak_of(&path);
        let hf = result.unwrap_or_else(|e| panic!("{real}: {e}"));
        let decoded = hf.samples().len() * 4;
        drop(hf);
        assert!(
            peak <= 3 * decoded + 8 * MIB,
            "{real}: peak heap {} MiB for a {} MiB grid",
            peak / MIB,
            decoded / MIB
        );
        eprintln!(
            "real {real:<40} grid {:>7} KiB peak {:>7} KiB ({:.2}x)",
            decoded / 1024,
            peak / 1024,
            peak as f64 / decoded as f64
        );
    }
}
