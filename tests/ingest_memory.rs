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

/// Issue 39's three bombs: files whose data really decodes to what their headers declare,
/// out of all proportion to their bytes. Each is refused from its header (an error, exit 2,
/// no decoding: the peak heap stays under 64 MiB), by the proportion of samples to bytes or
/// by the memory budget, and the error says which limit and how to raise it.
#[test]
fn decompression_bombs_are_refused_from_their_headers() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let deflate = |bytes: &[u8], repeat: usize| {
        let mut z = flate2::write::ZlibEncoder::new(Vec::new(), flate2::Compression::best());
        for _ in 0..repeat {
            z.write_all(bytes).unwrap();
        }
        z.finish().unwrap()
    };
    // 1. A tiled GeoTIFF of 65536² f32 (16 GiB) in 256² tiles whose 65,536 offsets all point
    //    at one deflate stream of one zero tile (~525 KB in all). It aborted the process
    //    ("memory allocation of 17179869184 bytes failed").
    let tile = deflate(&[0u8; 256 * 4], 256);
    let n_tiles = (65536 / 256) * (65536 / 256);
    let shared_tiles = tiff::tiff_raw(
        vec![
            (256, Value::Long(vec![65536])),
            (257, Value::Long(vec![65536])),
            (258, Value::Short(vec![32])),
            (259, Value::Short(vec![8])),
            (262, Value::Short(vec![1])),
            (277, Value::Short(vec![1])),
            (322, Value::Long(vec![256])),
            (323, Value::Long(vec![256])),
            (324, Value::Long(vec![8; n_tiles])),
            (325, Value::Long(vec![tile.len() as u32; n_tiles])),
            (339, Value::Short(vec![3])),
        ],
        &tile,
    );
    // 2. A striped GeoTIFF of 32768 x 16384 f32 (2 GiB) whose 16,384 one-row strips share one
    //    deflate stream of a zero row (~66 KB in all). It built at 2.1 GB RSS.
    let row = deflate(&[0u8; 32768 * 4], 1);
    let shared_strips = tiff::tiff_raw(
        vec![
            (256, Value::Long(vec![32768])),
            (257, Value::Long(vec![16384])),
            (258, Value::Short(vec![32])),
            (259, Value::Short(vec![8])),
            (262, Value::Short(vec![1])),
            (273, Value::Long(vec![8; 16384])),
            (277, Value::Short(vec![1])),
            (278, Value::Long(vec![1])),
            (279, Value::Long(vec![row.len() as u32; 16384])),
            (339, Value::Short(vec![3])),
        ],
        &row,
    );
    // 3. An 8-bit grey PNG of 30000² whose rows are all zero (~0.9 MB). It took 106 s and
    //    5.2 GB.
    let mut ihdr = 30_000u32.to_be_bytes().to_vec();
    ihdr.extend(30_000u32.to_be_bytes());
    ihdr.extend([8, 0, 0, 0, 0]);
    let mut png = b"\x89PNG\r\n\x1a\n".to_vec();
    png.extend(hostile::png_chunk(b"IHDR", &ihdr));
    png.extend(hostile::png_chunk(
        b"IDAT",
        &deflate(&[0u8; 30_001], 30_000),
    ));
    png.extend(hostile::png_chunk(b"IEND", &[]));
    for (name, bytes, limit) in [
        ("shared-tiles.tif", &shared_tiles, "--max-memory"),
        (
            "shared-strips.tif",
            &shared_strips,
            "--max-samples-per-byte",
        ),
        ("zeros.png", &png, "--max-samples-per-byte"),
    ] {
        assert!(bytes.len() <= 2 * MIB, "{name}: {} bytes", bytes.len());
        let path = d.join(name);
        std::fs::write(&path, bytes).unwrap();
        let (result, peak) = peak_of(&path);
        let err = match result {
            Err(e) => e,
            Ok(hf) => panic!("{name}: a bomb loaded ({} x {})", hf.width(), hf.height()),
        };
        assert!(
            matches!(
                err,
                fmrh::Error::Input { .. } | fmrh::Error::TooLarge { .. }
            ),
            "{name}: {err}"
        );
        // The first bomb is past both limits; the proportion needs only the header.
        assert!(
            err.to_string().contains(limit) || err.to_string().contains("--max-"),
            "{name}: {err}"
        );
        assert!(peak <= 64 * MIB, "{name}: peak heap {} MiB", peak / MIB);
        eprintln!("bomb {name:<18} {:>8} bytes refused: {err}", bytes.len());
        // The command line: exit 2, the same message.
        let out = common::fmrh(&[
            "build",
            path.to_str().unwrap(),
            "-o",
            d.join("x.fmrh").to_str().unwrap(),
        ]);
        assert_eq!(out.status.code(), Some(2), "{name}");
        assert!(!d.join("x.fmrh").exists());
    }
    // Raised explicitly, the proportion lets the second through to the memory budget, and a
    // budget of 1 GiB refuses it there (2 GiB of f32 needs 12 GiB to build).
    let path = d.join("shared-strips.tif");
    let raised = IngestOptions {
        limits: fmrh::ingest::IngestLimits {
            max_memory: Some(1 << 30),
            max_samples_per_byte: Some(0.0),
        },
        ..IngestOptions::default()
    };
    match load(&path, &raised) {
        Err(fmrh::Error::TooLarge { detail, .. }) => assert!(detail.contains("--max-memory")),
        other => panic!("{:?}", other.map(|h| h.width())),
    }
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

/// A raster read by windows costs the window, never the raster: a 6,000 × 6,000 `f32`
/// GeoTIFF (144 MB of samples in 2.2 MB of PackBits tiles) read as a 1,000 × 700 window
/// (2.8 MB) peaks at the window, one decoded tile and the tile table, under 8 MiB; the
/// samples are the tiles' own.
#[test]
fn a_window_costs_the_window_not_the_raster() {
    const TILE: u32 = 256;
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("large.tif");
    std::fs::write(&path, tiff::packbits_tiled(6000, 6000, TILE)).unwrap();
    let base = CURRENT.load(Ordering::Relaxed);
    PEAK.store(base, Ordering::Relaxed);
    let window = fmrh::model::SampleRect {
        col0: 2500,
        row0: 4100,
        col1: 3499,
        row1: 4799,
    };
    let part = fmrh::ingest::WindowedRaster::open(&path, &IngestOptions::default())
        .and_then(|mut r| r.read(window))
        .unwrap();
    let peak = PEAK.load(Ordering::Relaxed) - base;
    assert!(
        peak <= 8 * MIB,
        "peak heap {peak} bytes for a 2.8 MB window"
    );
    let across = 6000u32.div_ceil(TILE);
    for (i, v) in part.samples().iter().enumerate() {
        let (x, y) = (2500 + i as u32 % 1000, 4100 + i as u32 / 1000);
        assert_eq!(
            *v,
            tiff::tile_value((y / TILE) * across + x / TILE),
            "({x}, {y})"
        );
    }
}
