//! `fmrh extract -o X.tif` writes a Cloud-Optimized GeoTIFF (`fmrh::export::geotiff`), and
//! what it claims holds when the bytes are read back by a reader that is not fmrh's: the
//! `tiff` crate decodes every image (the full resolution bit for bit, NaN voids included;
//! each overview the sample nearest each pixel's centre, as computed here); a TIFF parser
//! written here finds the COG layout (the ghost area first, every IFD before any tile, the
//! smallest overview's tiles first and the full resolution's last, row-major, each tile
//! with its size before it and its last four bytes after it), 512² tiles, predictor 3,
//! DEFLATE or ZSTD, classic TIFF or BigTIFF; the overviews' declared errors are the largest
//! differences measured here; a grid without a georeference still gets its spacing as a
//! geotransform; a CRS that is not an EPSG code goes beside the file as GDAL's `.aux.xml`.
//! GDAL's own validation of these files is in the large-data suite (`tests/cog_gdal.rs`).

mod common;

use fmrh::export::geotiff::{write, CogOptions, TiffCompression, Written};
use fmrh::heightfield::Georeference;
use fmrh::Heightfield;

/// A rough field with voids: 1100 × 700 (3 × 2 tiles of 512, two overviews).
fn field(w: u32, h: u32) -> Heightfield {
    let mut f = Heightfield::from_fn(w, h, |x, y| {
        let v = ((x * 7919 + y * 104_729) % 1013) as f32 * 0.37 - 90.0;
        if (x * 31 + y * 17) % 97 == 5 {
            f32::NAN
        } else {
            v
        }
    })
    .unwrap();
    f.metadata.georeference = Some(Georeference {
        crs: Some("EPSG:32610".into()),
        origin: [500_015.0, 4_100_015.0],
        step: [30.0, -30.0],
    });
    f
}

/// A little-endian TIFF's images as a parser written here reads them: each IFD's offset
/// and its fields (tag → values as u64, or the ASCII text).
struct Parsed {
    big: bool,
    ifds: Vec<(u64, std::collections::BTreeMap<u16, Vec<u64>>)>,
    ascii: std::collections::BTreeMap<(usize, u16), String>,
}

fn parse(b: &[u8]) -> Parsed {
    let u16_at = |o: usize| u16::from_le_bytes([b[o], b[o + 1]]);
    let u32_at = |o: usize| u32::from_le_bytes(b[o..o + 4].try_into().unwrap());
    let u64_at = |o: usize| u64::from_le_bytes(b[o..o + 8].try_into().unwrap());
    assert_eq!(&b[..2], b"II", "little-endian");
    let big = match u16_at(2) {
        42 => false,
        43 => true,
        v => panic!("not a TIFF: version {v}"),
    };
    let mut at = if big { u64_at(8) } else { u64::from(u32_at(4)) };
    let mut ifds = Vec::new();
    let mut ascii = std::collections::BTreeMap::new();
    while at != 0 {
        let o = at as usize;
        let (n, mut e) = if big {
            (u64_at(o) as usize, o + 8)
        } else {
            (usize::from(u16_at(o)), o + 2)
        };
        let mut fields = std::collections::BTreeMap::new();
        for _ in 0..n {
            let (tag, kind) = (u16_at(e), u16_at(e + 2));
            let count = if big {
                u64_at(e + 4)
            } else {
                u64::from(u32_at(e + 4))
            } as usize;
            let size = match kind {
                1 | 2 => 1,
                3 => 2,
                4 => 4,
                12 | 16 => 8,
                k => panic!("type {k}"),
            };
            let inline = if big { 8 } else { 4 };
            let slot = if big { e + 12 } else { e + 8 };
            let data = if size * count <= inline {
                slot
            } else if big {
                u64_at(slot) as usize
            } else {
                u32_at(slot) as usize
            };
            let values: Vec<u64> = (0..count)
                .map(|i| match kind {
                    1 | 2 => u64::from(b[data + i]),
                    3 => u64::from(u16_at(data + 2 * i)),
                    4 => u64::from(u32_at(data + 4 * i)),
                    _ => u64_at(data + 8 * i),
                })
                .collect();
            if kind == 2 {
                let text = String::from_utf8(b[data..data + count].to_vec()).unwrap();
                ascii.insert((ifds.len(), tag), text.trim_end_matches('\0').to_string());
            }
            fields.insert(tag, values);
            e += if big { 20 } else { 12 };
        }
        ifds.push((at, fields));
        at = if big { u64_at(e) } else { u64::from(u32_at(e)) };
    }
    Parsed { big, ifds, ascii }
}

/// Writes `hf` and reads it back.
fn cog(hf: &Heightfield, options: &CogOptions) -> (Vec<u8>, Written) {
    let mut bytes = Vec::new();
    let written = write(hf, options, &mut bytes).unwrap();
    (bytes, written)
}

/// Decodes every image of `bytes` with the `tiff` crate: (width, height, samples).
fn decode(bytes: &[u8]) -> Vec<(u32, u32, Vec<f32>)> {
    let mut d = tiff::decoder::Decoder::new(std::io::Cursor::new(bytes)).unwrap();
    let mut out = Vec::new();
    loop {
        let (w, h) = d.dimensions().unwrap();
        let tiff::decoder::DecodingResult::F32(v) = d.read_image().unwrap() else {
            panic!("not f32");
        };
        out.push((w, h, v));
        if !d.more_images() {
            return out;
        }
        d.next_image().unwrap();
    }
}

fn same(a: &[f32], b: &[f32]) -> bool {
    a.len() == b.len()
        && a.iter()
            .zip(b)
            .all(|(x, y)| x.to_bits() == y.to_bits() || (x.is_nan() && y.is_nan()))
}

/// The overview of `w × h` samples to `ow × oh` computed here: sample nearest each centre.
fn nearest(s: &[f32], w: u32, h: u32, ow: u32, oh: u32) -> Vec<f32> {
    let mut out = Vec::new();
    for j in 0..oh {
        let y = (((f64::from(j) + 0.5) * f64::from(h) / f64::from(oh)).floor() as u32).min(h - 1);
        for i in 0..ow {
            let x =
                (((f64::from(i) + 0.5) * f64::from(w) / f64::from(ow)).floor() as u32).min(w - 1);
            out.push(s[(y * w + x) as usize]);
        }
    }
    out
}

#[test]
fn every_image_reads_back_and_the_overviews_are_the_nearest_samples() {
    let hf = field(1100, 700);
    for compression in [TiffCompression::Deflate, TiffCompression::Zstd] {
        let options = CogOptions {
            compression,
            ..CogOptions::default()
        };
        let (bytes, written) = cog(&hf, &options);
        let images = decode(&bytes);
        let sizes: Vec<(u32, u32)> = images.iter().map(|i| (i.0, i.1)).collect();
        assert_eq!(sizes, vec![(1100, 700), (550, 350), (275, 175)]);
        assert!(
            same(&images[0].2, hf.samples()),
            "{compression:?}: full resolution"
        );
        for (k, (ow, oh, got)) in images.iter().enumerate().skip(1) {
            let want = nearest(hf.samples(), 1100, 700, *ow, *oh);
            assert!(same(got, &want), "{compression:?}: overview {k}");
            // Its declared error: the largest difference from the samples it covers.
            let mut err = 0.0f64;
            for y in 0..700u32 {
                for x in 0..1100u32 {
                    let (i, j) = (
                        ((f64::from(x) + 0.5) * f64::from(*ow) / 1100.0).floor() as u32,
                        ((f64::from(y) + 0.5) * f64::from(*oh) / 700.0).floor() as u32,
                    );
                    let (a, b) = (
                        hf.samples()[(y * 1100 + x) as usize],
                        got[(j * ow + i) as usize],
                    );
                    if !a.is_nan() && !b.is_nan() {
                        err = err.max((f64::from(a) - f64::from(b)).abs());
                    }
                }
            }
            assert_eq!(written.overviews[k - 1].max_error, err);
            assert!(err > 0.0);
        }
        assert_eq!(written.epsg, Some(32610));
        assert!(written.voids > 0);
    }
}

#[test]
fn the_layout_is_a_cloud_optimized_geotiff() {
    let hf = field(1100, 700);
    for (compression, code) in [
        (TiffCompression::Deflate, 8),
        (TiffCompression::Zstd, 50000),
    ] {
        for force_bigtiff in [false, true] {
            let options = CogOptions {
                compression,
                force_bigtiff,
                ..CogOptions::default()
            };
            let (bytes, written) = cog(&hf, &options);
            assert_eq!(written.bigtiff, force_bigtiff);
            if force_bigtiff {
                assert!(
                    same(&decode(&bytes)[0].2, hf.samples()),
                    "BigTIFF reads back"
                );
            }
            let p = parse(&bytes);
            assert_eq!(p.big, force_bigtiff);
            // The ghost area right after the header, and the first IFD right after it.
            let header = if p.big { 16 } else { 8 };
            let first = "GDAL_STRUCTURAL_METADATA_SIZE=";
            assert_eq!(&bytes[header..header + first.len()], first.as_bytes());
            let size: usize = std::str::from_utf8(&bytes[header + first.len()..][..6])
                .unwrap()
                .parse()
                .unwrap();
            let line = first.len() + 6 + " bytes\n".len();
            let ghost = std::str::from_utf8(&bytes[header + line..][..size]).unwrap();
            for item in [
                "LAYOUT=IFDS_BEFORE_DATA",
                "BLOCK_ORDER=ROW_MAJOR",
                "BLOCK_LEADER=SIZE_AS_UINT4",
                "BLOCK_TRAILER=LAST_4_BYTES_REPEATED",
                "KNOWN_INCOMPATIBLE_EDITION=NO",
            ] {
                assert!(ghost.contains(item), "{item}");
            }
            let ifd0 = (header + line + size).next_multiple_of(2) as u64;
            assert_eq!(p.ifds[0].0, ifd0);
            assert_eq!(p.ifds.len(), 3);
            let mut first_tile = Vec::new();
            for (k, (at, f)) in p.ifds.iter().enumerate() {
                assert!(k == 0 || *at > p.ifds[k - 1].0, "IFDs in order");
                assert_eq!(f[&254], vec![u64::from(k > 0)], "NewSubfileType");
                assert_eq!((f[&322][0], f[&323][0]), (512, 512), "tiles of 512");
                assert_eq!(f[&259], vec![code]);
                assert_eq!(f[&317], vec![3], "the floating-point predictor");
                assert_eq!(f[&339], vec![3], "IEEE floats");
                assert_eq!(p.ascii[&(k, 42113)], "nan", "GDAL_NODATA");
                let (offsets, counts) = (&f[&324], &f[&325]);
                // Row-major, each tile with its size before it and its last 4 bytes after.
                for (i, (&o, &n)) in offsets.iter().zip(counts).enumerate() {
                    let (o, n) = (o as usize, n as usize);
                    assert!(i == 0 || o > offsets[i - 1] as usize);
                    let leader = u32::from_le_bytes(bytes[o - 4..o].try_into().unwrap());
                    assert_eq!(leader as usize, n, "leader");
                    assert_eq!(bytes[o + n - 4..o + n], bytes[o + n..o + n + 4], "trailer");
                }
                first_tile.push(offsets[0]);
            }
            // Every IFD before any tile; the smallest overview's tiles first.
            let last_ifd = p.ifds.last().unwrap().0;
            assert!(first_tile.iter().all(|&o| o > last_ifd));
            assert!(first_tile[2] < first_tile[1] && first_tile[1] < first_tile[0]);
            // Georeferenced: the tie point is the corner of pixel (0, 0), EPSG:32610.
            let main = &p.ifds[0].1;
            assert!(main.contains_key(&33550) && main.contains_key(&33922));
            let keys = &main[&34735];
            assert!(keys.chunks(4).any(|k| k == [3072, 0, 1, 32610]), "{keys:?}");
            assert!(p.ascii[&(0, 42112)].contains("FMRH_OVERVIEW_2_MAX_ERROR"));
        }
    }
}

#[test]
fn a_small_grid_is_one_tile_and_no_overview() {
    let hf = field(300, 200);
    let (bytes, written) = cog(&hf, &CogOptions::default());
    assert!(written.overviews.is_empty());
    let images = decode(&bytes);
    assert_eq!(images.len(), 1);
    assert!(same(&images[0].2, hf.samples()));
    let p = parse(&bytes);
    assert_eq!(p.ifds[0].1[&324].len(), 1);
    // Tiles of 256 when asked: 2 × 1 of them.
    let (bytes, _) = cog(
        &hf,
        &CogOptions {
            tile: 256,
            ..CogOptions::default()
        },
    );
    assert_eq!(parse(&bytes).ifds[0].1[&324].len(), 2);
    assert!(same(&decode(&bytes)[0].2, hf.samples()));
    let refused = write(
        &hf,
        &CogOptions {
            tile: 300,
            ..CogOptions::default()
        },
        Vec::new(),
    );
    assert!(refused.is_err());
}

#[test]
fn a_grid_without_a_georeference_gets_its_spacing_as_a_geotransform() {
    let mut hf = Heightfield::from_fn(64, 48, |x, y| (x + y) as f32).unwrap();
    hf.metadata.spacing_m = Some([40.0, 25.0]);
    let (bytes, written) = cog(&hf, &CogOptions::default());
    let p = parse(&bytes);
    let main = &p.ifds[0].1;
    let doubles =
        |tag: u16| -> Vec<f64> { main[&tag].iter().map(|&v| f64::from_bits(v)).collect() };
    assert_eq!(doubles(33550), vec![40.0, 25.0, 0.0]);
    // Sample (0, 0)'s centre at (0, 0): its corner half a step west and north.
    assert_eq!(doubles(33922), vec![0.0, 0.0, 0.0, -20.0, 12.5, 0.0]);
    assert!(!main.contains_key(&34735), "no CRS, no key directory");
    assert_eq!(written.epsg, None);
    assert_eq!(written.crs_wkt, None);
    assert!(!main.contains_key(&42113), "no voids, no nodata");
}

/// Through the CLI: a container of a grid whose CRS is WKT fmrh cannot reduce to a code
/// becomes a `.tif` with the WKT in `.tif.aux.xml`; `fmrh build` of the `.tif` gives the
/// samples back; a second extract refuses to replace either file without --force, and
/// with it replaces both.
#[test]
fn fmrh_extract_writes_the_cog_and_the_wkt_beside_it() {
    let dir = tempfile::tempdir().unwrap();
    let (w, h) = (600u32, 530u32);
    let samples: Vec<f32> = (0..w * h).map(|i| ((i * 37) % 503) as f32 * 0.25).collect();
    let raw: Vec<u8> = samples.iter().flat_map(|v| v.to_le_bytes()).collect();
    std::fs::write(dir.path().join("g.f32"), raw).unwrap();
    let wkt = r#"LOCAL_CS["a site grid",LOCAL_DATUM["site",0],UNIT["metre",1]]"#;
    let json = serde_json::json!({
        "width": w, "height": h,
        "georeference": {"crs": wkt, "origin": [1000.0, 2000.0], "step": [2.0, -2.0]}
    });
    std::fs::write(dir.path().join("g.json"), json.to_string()).unwrap();
    let container = dir.path().join("g.fmrh");
    let out = common::fmrh(&[
        "build",
        dir.path().join("g.f32").to_str().unwrap(),
        "-o",
        container.to_str().unwrap(),
    ]);
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let tif = dir.path().join("g.tif");
    let aux = dir.path().join("g.tif.aux.xml");
    let extract = |extra: &[&str]| {
        let mut args = vec![
            "extract",
            container.to_str().unwrap(),
            "-o",
            tif.to_str().unwrap(),
            "--compress",
            "zstd",
        ];
        args.extend(extra);
        common::fmrh(&args)
    };
    let out = extract(&[]);
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let said = String::from_utf8_lossy(&out.stderr);
    assert!(said.contains("aux.xml"), "{said}");
    let xml = std::fs::read_to_string(&aux).unwrap();
    assert!(
        xml.contains("<SRS") && xml.contains("LOCAL_CS[&quot;a site grid&quot;"),
        "{xml}"
    );
    let bytes = std::fs::read(&tif).unwrap();
    assert_eq!(parse(&bytes).ifds[0].1[&259], vec![50000]);
    assert!(same(&decode(&bytes)[0].2, &samples));
    // Read back by fmrh's own GeoTIFF reader.
    let again = dir.path().join("again.fmrh");
    let out = common::fmrh(&[
        "build",
        tif.to_str().unwrap(),
        "-o",
        again.to_str().unwrap(),
    ]);
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let f32_out = dir.path().join("again.f32");
    let out = common::fmrh(&[
        "extract",
        again.to_str().unwrap(),
        "-o",
        f32_out.to_str().unwrap(),
    ]);
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let back: Vec<f32> = std::fs::read(&f32_out)
        .unwrap()
        .chunks_exact(4)
        .map(|b| f32::from_le_bytes(b.try_into().unwrap()))
        .collect();
    assert!(same(&back, &samples));
    // Existing outputs are kept without --force; with it both are replaced.
    let before = std::fs::read(&tif).unwrap();
    std::fs::remove_file(&tif).unwrap();
    let out = extract(&[]);
    assert_eq!(out.status.code(), Some(2), "the .aux.xml exists");
    assert!(!tif.exists());
    let out = extract(&["--force"]);
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    assert_eq!(std::fs::read(&tif).unwrap(), before);
}
