//! Malformed input never panics, never allocates from an unchecked size, and always names the
//! file. Crafted headers claim absurd sizes. Real files are truncated at every kind of place,
//! and property tests flip, cut and replace bytes of real files of every format.

mod common;
#[path = "common/hostile.rs"]
mod hostile;

use std::path::{Path, PathBuf};

use common::data;
use fmrh::ingest::{load, ColorEncoding, IngestOptions};
use fmrh::Error;
use proptest::prelude::*;

fn write(dir: &Path, name: &str, bytes: &[u8]) -> PathBuf {
    let p = dir.join(name);
    std::fs::write(&p, bytes).unwrap();
    p
}

fn load_default(p: &Path) -> Result<fmrh::Heightfield, Error> {
    load(p, &IngestOptions::default())
}

/// An input error that names `file` (malformed, unsupported or too large).
fn assert_input_error(result: Result<fmrh::Heightfield, Error>, file: &Path) {
    match result {
        Err(Error::Input { path, .. } | Error::Unsupported { path, .. }) => {
            assert_eq!(path.file_name(), file.file_name())
        }
        Err(Error::TooLarge { .. }) => {}
        Err(e) => panic!("{}: expected an input error, got {e:?}", file.display()),
        Ok(_) => panic!("{}: malformed input was accepted", file.display()),
    }
}

#[test]
fn raw_f32_pairs() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    write(d, "a.json", br#"{"width": 10, "height": 10}"#);
    let f = write(d, "a.f32", &[0u8; 399]);
    assert_input_error(load_default(&f), &f);
    // Absurd size: refused from the sidecar, before touching the .f32.
    let j = write(
        d,
        "b.json",
        br#"{"width": 1000000000, "height": 1000000000}"#,
    );
    write(d, "b.f32", &[0u8; 4]);
    assert_input_error(load_default(&j), &j);
    let j = write(d, "c.json", br#"{"width": "ten"}"#);
    assert_input_error(load_default(&j), &j);
    let f = write(d, "lonely.f32", &[0u8; 16]);
    assert_input_error(load_default(&f), &f);
    write(d, "inf.json", br#"{"width": 2, "height": 1}"#);
    let mut bytes = 1.0f32.to_le_bytes().to_vec();
    bytes.extend(f32::INFINITY.to_le_bytes());
    let f = write(d, "inf.f32", &bytes);
    assert_input_error(load_default(&f), &f);
}

#[test]
fn srtm_tiles() {
    let dir = tempfile::tempdir().unwrap();
    let f = write(dir.path(), "N00E000.hgt", &[0u8; 1201 * 1201 * 2 - 2]);
    assert_input_error(load_default(&f), &f);
    let f = write(dir.path(), "N00E000.hgt.gz", b"\x1f\x8b\x08\x00garbage");
    assert_input_error(load_default(&f), &f);
    // A gzip bomb: far more than a tile decompresses, and is cut off at one tile's size.
    let mut enc = flate2::write::GzEncoder::new(Vec::new(), flate2::Compression::fast());
    std::io::Write::write_all(&mut enc, &vec![0u8; 40 << 20]).unwrap();
    let f = write(dir.path(), "N01E000.hgt.gz", &enc.finish().unwrap());
    assert_input_error(load_default(&f), &f);
}

fn tiff_header(width: u32, height: u32, bits: u16, samples: u16) -> Vec<u8> {
    // Little-endian TIFF with one IFD: width, length, bits per sample, compression 1,
    // photometric 1, strip offset 0, samples per pixel, rows per strip, strip byte count 0.
    let entries: [(u16, u16, u32); 9] = [
        (256, 4, width),
        (257, 4, height),
        (258, 3, u32::from(bits)),
        (259, 3, 1),
        (262, 3, 1),
        (273, 4, 200),
        (277, 3, u32::from(samples)),
        (278, 4, height),
        (279, 4, 0),
    ];
    let mut b = b"II*\0\x08\0\0\0".to_vec();
    b.extend((entries.len() as u16).to_le_bytes());
    for (tag, kind, value) in entries {
        b.extend(tag.to_le_bytes());
        b.extend(kind.to_le_bytes());
        b.extend(1u32.to_le_bytes());
        if kind == 3 {
            b.extend((value as u16).to_le_bytes());
            b.extend([0, 0]);
        } else {
            b.extend(value.to_le_bytes());
        }
    }
    b.extend(0u32.to_le_bytes());
    b.resize(256, 0);
    b
}

#[test]
fn geotiffs() {
    let dir = tempfile::tempdir().unwrap();
    let f = write(
        dir.path(),
        "huge.tif",
        &tiff_header(1_000_000, 1_000_000, 16, 1),
    );
    assert_input_error(load_default(&f), &f);
    let f = write(dir.path(), "rgb.tif", &tiff_header(4, 4, 8, 3));
    assert_input_error(load_default(&f), &f);
    let f = write(dir.path(), "empty.tif", &tiff_header(4, 4, 16, 1));
    assert_input_error(load_default(&f), &f);
    // A real float GeoTIFF (bundled), cut in its header, its tags and its image data (which
    // fills most of the file; its last bytes are not image data).
    let real = std::fs::read(data("gdal-rs-dem-hills/dem-hills.tiff")).unwrap();
    for cut in [8, 100, 1000, real.len() / 2, real.len() * 3 / 4] {
        let f = write(dir.path(), "cut.tif", &real[..cut]);
        assert_input_error(load_default(&f), &f);
    }
}

fn png_header(width: u32, height: u32, depth: u8, color: u8) -> Vec<u8> {
    let mut ihdr = width.to_be_bytes().to_vec();
    ihdr.extend(height.to_be_bytes());
    ihdr.extend([depth, color, 0, 0, 0]);
    let mut b = b"\x89PNG\r\n\x1a\n".to_vec();
    b.extend(hostile::png_chunk(b"IHDR", &ihdr));
    b
}

#[test]
fn pngs() {
    let dir = tempfile::tempdir().unwrap();
    let mut huge = png_header(1_000_000, 1_000_000, 16, 0);
    huge.extend(hostile::png_chunk(b"IEND", &[]));
    let f = write(dir.path(), "huge.png", &huge);
    assert_input_error(load_default(&f), &f);
    let real = std::fs::read(data("puget-sound-east-512/ps-e.lg.png")).unwrap();
    for cut in [8, 33, 1000, real.len() / 2, real.len() - 13] {
        let f = write(dir.path(), "cut.png", &real[..cut]);
        assert_input_error(load_default(&f), &f);
    }
    // 16-bit RGB is no heightfield coding.
    let enc_path = dir.path().join("rgb16.png");
    let file = std::fs::File::create(&enc_path).unwrap();
    let mut enc = png::Encoder::new(file, 2, 2);
    enc.set_color(png::ColorType::Rgb);
    enc.set_depth(png::BitDepth::Sixteen);
    enc.write_header()
        .unwrap()
        .write_image_data(&[0u8; 24])
        .unwrap();
    let options = IngestOptions {
        color_encoding: Some(ColorEncoding::TerrainRgb),
        ..IngestOptions::default()
    };
    assert_input_error(load(&enc_path, &options), &enc_path);
}

#[test]
fn esri_ascii_grids() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let header = "ncols 3\nnrows 2\nxllcorner 0\nyllcorner 0\ncellsize 1\nNODATA_value -9999\n";
    let ok = write(
        d,
        "ok.asc",
        format!("{header}1 2 3\n4 -9999 6\n").as_bytes(),
    );
    let hf = load_default(&ok).unwrap();
    assert_eq!((hf.width(), hf.height(), hf.void_count()), (3, 2, 1));
    let cases: [(&str, String); 6] = [
        ("short.asc", format!("{header}1 2 3\n4 5\n")),
        ("long.asc", format!("{header}1 2 3\n4 5 6 7\n")),
        ("text.asc", format!("{header}1 2 3\n4 five 6\n")),
        (
            "huge.asc",
            "ncols 1000000\nnrows 1000000\ncellsize 1\n1 2 3\n".to_string(),
        ),
        ("nokey.asc", "nrows 2\ncellsize 1\n1 2\n".to_string()),
        ("odd.asc", format!("{header}colour blue\n1 2 3\n4 5 6\n")),
    ];
    for (name, text) in cases {
        let f = write(d, name, text.as_bytes());
        assert_input_error(load_default(&f), &f);
    }
}

#[test]
fn usgs_dems() {
    let dir = tempfile::tempdir().unwrap();
    let real = std::fs::read(data("mount-st-helens-usgs/SainteHelens.dem")).unwrap();
    for cut in [0, 500, 1024, 1100, 5000, real.len() / 2] {
        let f = write(dir.path(), "cut.dem", &real[..cut]);
        assert_input_error(load_default(&f), &f);
    }
    let mut bad = real.clone();
    bad[858..864].copy_from_slice(b"999999"); // more profiles than the file holds
    let f = write(dir.path(), "profiles.dem", &bad);
    assert_input_error(load_default(&f), &f);
}

/// Regression (issue 13): a 1 MB file whose profiles' northings span 2^20 rows allocated a
/// 4 GiB grid and aborted; 256 such profiles built for 45 s into a 2.2 GB container. The grid
/// is now bounded by the elevations the file holds.
#[test]
fn usgs_dem_profiles_spanning_more_than_they_hold_are_refused() {
    let dir = tempfile::tempdir().unwrap();
    for n in [2, 256, 1024] {
        let f = write(
            dir.path(),
            &format!("bomb{n}.dem"),
            &hostile::usgs_dem_bomb(n),
        );
        // The proportion of samples to bytes (issue 39) refuses the larger ones first; with
        // it lifted, this checks the format's own bound.
        let lifted = IngestOptions {
            limits: fmrh::ingest::IngestLimits::none(),
            ..IngestOptions::default()
        };
        let err = load(&f, &lifted).unwrap_err();
        assert!(err.to_string().contains("elevations"), "{err}");
        assert_input_error(Err(err), &f);
        assert_input_error(load_default(&f), &f);
    }
    // A well-formed small DEM with staggered profiles (a rotated quadrangle) still reads.
    let ok = hostile::usgs_dem(&[
        (0.0, vec![1, 2, 3, 4]),
        (30.0, vec![5, 6, 7, 8]),
        (60.0, vec![9, 10, 11]),
    ]);
    let f = write(dir.path(), "ok.dem", &ok);
    let hf = load_default(&f).unwrap();
    assert_eq!((hf.width(), hf.height()), (3, 5));
    assert_eq!(hf.void_count(), 4);
}

/// Regression (issue 13): negative, zero or infinite spacing was accepted and reached scenes.
#[test]
fn spacing_must_be_finite_and_positive() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    for (i, spacing) in ["[-30, 0]", "[30, 0]", "[0, 30]", "[30, -30]", "[1e400, 30]"]
        .iter()
        .enumerate()
    {
        let json = format!(r#"{{"width": 2, "height": 1, "spacing_m": {spacing}}}"#);
        let j = write(d, &format!("s{i}.json"), json.as_bytes());
        let f = write(d, &format!("s{i}.f32"), &[0u8; 8]);
        // 1e400 fails in the sidecar's JSON (it names the .json), the others in the checks.
        let named = if spacing.contains("1e400") { &j } else { &f };
        assert_input_error(load_default(&j), named);
    }
    for cell in ["cellsize -1", "cellsize 0", "dx 1\ndy -1", "cellsize inf"] {
        let text = format!("ncols 2\nnrows 1\nxllcorner 0\nyllcorner 0\n{cell}\n1 2\n");
        let f = write(d, "neg.asc", text.as_bytes());
        assert_input_error(load_default(&f), &f);
    }
    write(
        d,
        "fine.json",
        br#"{"width": 2, "height": 1, "spacing_m": [30, 30]}"#,
    );
    let f = write(d, "fine.f32", &[0u8; 8]);
    assert_eq!(
        load_default(&f).unwrap().metadata.spacing_m,
        Some([30.0, 30.0])
    );
}

#[test]
fn undetectable_format() {
    let dir = tempfile::tempdir().unwrap();
    let f = write(dir.path(), "mystery.bin", b"hello");
    assert_input_error(load_default(&f), &f);
}

/// Real files of every format, each in its own extension.
fn real_files() -> Vec<(PathBuf, &'static str)> {
    vec![
        (data("gdal-rs-dem-hills/dem-hills.tiff"), "x.tiff"),
        (data("puget-sound-east-512/ps-e.lg.png"), "x.png"),
        (data("mount-st-helens-usgs/SainteHelens.dem"), "x.dem"),
        (data("puget-sound-east-512/ps-e_lg.f32"), "x.f32"),
        (data("srtm1-asmyasnikov/S46W066.hgt.gz"), "N00E000.hgt.gz"),
    ]
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(48))]

    /// Damaged real files load or fail cleanly; they never panic.
    #[test]
    fn damaged_files_never_panic(which in 0usize..5, edits in prop::collection::vec((any::<prop::sample::Index>(), any::<u8>()), 1..8), cut in prop::option::of(any::<prop::sample::Index>())) {
        let dir = tempfile::tempdir().unwrap();
        let (source, name) = &real_files()[which];
        let mut bytes = std::fs::read(source).unwrap();
        for (at, value) in edits {
            let i = at.index(bytes.len());
            bytes[i] = value;
        }
        if let Some(c) = cut {
            let len = c.index(bytes.len());
            bytes.truncate(len);
        }
        if name.ends_with(".f32") {
            std::fs::copy(source.with_extension("json"), dir.path().join("x.json")).unwrap();
        }
        let f = write(dir.path(), name, &bytes);
        let _ = load_default(&f);
    }

    /// Arbitrary bytes under every extension load or fail cleanly.
    #[test]
    fn arbitrary_bytes_never_panic(bytes in prop::collection::vec(any::<u8>(), 0..4096), ext in prop::sample::select(vec!["hgt", "hgt.gz", "tif", "png", "jpg", "asc", "dem", "json"])) {
        let dir = tempfile::tempdir().unwrap();
        let f = write(dir.path(), &format!("N10E010.{ext}"), &bytes);
        let _ = load_default(&f);
    }
}

/// Regression (issue 39, found by the `ingest` fuzz target): a 705-byte TIFF whose
/// GeoKeyDirectory declares 926 M shorts made the `tiff` crate ask for 29.6 GB before reading
/// them, and the process aborted. Every tag's declared size is now checked against the file
/// first: an input error.
#[test]
fn a_tiff_tag_declaring_more_than_the_file_holds_is_refused() {
    let input = std::fs::read(
        PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("fuzz/corpus/ingest/regress-tag-count-29gb"),
    )
    .unwrap();
    let dir = tempfile::tempdir().unwrap();
    // The fuzz target's first byte picks the format (2: a `.tif`).
    assert_eq!(input[0], 2);
    let f = write(dir.path(), "x.tif", &input[1..]);
    let err = load_default(&f).unwrap_err();
    assert!(err.to_string().contains("more than the whole"), "{err}");
    assert_input_error(Err(err), &f);
}
