//! A GeoTIFF written by fmrh (`fmrh::export::geotiff`, `extract --format tif`,
//! `scene --reconstruct X.tif`) reads back as what was written: the same samples bit for
//! bit, voids where the voids were, and the same georeference (the centre of sample (0, 0),
//! the steps, the EPSG code) as fmrh's own GeoTIFF reader sees it; a grid without a
//! georeference reads back with the geotransform the writer gives it (1 a sample from the
//! origin) and no CRS. A property test writes
//! random grids with voids, north-up and south-up georeferences, geographic, projected and
//! unnamed CRSs; the committed georeferencing fixtures (GeoTIFFs made by GDAL) go through a
//! container and `fmrh extract` whole and as a window, whose georeference must be the
//! source's moved to the window's first sample.
//!
//! What GDAL says of the same files is checked in `tests/georeference_gdal.rs` (the
//! large-data suite, which has GDAL).

mod common;
#[path = "common/georef.rs"]
mod georef;

use std::path::{Path, PathBuf};

use fmrh::export::geotiff;
use fmrh::heightfield::{Georeference, Heightfield, Metadata};
use fmrh::ingest::{load, IngestOptions};
use proptest::prelude::*;

/// Writes `hf` as a GeoTIFF into `dir` and reads it back with fmrh's reader.
fn round_trip(hf: &Heightfield, dir: &Path) -> (geotiff::Written, Heightfield) {
    let path = dir.join("out.tif");
    let file = std::fs::File::create(&path).unwrap();
    let written = geotiff::write(
        hf,
        &geotiff::CogOptions::default(),
        std::io::BufWriter::new(file),
    )
    .unwrap();
    let back = load(&path, &IngestOptions::default()).unwrap();
    (written, back)
}

/// The committed georeferencing fixture `name` (made by GDAL).
fn fixture(name: &str) -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("tests/fixtures/georef")
        .join(name)
}

/// Builds `src` into `dir/NAME.fmrh` (blocks of 9 samples) with the CLI.
fn built(src: &Path, dir: &Path) -> PathBuf {
    let name = src.file_name().unwrap().to_string_lossy();
    let container = dir.join(format!("{name}.fmrh"));
    let out = common::fmrh(&[
        "build",
        src.to_str().unwrap(),
        "-o",
        container.to_str().unwrap(),
        "--block-size",
        "9",
    ]);
    assert!(
        out.status.success(),
        "{name}: {}",
        String::from_utf8_lossy(&out.stderr)
    );
    container
}

fn same_samples(a: &Heightfield, b: &Heightfield) {
    assert_eq!((a.width(), a.height()), (b.width(), b.height()));
    for (i, (x, y)) in a.samples().iter().zip(b.samples()).enumerate() {
        assert!(
            x.to_bits() == y.to_bits() || (x.is_nan() && y.is_nan()),
            "sample {i}: {x} against {y}"
        );
    }
}

fn close(a: f64, b: f64) -> bool {
    (a - b).abs() <= 1e-9 * a.abs().max(b.abs()).max(1.0)
}

fn same_georeference(a: &Georeference, b: &Georeference) {
    for i in 0..2 {
        assert!(
            close(a.origin[i], b.origin[i]),
            "origin {a:?} against {b:?}"
        );
        assert!(close(a.step[i], b.step[i]), "step {a:?} against {b:?}");
    }
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(48))]

    #[test]
    fn a_written_geotiff_reads_back_as_written(
        w in 1u32..60,
        h in 1u32..60,
        seed in 0u64..1000,
        voids in 0.0f64..0.3,
        crs in prop_oneof![
            Just(Some("EPSG:4326".to_string())),
            Just(Some("EPSG:32610".to_string())),
            Just(Some("EPSG:2927".to_string())),
            Just(Some("a local grid".to_string())),
            Just(None),
        ],
        x0 in -1.0e6f64..1.0e6,
        y0 in -1.0e6f64..1.0e6,
        sx in 0.001f64..100.0,
        sy in 0.001f64..100.0,
        south_up in proptest::bool::ANY,
        georeferenced in proptest::bool::ANY,
    ) {
        let mut hf = common::fields::make(w, h, common::fields::Character::Hills, voids, seed);
        let step = [sx, if south_up { sy } else { -sy }];
        hf.metadata = Metadata {
            georeference: georeferenced.then(|| Georeference {
                crs: crs.clone(),
                origin: [x0, y0],
                step,
            }),
            ..Metadata::default()
        };
        let dir = tempfile::tempdir().unwrap();
        let (written, back) = round_trip(&hf, dir.path());
        // fmrh's reader turns a south-up grid north-up: compare against that.
        let want = if georeferenced && south_up {
            let mut rows: Vec<f32> = Vec::with_capacity(hf.samples().len());
            for y in (0..h as usize).rev() {
                rows.extend_from_slice(&hf.samples()[y * w as usize..(y + 1) * w as usize]);
            }
            Heightfield::new(w, h, rows).unwrap()
        } else {
            hf.clone()
        };
        same_samples(&want, &back);
        let void_count = hf.samples().iter().filter(|v| v.is_nan()).count() as u64;
        prop_assert_eq!(written.voids, void_count);
        match (&hf.metadata.georeference, &back.metadata.georeference) {
            (Some(g), Some(b)) => {
                let expect = if south_up {
                    Georeference {
                        crs: g.crs.clone(),
                        origin: [g.origin[0], g.origin[1] + f64::from(h - 1) * g.step[1]],
                        step: [g.step[0], -g.step[1]],
                    }
                } else {
                    g.clone()
                };
                same_georeference(&expect, b);
                let code = g.crs.as_deref().and_then(geotiff::epsg_code);
                prop_assert_eq!(written.epsg, code);
                prop_assert_eq!(b.crs.clone(), code.map(|c| format!("EPSG:{c}")));
                prop_assert_eq!(
                    written.crs_wkt.is_some(),
                    g.crs.is_some() && code.is_none()
                );
            }
            // No georeference: the file still has a geotransform (1 a sample, sample
            // (0, 0)'s centre at the origin, rows running south), and no CRS.
            (None, Some(b)) => {
                prop_assert_eq!(written.epsg, None);
                same_georeference(
                    &Georeference {
                        crs: None,
                        origin: [0.0, 0.0],
                        step: [1.0, -1.0],
                    },
                    b,
                );
                prop_assert_eq!(b.crs.clone(), None);
            }
            (a, b) => prop_assert!(false, "georeference {a:?} read back as {b:?}"),
        }
    }
}

/// Each committed GeoTIFF fixture (made by GDAL), built into a container and extracted as
/// a GeoTIFF, whole and as a window, reads back as the source: samples and georeference.
#[test]
fn extracts_of_the_georeferencing_fixtures_read_back_as_their_sources() {
    let dir = tempfile::tempdir().unwrap();
    let mut checked = 0;
    for name in georef::GEOTIFFS {
        let src = fixture(name);
        let source = load(&src, &IngestOptions::default()).unwrap();
        let container = built(&src, dir.path());
        // Whole.
        let tif = dir.path().join(format!("{name}.out.tif"));
        let out = common::fmrh(&[
            "extract",
            container.to_str().unwrap(),
            "-o",
            tif.to_str().unwrap(),
        ]);
        assert!(
            out.status.success(),
            "{name}: {}",
            String::from_utf8_lossy(&out.stderr)
        );
        let back = load(&tif, &IngestOptions::default()).unwrap();
        same_samples(&source, &back);
        assert_eq!(
            source.metadata.spacing_m.is_some(),
            back.metadata.spacing_m.is_some()
        );
        match (&source.metadata.georeference, &back.metadata.georeference) {
            (Some(a), Some(b)) => {
                same_georeference(a, b);
                assert_eq!(a.crs, b.crs, "{name}");
            }
            (a, b) => panic!("{name}: {a:?} against {b:?}"),
        }
        // A window, by --format on a name that does not say.
        let part = dir.path().join(format!("{name}.part"));
        let out = common::fmrh(&[
            "extract",
            container.to_str().unwrap(),
            "--window",
            "1,1,4,2",
            "--format",
            "tif",
            "-o",
            part.to_str().unwrap(),
        ]);
        assert!(
            out.status.success(),
            "{name}: {}",
            String::from_utf8_lossy(&out.stderr)
        );
        let back = load(
            &part,
            &IngestOptions {
                format: Some(fmrh::ingest::Format::Geotiff),
                ..Default::default()
            },
        )
        .unwrap_or_else(|e| panic!("{name}: {e}"));
        assert_eq!((back.width(), back.height()), (4, 2));
        let w = source.width() as usize;
        for y in 0..2 {
            for x in 0..4 {
                assert_eq!(
                    back.samples()[y * 4 + x].to_bits(),
                    source.samples()[(y + 1) * w + x + 1].to_bits()
                );
            }
        }
        let (a, b) = (
            source.metadata.georeference.as_ref().unwrap(),
            back.metadata.georeference.as_ref().unwrap(),
        );
        let moved = Georeference {
            crs: a.crs.clone(),
            origin: [a.origin[0] + a.step[0], a.origin[1] + a.step[1]],
            step: a.step,
        };
        same_georeference(&moved, b);
        checked += 1;
    }
    assert_eq!(checked, georef::GEOTIFFS.len());
}

/// An existing output is kept unless --force, and a bad --format is refused.
#[test]
fn extract_to_a_geotiff_refuses_to_overwrite_and_bad_formats() {
    let dir = tempfile::tempdir().unwrap();
    let src = fixture("utm.tif");
    let container = built(&src, dir.path());
    let tif = dir.path().join("u.tif");
    std::fs::write(&tif, b"keep me").unwrap();
    let out = common::fmrh(&[
        "extract",
        container.to_str().unwrap(),
        "-o",
        tif.to_str().unwrap(),
    ]);
    assert!(!out.status.success());
    assert!(String::from_utf8_lossy(&out.stderr).contains("--force"));
    assert_eq!(std::fs::read(&tif).unwrap(), b"keep me");
    let out = common::fmrh(&[
        "extract",
        container.to_str().unwrap(),
        "--format",
        "png",
        "-o",
        tif.to_str().unwrap(),
    ]);
    assert!(!out.status.success());
    let out = common::fmrh(&[
        "extract",
        container.to_str().unwrap(),
        "-o",
        tif.to_str().unwrap(),
        "--force",
    ]);
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    assert!(load(&tif, &IngestOptions::default()).is_ok());
}

/// `scene --reconstruct X.tif` writes the same surface and georeference as the `.f32` and
/// sidecar of the same scene.
#[test]
fn a_scene_reconstructed_as_a_geotiff_is_the_f32_reconstruction() {
    let dir = tempfile::tempdir().unwrap();
    let src = fixture("utm.tif");
    let container = built(&src, dir.path());
    let scene = |output: &Path| {
        let out = common::fmrh(&[
            "scene",
            container.to_str().unwrap(),
            "--eye",
            "90,60,400",
            "--target",
            "90,60,0",
            "--tau",
            "1",
            "--window",
            "1,0,5,3",
            "--reconstruct",
            output.to_str().unwrap(),
        ]);
        assert!(
            out.status.success(),
            "{}",
            String::from_utf8_lossy(&out.stderr)
        );
    };
    let (f32_path, tif_path) = (dir.path().join("r.f32"), dir.path().join("r.tif"));
    scene(&f32_path);
    scene(&tif_path);
    let a = load(&f32_path, &IngestOptions::default()).unwrap();
    let b = load(&tif_path, &IngestOptions::default()).unwrap();
    assert_eq!((b.width(), b.height()), (5, 4));
    same_samples(&a, &b);
    let (ga, gb) = (
        a.metadata.georeference.as_ref().unwrap(),
        b.metadata.georeference.as_ref().unwrap(),
    );
    same_georeference(ga, gb);
    assert_eq!(gb.crs.as_deref(), Some("EPSG:32610"));
    // The window starts at column 1: the source's georeference moved one step east.
    let source = load(&src, &IngestOptions::default()).unwrap();
    let g = source.metadata.georeference.unwrap();
    let moved = Georeference {
        crs: g.crs.clone(),
        origin: [g.origin[0] + g.step[0], g.origin[1]],
        step: g.step,
    };
    same_georeference(&moved, gb);
}
