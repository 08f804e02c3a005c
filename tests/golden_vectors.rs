//! The format is pinned: the small containers in `format-spec/vectors/` are rebuilt from the
//! fixed heightfields below and must come out byte for byte identical, and `fmrh info --json`
//! on each stored file must print exactly the stored `.info.json`. A change to the writer, the
//! layout, the model or the reader makes this fail. If the change is deliberate, it is a
//! format change: bump the version per the policy in `format-spec/container.md`, then
//! regenerate with `FMRH_BLESS=1 cargo test --release --test golden_vectors`.
//!
//! Files of older versions stay readable: `format-spec/vectors/v1.1/`, `v1.2/`, `v2.0/`,
//! `v2.1/`, `v3.0/`, `v4.0/`, `v5.0/`, `v6.0/`, `v6.1/` and `v6.2/` keep the same vectors as
//! those versions wrote them. They must read and verify exactly as the current ones do; 2.x
//! to 6.2 files accept a transaction (which makes them 7.0), 1.x files refuse one. The polar vector (format 6.0: a
//! longitude-latitude grid at 80° N whose coarse grids are thinned by area) has no older copy.
//!
//! Three more pins: a crafted vector (`slot-1-beside-invalid-slot-0.fmrh`: where slot 1 lies
//! when slot 0 is sealed but invalid, §3); every `.info.json` under `format-spec/vectors/`
//! is what `fmrh info --json` prints today; and `container.md` states the code's
//! `FORMAT_MAJOR.FORMAT_MINOR` and last minors.

use std::io::Cursor;
use std::path::PathBuf;
use std::process::Command;

use fmrh::codec::Encoding;
use fmrh::heightfield::{Georeference, Metadata};
use fmrh::model::{BuildOptions, Model, Thresholds};
use fmrh::store::{write_to, WriteOptions};
use fmrh::types::VerticalDatum;
use fmrh::Heightfield;

struct Vector {
    name: &'static str,
    field: Heightfield,
    block_size: u32,
    thresholds: Thresholds,
    /// The storage precision (format 2.1); the vectors of older versions have none.
    precision: Option<f64>,
    /// Written with every table in pages of its own (no metadata bundle, format 3.0): the
    /// layout of a state whose metadata is too large to bundle. Older versions have no
    /// such vector.
    paged: bool,
    /// Thinned by area (format 6.0): no older version has it.
    thinned: bool,
}

fn vectors() -> Vec<Vector> {
    let ramp = Heightfield::from_fn(9, 9, |x, y| (x + 2 * y) as f32).unwrap();
    let mut hills = Heightfield::from_fn(20, 13, |x, y| {
        if (x, y) == (3, 4) || (x, y) == (15, 0) || (x, y) == (19, 12) {
            f32::NAN
        } else {
            ((x as f32 * 0.7).sin() * 40.0 + (y as f32 * 0.45).cos() * 25.0).round()
        }
    })
    .unwrap();
    hills.metadata = Metadata {
        spacing_m: Some([30.0, 30.0]),
        georeference: Some(Georeference {
            crs: Some("EPSG:4326".into()),
            origin: [-160.0, 23.0],
            step: [0.001, -0.001],
        }),
        units: Some("metres".into()),
        source_format: "test".into(),
        // Format 6.1 records it (byte 156 of the dataset header: 3).
        vertical_datum: VerticalDatum::Egm96,
    };
    let hills_paged = hills.clone();
    let cliff = Heightfield::from_fn(33, 33, |x, _| if x < 11 { 10.0 } else { 500.0 }).unwrap();
    // Float heights off every lattice, stored to a step of 0.3.
    let waves = Heightfield::from_fn(17, 17, |x, y| {
        (x as f32 * 0.41).sin() * 7.3 + (y as f32 * 0.29).cos() * 4.1 + 100.0
    })
    .unwrap();
    // At 80° N a column is 0.17 of a row apart on the ground: the coarse grids keep every
    // fourth column where that does not raise their error. The relief runs east-west as a
    // plane (every grid, thinned and expanded, is the square one) with waves north-south.
    let mut polar = Heightfield::from_fn(33, 33, |x, y| {
        300.0 + x as f32 + (25.0 * (y as f32 * 0.3).cos()).round()
    })
    .unwrap();
    polar.metadata = Metadata {
        spacing_m: None,
        georeference: Some(Georeference {
            crs: Some("EPSG:4326".into()),
            origin: [20.0, 80.0],
            step: [0.01, -0.01],
        }),
        units: Some("metres".into()),
        source_format: "test".into(),
        vertical_datum: VerticalDatum::Ellipsoid,
    };
    vec![
        Vector {
            name: "ramp-9x9",
            field: ramp,
            block_size: 9,
            thresholds: Thresholds::Ladder,
            precision: None,
            paged: false,
            thinned: false,
        },
        Vector {
            name: "hills-20x13-voids",
            field: hills,
            block_size: 9,
            thresholds: Thresholds::Ladder,
            precision: None,
            paged: false,
            thinned: false,
        },
        Vector {
            name: "cliff-33x33",
            field: cliff,
            block_size: 9,
            thresholds: Thresholds::Explicit(vec![0.0, 1.0, 10.0]),
            precision: None,
            paged: false,
            thinned: false,
        },
        Vector {
            name: "waves-17x17-precision-0.3",
            field: waves,
            block_size: 9,
            thresholds: Thresholds::Ladder,
            precision: Some(0.3),
            paged: false,
            thinned: false,
        },
        Vector {
            name: "hills-20x13-voids-paged",
            field: hills_paged,
            block_size: 9,
            thresholds: Thresholds::Ladder,
            precision: None,
            paged: true,
            thinned: false,
        },
        Vector {
            name: "polar-33x33-thinned",
            field: polar,
            block_size: 9,
            thresholds: Thresholds::Ladder,
            precision: None,
            paged: false,
            thinned: true,
        },
    ]
}

/// The vectors a format older than 2.1 has: those without a storage precision.
fn lossless_vectors() -> Vec<Vector> {
    old_vectors()
        .into_iter()
        .filter(|v| v.precision.is_none() && !v.paged)
        .collect()
}

/// The vectors formats 2.1 to 5.0 have: all but the thinned one.
fn old_vectors() -> Vec<Vector> {
    vectors().into_iter().filter(|v| !v.thinned).collect()
}

fn build(v: &Vector) -> Vec<u8> {
    let model = Model::build(
        v.field.clone(),
        &BuildOptions {
            block_size: v.block_size,
            thresholds: v.thresholds.clone(),
            precision: v.precision.map(|q| fmrh::model::Precision::new(q).unwrap()),
            thin: Default::default(),
        },
    )
    .unwrap();
    let mut out = Cursor::new(Vec::new());
    write_to(
        &model,
        &v.field.metadata,
        &WriteOptions {
            page_size: 1024,
            bundle_limit: if v.paged {
                0
            } else {
                WriteOptions::default().bundle_limit
            },
            ..WriteOptions::default()
        },
        &mut out,
    )
    .unwrap();
    out.into_inner()
}

/// The ids of the checks `report` failed, by name.
fn failed_checks(report: &fmrh::store::VerifyReport) -> Vec<String> {
    report
        .checks
        .iter()
        .filter(|c| c.status == fmrh::store::CheckStatus::Failed)
        .map(|c| format!("{:?}", c.id))
        .collect()
}

fn dir() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("format-spec/vectors")
}

#[test]
fn vectors_are_byte_exact_and_read_as_recorded() {
    let bless = std::env::var_os("FMRH_BLESS").is_some();
    for v in vectors() {
        let bytes = build(&v);
        let file = dir().join(format!("{}.fmrh", v.name));
        let info_file = dir().join(format!("{}.info.json", v.name));
        if bless {
            std::fs::write(&file, &bytes).unwrap();
        }
        let stored = std::fs::read(&file)
            .unwrap_or_else(|e| panic!("{}: {e} (bless to create)", file.display()));
        assert!(
            stored == bytes,
            "{}: the writer's bytes drifted from the vector",
            v.name
        );
        let out = Command::new(env!("CARGO_BIN_EXE_fmrh"))
            .args(["info", "--json", file.to_str().unwrap()])
            .output()
            .unwrap();
        assert!(
            out.status.success(),
            "{}",
            String::from_utf8_lossy(&out.stderr)
        );
        if bless {
            std::fs::write(&info_file, &out.stdout).unwrap();
        }
        let want: serde_json::Value =
            serde_json::from_slice(&std::fs::read(&info_file).unwrap()).unwrap();
        let got: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
        assert_eq!(got, want, "{}: the reading drifted", v.name);
        let verify = Command::new(env!("CARGO_BIN_EXE_fmrh"))
            .args(["verify", "--full", file.to_str().unwrap()])
            .output()
            .unwrap();
        assert!(
            verify.status.success(),
            "{}",
            String::from_utf8_lossy(&verify.stdout)
        );
    }
}

/// Whether a code's id is one of the encodings against a parent (§7): 5 to 8, their tANS
/// twins 11 to 14 (format 7), and 15.
fn against_parent(id: u8) -> bool {
    (5..=8).contains(&id) || (11..=15).contains(&id)
}

/// Whether a code against a parent predicts by interpolating the parent's grid (5, 6, 11,
/// 12, 15) rather than by the planar predictor (7, 8, 13, 14).
fn interpolated(id: u8) -> bool {
    matches!(id, 5 | 6 | 11 | 12 | 15)
}

/// The vectors pin format 4's blocks coded against their parent's grid: the voids vectors
/// have such blocks (encodings 5 to 8, from format 7 their tANS twins 11 to 14 and 15, the
/// block record naming the parent), and a block whose record names no parent is coded alone.
#[test]
fn vectors_pin_blocks_coded_against_their_parents() {
    let mut seen = std::collections::BTreeSet::new();
    for v in vectors() {
        let store = fmrh::store::Store::open(&dir().join(format!("{}.fmrh", v.name))).unwrap();
        let d = *store.domain();
        let (cols, rows) = d.nodes_across(d.finest_level());
        let mut against = 0;
        for y in 0..rows {
            for x in 0..cols {
                let b = store.stored_block(x, y).unwrap();
                let bytes = store.payload(b.payload).unwrap();
                let encoding = bytes[4];
                if let Some(n) = b.against {
                    against += 1;
                    assert!(against_parent(encoding), "{} ({x}, {y})", v.name);
                    seen.insert(encoding);
                    let parent = store.node(n).unwrap();
                    assert_eq!(
                        (parent.level, parent.x, parent.y),
                        (d.finest_level() - 1, x / 2, y / 2)
                    );
                } else {
                    assert!(!against_parent(encoding), "{} ({x}, {y})", v.name);
                }
            }
        }
        if v.name.starts_with("hills") {
            assert!(against > 0, "{}: no block coded against its parent", v.name);
        }
    }
    // Both predictions against a parent are pinned: the grid's interpolation (5, 6, 11, 12
    // or 15) and the planar predictor over the block's own samples (7, 8, 13 or 14).
    assert!(
        seen.iter().any(|&e| interpolated(e)) && seen.iter().any(|&e| !interpolated(e)),
        "encodings seen: {seen:?}"
    );
}

/// The vectors pin format 5's grids: some grid is coded against its parent's (flag bit 1,
/// encodings 5 to 8 and, from format 7, 11 to 15), every grid with a bitmap keeps it behind a void flag (bit 2), and some
/// void bitmap is stored as runs (void flag 2).
#[test]
fn vectors_pin_grids_coded_against_their_parents_and_flagged_bitmaps() {
    let (mut against, mut flagged, mut runs) = (0, 0, 0);
    for v in vectors() {
        let store = fmrh::store::Store::open(&dir().join(format!("{}.fmrh", v.name))).unwrap();
        let finest = store.domain().finest_level();
        for n in store.nodes().unwrap().iter().filter(|n| n.level < finest) {
            let bytes = store.payload(n.payload).unwrap();
            let a = u32::from_le_bytes(bytes[..4].try_into().unwrap()) as usize;
            let encoding = bytes[4];
            assert_eq!(
                n.grid_against_parent,
                against_parent(encoding),
                "{}",
                v.name
            );
            against += usize::from(n.grid_against_parent);
            assert_eq!(n.grid_bitmap_flagged, n.grid_has_voids, "{}", v.name);
            if n.grid_bitmap_flagged {
                flagged += 1;
                runs += usize::from(bytes[4 + a] == 2);
            }
        }
    }
    assert!(
        against > 0 && flagged > 0 && runs > 0,
        "{against} {flagged} {runs}"
    );
}

/// The metadata bundle of a vector (format §6.7, 5.0: a frame per page), decompressed by
/// zstd itself (not by fmrh): offset, stored length, CRC, pages and head length from commit
/// record bytes 176..200; the frame table (an `(offset, len, crc)` per page) first, its CRC
/// in the record; the head ends where the dataset header's and directory's frames, stored first, do.
fn bundle_of(bytes: &[u8]) -> Vec<u8> {
    let offset = u64::from_le_bytes(bytes[176..184].try_into().unwrap()) as usize;
    let len = u32::from_le_bytes(bytes[184..188].try_into().unwrap()) as usize;
    let crc = u32::from_le_bytes(bytes[188..192].try_into().unwrap());
    let pages = u32::from_le_bytes(bytes[192..196].try_into().unwrap()) as usize;
    let head_len = u32::from_le_bytes(bytes[196..200].try_into().unwrap()) as usize;
    let stored = &bytes[offset..offset + len];
    let table = &stored[..12 * pages];
    assert_eq!(crc32fast::hash(table), crc, "the frame table's CRC");
    let mut raw = Vec::new();
    let mut head_end = 12 * pages;
    for e in table.chunks_exact(12) {
        let at = u32::from_le_bytes(e[..4].try_into().unwrap()) as usize;
        let flen = u32::from_le_bytes(e[4..8].try_into().unwrap()) as usize;
        let frame = &stored[at..at + flen];
        assert_eq!(
            crc32fast::hash(frame),
            u32::from_le_bytes(e[8..].try_into().unwrap()),
            "a frame's CRC"
        );
        let page = zstd::stream::decode_all(frame).unwrap();
        assert_eq!(page.len(), 1024, "a frame holds one page");
        if &page[..4] == b"FMHD" || &page[..4] == b"FMCD" {
            head_end = head_end.max(at + flen);
        }
        raw.extend(page);
    }
    assert_eq!(
        head_len, head_end,
        "the head is the table and the opening pages' frames"
    );
    raw
}

#[test]
fn vector_commit_record_fields_sit_where_the_spec_says() {
    // Spot checks against the byte table of format-spec/container.md §3.
    let bytes = build(&vectors()[1]);
    assert_eq!(&bytes[0..8], b"FMRH\r\n\x1a\n");
    assert_eq!(u16::from_le_bytes([bytes[8], bytes[9]]), 7); // major
    assert_eq!(u16::from_le_bytes([bytes[10], bytes[11]]), 0); // minor
    assert_eq!(u32::from_le_bytes(bytes[12..16].try_into().unwrap()), 1024); // page size
    assert_eq!(u64::from_le_bytes(bytes[16..24].try_into().unwrap()), 1); // txn id
    assert_eq!(
        u64::from_le_bytes(bytes[24..32].try_into().unwrap()),
        bytes.len() as u64
    );
    // pages_txn (1.2 and later): the fresh file's one transaction wrote every structured page.
    assert_eq!(u64::from_le_bytes(bytes[168..176].try_into().unwrap()), 1);
    // The bundle's head length (5.0) is set; a bundled state has no top of the tree (6.2,
    // bytes 200..216); the record's reserved tail is zero.
    assert!(u32::from_le_bytes(bytes[196..200].try_into().unwrap()) > 0);
    assert!(bytes[200..216].iter().all(|&b| b == 0));
    assert!(bytes[216..252].iter().all(|&b| b == 0));
    let crc = crc32fast::hash(&bytes[..252]);
    assert_eq!(u32::from_le_bytes(bytes[252..256].try_into().unwrap()), crc);
    assert!(
        bytes[1024..2048].iter().all(|&b| b == 0),
        "slot 1 of a fresh file is zero"
    );
    // Payloads start at page 2, and the bundle follows the last of them (§2).
    let offset = u64::from_le_bytes(bytes[176..184].try_into().unwrap());
    let len = u32::from_le_bytes(bytes[184..188].try_into().unwrap()) as u64;
    assert!(offset > 2048 && offset + len <= bytes.len() as u64);
    assert!(
        bytes.len() as u64 - (offset + len) < 1024,
        "only the page tail follows"
    );
    // The bundle's first page is the dataset header blob, page 2^40: tag, txn tag of
    // transaction 1 at bytes 18..20, then width, height and block size.
    let raw = bundle_of(&bytes);
    assert_eq!(&raw[0..4], b"FMHD");
    assert_eq!(u64::from_le_bytes(raw[8..16].try_into().unwrap()), 1 << 40);
    assert_eq!(u16::from_le_bytes([raw[18], raw[19]]), 1);
    let h = 24;
    assert_eq!(u32::from_le_bytes(raw[h..h + 4].try_into().unwrap()), 20);
    assert_eq!(
        u32::from_le_bytes(raw[h + 4..h + 8].try_into().unwrap()),
        13
    );
    assert_eq!(
        u32::from_le_bytes(raw[h + 8..h + 12].try_into().unwrap()),
        9
    );
    // The root references point into the bundle: the dataset header's BlobRef at 40.
    assert_eq!(
        u64::from_le_bytes(bytes[40..48].try_into().unwrap()),
        1 << 40
    );
}

/// Format 1.x files (the 1.1 and 1.2 vectors, kept as they were written) are read sample for
/// sample and pass `verify --full`, and a write is refused with a message that says to
/// rebuild, before anything is written (format §8).
#[test]
fn format_1_vectors_read_verify_and_refuse_writes() {
    for (minor, folder) in [(1u16, "v1.1"), (2, "v1.2")] {
        for v in lossless_vectors() {
            let old = dir().join(folder).join(format!("{}.fmrh", v.name));
            let store = fmrh::store::Store::open(&old).unwrap();
            assert_eq!(store.state().format_version, (1, minor), "{}", v.name);
            let all = store.domain().data_rect();
            let samples = store.read_window(all).unwrap();
            let want = v.field.samples();
            assert_eq!(samples.samples().len(), want.len());
            for (a, b) in samples.samples().iter().zip(want) {
                assert!(
                    a.to_bits() == b.to_bits() || (a.is_nan() && b.is_nan()),
                    "{}",
                    v.name
                );
            }
            let report = fmrh::store::verify(
                fmrh::store::FileSource::open(&old).unwrap(),
                fmrh::store::VerifyMode::Full,
            )
            .unwrap();
            assert!(report.valid, "{}: {report:?}", v.name);
            drop(store);

            let dir = tempfile::tempdir().unwrap();
            let copy = dir.path().join("old.fmrh");
            std::fs::copy(&old, &copy).unwrap();
            let before = std::fs::read(&copy).unwrap();
            let err = fmrh::store::Container::open(&copy)
                .err()
                .expect("a 1.x file is read-only");
            assert!(
                matches!(err, fmrh::Error::Unsupported { .. })
                    && err.to_string().contains("rebuild"),
                "{err}"
            );
            assert_eq!(std::fs::read(&copy).unwrap(), before, "the refusal wrote");
        }
    }
}

/// Format 2.x to 6.x files (the vectors as 2.0 and 2.1 wrote them, every table in pages of
/// its own, in 2.0 the dataset header's precision field still reserved and zero; as 3.0 wrote
/// them, every block coded alone; as 4.0 wrote them, every grid coded alone; as 5.0 wrote
/// them, no grid thinned; as 6.x wrote them, every residual by pco) read sample for sample,
/// pass `verify --full`, and accept a transaction, whose commit makes them 7.0 (format §8)
/// with their metadata in a bundle.
#[test]
fn format_2_to_6_2_vectors_read_verify_and_take_a_transaction() {
    let old_vectors = lossless_vectors()
        .into_iter()
        .map(|v| ((2u16, 0u16), v))
        .chain(
            old_vectors()
                .into_iter()
                .filter(|v| !v.paged)
                .map(|v| ((2, 1), v)),
        )
        .chain(old_vectors().into_iter().map(|v| ((3, 0), v)))
        .chain(old_vectors().into_iter().map(|v| ((4, 0), v)))
        .chain(old_vectors().into_iter().map(|v| ((5, 0), v)))
        .chain(vectors().into_iter().map(|v| ((6, 0), v)))
        .chain(vectors().into_iter().map(|v| ((6, 1), v)))
        .chain(vectors().into_iter().map(|v| ((6, 2), v)));
    for ((major, minor), v) in old_vectors {
        let old = dir()
            .join(format!("v{major}.{minor}"))
            .join(format!("{}.fmrh", v.name));
        let store = fmrh::store::Store::open(&old).unwrap();
        assert_eq!(store.state().format_version, (major, minor), "{}", v.name);
        // Before 6.1 the datum is not recorded: the reader's convention says (a test
        // source: unknown), whatever the field was built with.
        if (major, minor) < (6, 1) {
            assert_eq!(
                store.header().metadata.vertical_datum,
                VerticalDatum::Unknown
            );
        }
        assert_eq!(
            store.header().precision.map(|p| p.step()),
            v.precision.filter(|_| (major, minor) > (2, 0))
        );
        let samples = store.read_window(store.domain().data_rect()).unwrap();
        let bound = v.precision.map_or(0.0, |q| q * 0.5625);
        for (a, b) in samples.samples().iter().zip(v.field.samples()) {
            assert!(
                a.to_bits() == b.to_bits()
                    || (a.is_nan() && b.is_nan())
                    || (f64::from(*a) - f64::from(*b)).abs() <= bound
            );
        }
        drop(store);
        let report = fmrh::store::verify(
            fmrh::store::FileSource::open(&old).unwrap(),
            fmrh::store::VerifyMode::Full,
        )
        .unwrap();
        assert!(report.valid, "{}: {report:?}", v.name);

        let dir = tempfile::tempdir().unwrap();
        let copy = dir.path().join("old.fmrh");
        std::fs::copy(&old, &copy).unwrap();
        let patch = Heightfield::from_fn(3, 2, |x, y| 1000.0 + (x + y) as f32).unwrap();
        let c = fmrh::store::Container::open(&copy).unwrap();
        let mut txn = c.begin_write().unwrap();
        txn.replace_region(1, 1, &patch).unwrap();
        txn.commit().unwrap();
        drop(c);
        let store = fmrh::store::Store::open(&copy).unwrap();
        assert_eq!(
            store.state().format_version,
            (fmrh::format::FORMAT_MAJOR, fmrh::format::FORMAT_MINOR),
            "{}",
            v.name
        );
        assert!(store.layout().unwrap().bundle_bytes > 0, "{}", v.name);
        let got = store
            .read_window(fmrh::model::SampleRect {
                col0: 1,
                row0: 1,
                col1: 3,
                row1: 2,
            })
            .unwrap();
        for (a, b) in got.samples().iter().zip(patch.samples()) {
            assert!((f64::from(*a) - f64::from(*b)).abs() <= bound, "{a} vs {b}");
        }
        let report = fmrh::store::verify(
            fmrh::store::FileSource::open(&copy).unwrap(),
            fmrh::store::VerifyMode::Full,
        )
        .unwrap();
        assert!(report.valid, "{}: {report:?}", v.name);
    }
}

/// The storage precision sits at bytes 148..156 of the dataset header (format §5), and the
/// vector stored with it keeps every height within the storage bound (9Q/16) of its source.
#[test]
fn precision_field_sits_where_the_spec_says() {
    let v = vectors()
        .into_iter()
        .find(|v| v.precision.is_some())
        .unwrap();
    let bytes = build(&v);
    let raw = bundle_of(&bytes);
    let h = 24;
    assert_eq!(
        f64::from_le_bytes(raw[h + 148..h + 156].try_into().unwrap()),
        0.3
    );
    assert_eq!(raw[h + 156], 1, "vertical datum: unknown");
    assert!(raw[h + 157..h + 160].iter().all(|&b| b == 0));
    let store = fmrh::store::Store::from_bytes(bytes).unwrap();
    let got = store.read_window(store.domain().data_rect()).unwrap();
    for (a, b) in got.samples().iter().zip(v.field.samples()) {
        assert!(
            (f64::from(*a) - f64::from(*b)).abs() <= 0.3 * 0.5625,
            "{a} vs {b}"
        );
    }
}

/// The vertical datum (format 6.1) is byte 156 of the dataset header (§5): the hills vector
/// records EGM96 (3), the polar one the ellipsoid (2), the ramp says nothing and records
/// unknown (1); bytes 157..160 stay zero. Read back, each is what was built.
#[test]
fn vertical_datum_sits_where_the_spec_says() {
    for (name, code, datum) in [
        ("hills-20x13-voids", 3u8, VerticalDatum::Egm96),
        ("polar-33x33-thinned", 2, VerticalDatum::Ellipsoid),
        ("ramp-9x9", 1, VerticalDatum::Unknown),
    ] {
        let v = vectors().into_iter().find(|v| v.name == name).unwrap();
        let bytes = build(&v);
        let raw = bundle_of(&bytes);
        let h = 24;
        assert_eq!(&raw[h - 24..h - 20], b"FMHD", "{name}");
        assert_eq!(raw[h + 156], code, "{name}");
        assert!(raw[h + 157..h + 160].iter().all(|&b| b == 0), "{name}");
        let store = fmrh::store::Store::from_bytes(bytes).unwrap();
        assert_eq!(store.header().metadata.vertical_datum, datum, "{name}");
    }
}

/// The rules for byte 156 (§5, §8), on the hills vector's header blob: 0 is "not recorded"
/// (the reader's convention, here unknown); a known code in a 6.1 file is its datum; an
/// unknown code is I-6 damage in a 6.1 file and unknown in a newer minor's; any code but 0
/// in a 6.0 (or older) file is a reserved byte set, I-6; bytes 157..160 likewise.
#[test]
fn vertical_datum_codes_follow_the_version_rules() {
    use fmrh::format::DatasetHeader;
    let v = vectors()
        .into_iter()
        .find(|v| v.name == "hills-20x13-voids")
        .unwrap();
    let raw = bundle_of(&build(&v));
    let lens: usize = (0..3)
        .map(|i| {
            let at = 24 + 136 + 4 * i;
            u32::from_le_bytes(raw[at..at + 4].try_into().unwrap()) as usize
        })
        .sum();
    let blob = raw[24..24 + 160 + lens].to_vec();
    let with = |at: usize, value: u8| {
        let mut b = blob.clone();
        b[at] = value;
        b
    };
    let datum = |b: &[u8], version: (u16, u16)| {
        DatasetHeader::decode(b, version).map(|h| h.metadata.vertical_datum)
    };
    assert_eq!(datum(&blob, (6, 1)), Ok(VerticalDatum::Egm96));
    assert_eq!(datum(&with(156, 0), (6, 1)), Ok(VerticalDatum::Unknown));
    assert_eq!(datum(&with(156, 0), (6, 0)), Ok(VerticalDatum::Unknown));
    assert_eq!(datum(&with(156, 4), (6, 1)), Ok(VerticalDatum::Egm2008));
    assert!(datum(&with(156, 9), (6, 1)).is_err());
    assert_eq!(datum(&with(156, 9), (6, 3)), Ok(VerticalDatum::Unknown));
    assert!(datum(&blob, (6, 0)).is_err());
    assert!(datum(&blob, (5, 0)).is_err());
    assert!(datum(&with(158, 1), (6, 1)).is_err());
    assert_eq!(datum(&with(158, 1), (6, 3)), Ok(VerticalDatum::Egm96));
}

/// Format 6's thinned grids, read by the spec alone (container §7 "Thinned grids", model
/// §4a): the polar vector's header has flag 16; some coarse grid has flag bits 3–6 set; its
/// heights' code holds exactly the kept columns (every `k`-th and the last, in rows of
/// `kw`); expanding them with the spec's formula, written out here, gives the grid the reader
/// returns bit for bit; and its kept columns are the decimation's own heights.
#[test]
fn the_polar_vector_pins_thinned_grids() {
    let v = vectors().into_iter().find(|v| v.thinned).unwrap();
    let bytes = build(&v);
    let raw = bundle_of(&bytes);
    let h = 24;
    let flags = u16::from_le_bytes(raw[h + 14..h + 16].try_into().unwrap());
    assert_eq!(flags & 16, 16, "the dataset header's thinned flag");
    let store = fmrh::store::Store::from_bytes(bytes).unwrap();
    let d = *store.domain();
    let b = d.block_size();
    let (mut thinned, mut alone) = (0, 0);
    for n in store
        .nodes()
        .unwrap()
        .iter()
        .filter(|n| n.level < d.finest_level())
    {
        let t = n.grid_thin;
        if t == 0 {
            continue;
        }
        thinned += 1;
        let k = 1u32 << t;
        let (gw, gh) = d.grid_dims(n.level, n.x, n.y);
        let kept: Vec<u32> = (0..gw).filter(|i| i % k == 0 || *i == gw - 1).collect();
        let kw = kept.len();
        let grid = store.grid(n).unwrap();
        let view = grid.view();
        // The kept heights, as the reader returns them; checked against the code below.
        let heights: Vec<f32> = (0..gh)
            .flat_map(|j| kept.iter().map(move |&c| (c, j)))
            .map(|(c, j)| view.height(c, j))
            .collect();
        if !n.grid_against_parent {
            alone += 1;
            let payload = store.payload(n.payload).unwrap();
            let a = u32::from_le_bytes(payload[..4].try_into().unwrap()) as usize;
            let mut coded = vec![0f32; kw * gh as usize];
            fmrh::codec::decode(&payload[4..4 + a], kw, &mut coded).unwrap();
            assert_eq!(
                coded, heights,
                "the code holds the kept columns, in rows of kw"
            );
        }
        let s = d.stride(n.level);
        let fp = d.footprint(n.level, n.x, n.y);
        for j in 0..gh {
            let row = &heights[j as usize * kw..(j as usize + 1) * kw];
            for i in 0..gw {
                let c0 = k * (i / k);
                let want = if let Some(p) = kept.iter().position(|&c| c == i) {
                    row[p]
                } else {
                    let c1 = (c0 + k).min(gw - 1);
                    let p0 = kept.iter().position(|&c| c == c0).unwrap();
                    let p1 = kept.iter().position(|&c| c == c1).unwrap();
                    let (t, n) = (f64::from(i - c0), f64::from(c1 - c0));
                    ((f64::from(row[p0]) * (n - t) + f64::from(row[p1]) * t) / n) as f32
                };
                assert_eq!(view.height(i, j).to_bits(), want.to_bits(), "({i}, {j})");
            }
            for (p, &c) in kept.iter().enumerate() {
                let col = (fp.col0 + u64::from(c) * s).min(u64::from(d.width() - 1));
                let r = (fp.row0 + u64::from(j) * s).min(u64::from(d.height() - 1));
                let sample = v.field.get(col as u32, r as u32).unwrap();
                assert_eq!(row[p].to_bits(), sample.to_bits(), "kept ({c}, {j})");
            }
        }
        assert!(k < b);
    }
    assert!(thinned > 0, "no grid of the polar vector is thinned");
    assert!(alone > 0, "no thinned grid is coded alone");
}

/// Where slot 1 lies when slot 0 is sealed but invalid (container.md §3, step 2): slot 0
/// names no page size then, however sealed, and the reader searches every allowed offset.
/// The vector is the ramp vector (1024-byte pages) with slot 0 resealed naming 2048 (so its
/// file length, 3072, is not whole pages: invalid) and slot 1 at byte 1024 holding the
/// original state as txn 10. It opens at txn 10 from slot 1, and the validator fails I-4
/// alone (the inactive slot is not a valid record). Built from the ramp vector's bytes, so
/// the vector pins both the rule and the writer.
fn slot_vector() -> Vec<u8> {
    let mut bytes = build(&vectors()[0]);
    assert_eq!(u32::from_le_bytes(bytes[12..16].try_into().unwrap()), 1024);
    let reseal = |r: &mut [u8]| {
        let crc = crc32fast::hash(&r[..252]);
        r[252..256].copy_from_slice(&crc.to_le_bytes());
    };
    let mut slot1 = bytes[..256].to_vec();
    slot1[16..24].copy_from_slice(&10u64.to_le_bytes());
    reseal(&mut slot1);
    bytes[1024..1280].copy_from_slice(&slot1);
    bytes[12..16].copy_from_slice(&2048u32.to_le_bytes());
    reseal(&mut bytes[..256]);
    bytes
}

/// The top of the tree (format 6.2, §6.8), read from the paged vector by the spec alone:
/// the commit record names it at bytes 200..216; its `FMTP` pages hold `count`, `levels`
/// and the entries; each entry's record is byte for byte the node table's at its ordinal
/// (found by walking the table's B+-tree from the record's TreeRef at 72), and the top
/// holds exactly the nodes of level below `levels`. The fresh paged layout (§2) puts the
/// coarse grids after every block, the root's last, and the node table's root, the top, the
/// directory and the header in the file's last pages.
#[test]
fn the_paged_vector_pins_the_top_of_the_tree() {
    let v = vectors().into_iter().find(|v| v.paged).unwrap();
    let bytes = std::fs::read(dir().join(format!("{}.fmrh", v.name))).unwrap();
    let p = 1024usize;
    let u64_at = |at: usize| u64::from_le_bytes(bytes[at..at + 8].try_into().unwrap());
    let u32_at = |at: usize| u32::from_le_bytes(bytes[at..at + 4].try_into().unwrap());
    let u16_at = |at: usize| u16::from_le_bytes(bytes[at..at + 2].try_into().unwrap());
    // The blob: pages of P - 24 content bytes, each with its header.
    let (first, len) = (u64_at(200) as usize, u64_at(208) as usize);
    assert!(len > 0, "a paged state has a top");
    let mut top = Vec::new();
    for i in 0..len.div_ceil(p - 24) {
        let page = (first + i) * p;
        assert_eq!(&bytes[page..page + 4], b"FMTP");
        assert_eq!(u64_at(page + 8) as usize, first + i);
        assert_eq!(
            u32_at(page + 4),
            crc32fast::hash(&bytes[page + 8..page + p])
        );
        let count = u32_at(page + 20) as usize;
        top.extend_from_slice(&bytes[page + 24..page + 24 + count]);
    }
    assert_eq!(top.len(), len);
    let count = u32::from_le_bytes(top[0..4].try_into().unwrap()) as usize;
    let levels = top[4];
    assert_eq!(&top[5..8], &[0, 0, 0]);
    assert_eq!(len, 8 + 84 * count);
    // The node table's leaves, in order, by a walk from its root.
    let (root, records, record_size) = (u64_at(72) as usize, u64_at(80) as usize, u16_at(90));
    assert_eq!(record_size, 80);
    let mut table = Vec::new();
    let mut stack = vec![root];
    while let Some(page_no) = stack.pop() {
        let page = page_no * p;
        assert_eq!(&bytes[page..page + 4], b"FMNT");
        let (level, n) = (u16_at(page + 16), u32_at(page + 20) as usize);
        if level == 0 {
            table.extend_from_slice(&bytes[page + 24..page + 24 + 80 * n]);
        } else {
            // Children pushed last-first, so the first is walked first.
            for e in (0..n).rev() {
                stack.push(u64_at(page + 24 + 24 * e + 16) as usize);
            }
        }
    }
    assert_eq!(table.len(), 80 * records);
    // The finest level is the header's; the writer's top holds levels 0..=min(3, L).
    let finest = table.chunks(80).map(|r| r[8]).max().unwrap();
    assert_eq!(levels, (finest + 1).min(4));
    let expected: Vec<usize> = (0..records)
        .filter(|&i| table[80 * i + 8] < levels)
        .collect();
    let held: Vec<usize> = (0..count)
        .map(|e| u32::from_le_bytes(top[8 + 84 * e..12 + 84 * e].try_into().unwrap()) as usize)
        .collect();
    assert_eq!(held, expected);
    for (e, &o) in held.iter().enumerate() {
        assert_eq!(
            &top[12 + 84 * e..8 + 84 * (e + 1)],
            &table[80 * o..80 * (o + 1)],
            "entry {e}: node {o}"
        );
    }
    // The payloads (§2): the coarse grids (levels below 4) after every block, level 3 first
    // and the root's last.
    let offset = |o: usize| u64::from_le_bytes(table[80 * o + 64..80 * o + 72].try_into().unwrap());
    let level = |o: usize| table[80 * o + 8];
    let blocks_end = (0..records)
        .filter(|&o| level(o) == finest)
        .map(offset)
        .max()
        .unwrap();
    let coarse: Vec<usize> = (0..records).filter(|&o| level(o) < finest).collect();
    assert!(coarse.iter().all(|&o| offset(o) > blocks_end));
    assert!(
        coarse.iter().all(|&o| o == 0 || offset(o) < offset(0)),
        "the root's grid is last"
    );
    // The layout: node table root, top, directory, header, then the end of the file.
    let pages = bytes.len() / p;
    let header = u64_at(40) as usize;
    let directory = u64_at(56) as usize;
    assert_eq!(header, pages - 1);
    assert!(root < first && first < directory && directory < header);
    // Format 7.0: the top is a 6.2 structure, kept in major 7.
    assert_eq!((u16_at(8), u16_at(10)), (7, 0));
}

/// A top of the tree whose record differs from the node table's (its page's CRC made
/// right, so only the comparison can tell) is I-10 damage: `verify` says so, where a
/// remote reader would have trusted the copy.
#[test]
fn a_top_that_differs_from_the_table_fails_verify() {
    let v = vectors().into_iter().find(|v| v.paged).unwrap();
    let mut bytes = std::fs::read(dir().join(format!("{}.fmrh", v.name))).unwrap();
    let p = 1024usize;
    let first = u64::from_le_bytes(bytes[200..208].try_into().unwrap()) as usize;
    let page = &mut bytes[first * p..(first + 1) * p];
    assert_eq!(&page[..4], b"FMTP");
    // Entry 1's record (after the page header, the top's 8-byte prefix, entry 0 and the
    // entry's 4-byte ordinal): its static error, at +32 in the record.
    let at = 24 + 8 + 84 + 4 + 32;
    page[at] ^= 1;
    let crc = crc32fast::hash(&page[8..]);
    page[4..8].copy_from_slice(&crc.to_le_bytes());
    let report =
        fmrh::store::verify(fmrh::store::Bytes(bytes), fmrh::store::VerifyMode::Fast).unwrap();
    assert!(!report.valid);
    let failed = failed_checks(&report);
    assert_eq!(failed, ["NodeTable"], "{report:?}");
}

/// Pages reached only through a structure this validator does not know: the paged vector
/// with its top's reference cleared leaves the top's pages owned by nothing. In a 7.0 file
/// that is I-8 damage; in a file of a newer minor (7.1, record resealed) those pages may
/// belong to a structure 7.1 added through the record's reserved bytes (§8), so the
/// validator does not call them damage. (A 6.1 validator reports a 6.2 file's top pages
/// so, as §8 says.)
#[test]
fn pages_a_newer_minor_may_own_are_not_damage() {
    let v = vectors().into_iter().find(|v| v.paged).unwrap();
    let original = std::fs::read(dir().join(format!("{}.fmrh", v.name))).unwrap();
    let with = |minor: u16| {
        let mut bytes = original.clone();
        bytes[10..12].copy_from_slice(&minor.to_le_bytes());
        bytes[200..216].fill(0);
        let crc = crc32fast::hash(&bytes[..252]);
        bytes[252..256].copy_from_slice(&crc.to_le_bytes());
        let report =
            fmrh::store::verify(fmrh::store::Bytes(bytes), fmrh::store::VerifyMode::Full).unwrap();
        failed_checks(&report)
    };
    assert_eq!(with(0), ["PageOwnership"]);
    assert!(with(1).is_empty(), "{:?}", with(1));
}

#[test]
fn the_slot_vector_pins_where_slot_1_lies() {
    let bless = std::env::var_os("FMRH_BLESS").is_some();
    let bytes = slot_vector();
    let file = dir().join("slot-1-beside-invalid-slot-0.fmrh");
    if bless {
        std::fs::write(&file, &bytes).unwrap();
        // Its reading, which every_vectors_info_json_is_what_info_prints checks.
        let out = Command::new(env!("CARGO_BIN_EXE_fmrh"))
            .args(["info", "--json", file.to_str().unwrap()])
            .output()
            .unwrap();
        assert!(out.status.success());
        std::fs::write(file.with_extension("info.json"), &out.stdout).unwrap();
    }
    let stored = std::fs::read(&file)
        .unwrap_or_else(|e| panic!("{}: {e} (bless to create)", file.display()));
    assert!(stored == bytes, "the slot vector drifted");
    let store = fmrh::store::Store::open(&file).unwrap();
    assert_eq!(store.txn_id(), 10, "the state is slot 1's");
    let report = fmrh::store::verify(
        fmrh::store::FileSource::open(&file).unwrap(),
        fmrh::store::VerifyMode::Full,
    )
    .unwrap();
    let failed: Vec<fmrh::types::Invariant> = report
        .checks
        .iter()
        .filter(|c| c.status == fmrh::store::CheckStatus::Failed)
        .map(|c| c.id)
        .collect();
    assert_eq!(
        failed,
        vec![fmrh::types::Invariant::InactiveSlot],
        "{report:?}"
    );
}

/// Every `.info.json` under `format-spec/vectors/` (the current vectors, every older
/// version's, the crafted ones and the dataset's) is exactly what `fmrh info --json` prints
/// for its file today: a reader of the spec checks its reading against them, so they must not
/// go stale when `info` gains a field. `FMRH_BLESS=1` rewrites them.
#[test]
fn every_vectors_info_json_is_what_info_prints() {
    let bless = std::env::var_os("FMRH_BLESS").is_some();
    let mut infos = Vec::new();
    let mut folders = vec![dir()];
    while let Some(folder) = folders.pop() {
        for e in std::fs::read_dir(&folder).unwrap() {
            let path = e.unwrap().path();
            if path.is_dir() {
                folders.push(path);
            } else if path.to_string_lossy().ends_with("info.json") {
                infos.push(path);
            }
        }
    }
    infos.sort();
    // 6 current, 46 of older versions (v1.1 to v6.2), the crafted slot vector and the
    // dataset: none may be missed.
    assert!(infos.len() >= 54, "{} info files", infos.len());
    for info in infos {
        let name = info.file_name().unwrap().to_string_lossy().into_owned();
        // `X.info.json` describes `X.fmrh`; a dataset's `info.json` describes its folder.
        let subject = match name.strip_suffix(".info.json") {
            Some(stem) => info.with_file_name(format!("{stem}.fmrh")),
            None => info.parent().unwrap().to_path_buf(),
        };
        let out = Command::new(env!("CARGO_BIN_EXE_fmrh"))
            .args(["info", "--json", subject.to_str().unwrap()])
            .output()
            .unwrap();
        assert!(
            out.status.success(),
            "{}: {}",
            subject.display(),
            String::from_utf8_lossy(&out.stderr)
        );
        if bless {
            std::fs::write(&info, &out.stdout).unwrap();
        }
        let want: serde_json::Value =
            serde_json::from_slice(&std::fs::read(&info).unwrap()).unwrap();
        let got: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
        assert_eq!(got, want, "{}: info --json drifted", info.display());
    }
}

/// The spec's stated current version is the code's: container.md's title, its commit record
/// table and versioning section (`FORMAT_MAJOR (n)`, `FORMAT_MINOR (n)`, every
/// `LAST_MINOR_OF_n = m`), and its invariant I-2's range of majors.
#[test]
fn the_spec_states_the_codes_format_version() {
    use fmrh::format::{
        FORMAT_MAJOR, FORMAT_MINOR, LAST_MINOR_OF_1, LAST_MINOR_OF_2, LAST_MINOR_OF_3,
        LAST_MINOR_OF_4, LAST_MINOR_OF_5, LAST_MINOR_OF_6,
    };
    let spec = std::fs::read_to_string(
        PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("format-spec/container.md"),
    )
    .unwrap();
    let version = format!("{FORMAT_MAJOR}.{FORMAT_MINOR}");
    let title = spec.lines().next().unwrap();
    assert_eq!(
        title,
        format!("# The `.fmrh` container, format {version}"),
        "the title"
    );
    for stated in [
        format!("`FORMAT_MAJOR` ({FORMAT_MAJOR})"),
        format!("`FORMAT_MINOR` ({FORMAT_MINOR})"),
        format!("`FORMAT_MAJOR.FORMAT_MINOR` =\n{version}"),
        format!("| 8 | 2 | u16 | major | format major version: {FORMAT_MAJOR} "),
        format!("| 10 | 2 | u16 | minor | format minor version: {FORMAT_MINOR} "),
        format!("major version is 1 to {FORMAT_MAJOR}."),
        format!("*valid* (sealed, major 1 to {FORMAT_MAJOR},"),
    ] {
        assert!(
            spec.contains(&stated),
            "container.md does not say {stated:?}"
        );
    }
    for (major, last) in [
        (1, LAST_MINOR_OF_1),
        (2, LAST_MINOR_OF_2),
        (3, LAST_MINOR_OF_3),
        (4, LAST_MINOR_OF_4),
        (5, LAST_MINOR_OF_5),
        (6, LAST_MINOR_OF_6),
    ] {
        let stated = format!("`LAST_MINOR_OF_{major}` = {last}");
        assert!(
            spec.contains(&stated),
            "container.md does not say {stated:?}"
        );
    }
    // No "format N.M" names a version newer than the code's.
    for (i, _) in spec.match_indices("format ") {
        let rest = &spec[i + 7..];
        let digits: String = rest
            .chars()
            .take_while(|c| c.is_ascii_digit() || *c == '.')
            .collect();
        if let Some((ma, mi)) = digits.trim_end_matches('.').split_once('.') {
            if let (Ok(ma), Ok(mi)) = (ma.parse::<u16>(), mi.parse::<u16>()) {
                assert!(
                    (ma, mi) <= (FORMAT_MAJOR, FORMAT_MINOR),
                    "container.md names format {ma}.{mi}"
                );
            }
        }
    }
}

/// Container §7: a void at a position the parent's grid holds is a void, not the parent's
/// height (the void wins). The voids vector has such a sample: (19, 12), the clamp column and
/// an even row, in a block coded against its parent, where the parent's grid holds a mended
/// height. A reader that let the held value win would read that height there.
#[test]
fn the_voids_vector_pins_a_void_at_a_held_position() {
    let store = fmrh::store::Store::open(&dir().join("hills-20x13-voids.fmrh")).unwrap();
    let d = *store.domain();
    let (c, r) = (19u32, 12u32);
    let side = d.block_size() - 1;
    let (x, y) = (
        (c / side).min(d.nodes_across(d.finest_level()).0 - 1),
        (r / side).min(d.nodes_across(d.finest_level()).1 - 1),
    );
    let info = store.stored_block(x, y).unwrap();
    let parent = info.against.expect("the block is coded against its parent");
    let node = store.node(parent).unwrap();
    let grid = store.grid(&node).unwrap();
    let fp = d.footprint(node.level, node.x, node.y);
    let s = d.stride(node.level);
    let (gw, gh) = d.grid_dims(node.level, node.x, node.y);
    let col_of = |i: u32| (fp.col0 + u64::from(i) * s).min(u64::from(d.width() - 1));
    let row_of = |j: u32| (fp.row0 + u64::from(j) * s).min(u64::from(d.height() - 1));
    let i = (0..gw)
        .find(|&i| col_of(i) == u64::from(c))
        .expect("a held column");
    let j = (0..gh)
        .find(|&j| row_of(j) == u64::from(r))
        .expect("a held row");
    let held = grid.view().height(i, j);
    assert!(held.is_finite(), "the parent holds a height there: {held}");
    let block = store.block(x, y).unwrap();
    let v = block.view();
    let got = v
        .samples()
        .get(
            ((u64::from(r) - block.rect.row0) * u64::from(v.width) + u64::from(c) - block.rect.col0)
                as usize,
        )
        .unwrap()
        .get();
    assert_eq!(got.to_bits(), 0x7FC0_0000, "the void wins");
}

/// Every code id of a stored file's payloads: each block's samples' and stand-ins' codes and
/// each coarse grid's heights' code, by the stored form of §7 (a `u32` length, the code, then
/// what follows).
fn code_ids(store: &fmrh::store::Store) -> Vec<u8> {
    let d = *store.domain();
    let (cols, rows) = d.nodes_across(d.finest_level());
    let mut ids = Vec::new();
    for y in 0..rows {
        for x in 0..cols {
            let b = store.stored_block(x, y).unwrap();
            let bytes = store.payload(b.payload).unwrap();
            let a = u32::from_le_bytes(bytes[..4].try_into().unwrap()) as usize;
            ids.push(bytes[4]);
            if b.void_count > 0 {
                ids.push(bytes[4 + a]);
            }
        }
    }
    for n in store
        .nodes()
        .unwrap()
        .iter()
        .filter(|n| n.level < d.finest_level())
    {
        ids.push(store.payload(n.payload).unwrap()[4]);
    }
    ids
}

/// Format 7 (§7, §8): the vectors code their residuals with tANS (some code of every vector
/// with a residual stream is 9 to 15, none of 6.2's is), and a 6.2 file (the voids vector as
/// 6.2 wrote it) committed on becomes 7.0 with its untouched payloads still in their pco
/// codes beside the commit's new tANS ones: the ids mix, the file verifies, and every sample
/// reads as before but the patch.
#[test]
fn a_commit_on_a_6_2_file_mixes_pco_and_tans_codes() {
    for v in vectors() {
        let now = fmrh::store::Store::open(&dir().join(format!("{}.fmrh", v.name))).unwrap();
        let old =
            fmrh::store::Store::open(&dir().join("v6.2").join(format!("{}.fmrh", v.name))).unwrap();
        assert!(
            code_ids(&old).iter().all(|&id| id < 9),
            "{}: a 6.2 file holds pco codes only",
            v.name
        );
        let ids = code_ids(&now);
        // Encodings 0, 1 and 3 have no tANS twin: a vector of constant or raw codes only
        // would hold none, but each of these has residuals somewhere.
        assert!(
            ids.iter().any(|&id| id >= 9),
            "{}: no tANS code in {ids:?}",
            v.name
        );
        assert!(
            ids.iter().all(|&id| Encoding::from_id(id).is_some()),
            "{}: {ids:?}",
            v.name
        );
    }
    let v = vectors()
        .into_iter()
        .find(|v| v.name == "hills-20x13-voids")
        .unwrap();
    let dir = tempfile::tempdir().unwrap();
    let copy = dir.path().join("old.fmrh");
    std::fs::copy(
        self::dir().join("v6.2").join("hills-20x13-voids.fmrh"),
        &copy,
    )
    .unwrap();
    let patch = Heightfield::from_fn(4, 3, |x, y| 1000.25 + (x * y) as f32 * 0.5).unwrap();
    let c = fmrh::store::Container::open(&copy).unwrap();
    let mut txn = c.begin_write().unwrap();
    txn.replace_region(2, 2, &patch).unwrap();
    txn.commit().unwrap();
    drop(c);
    let store = fmrh::store::Store::open(&copy).unwrap();
    assert_eq!(store.state().format_version, (7, 0));
    let ids = code_ids(&store);
    assert!(
        ids.iter().any(|&id| id >= 9) && ids.iter().any(|&id| (2..9).contains(&id)),
        "pco and tANS codes side by side: {ids:?}"
    );
    let got = store.read_window(store.domain().data_rect()).unwrap();
    for (i, (a, b)) in got.samples().iter().zip(v.field.samples()).enumerate() {
        let (x, y) = (i % 20, i / 20);
        let want = if (2..6).contains(&x) && (2..5).contains(&y) {
            patch.get(x as u32 - 2, y as u32 - 2).unwrap()
        } else {
            *b
        };
        assert!(
            a.to_bits() == want.to_bits() || (a.is_nan() && want.is_nan()),
            "({x}, {y}): {a} vs {want}"
        );
    }
    let report = fmrh::store::verify(
        fmrh::store::FileSource::open(&copy).unwrap(),
        fmrh::store::VerifyMode::Full,
    )
    .unwrap();
    assert!(report.valid, "{report:?}");
}

/// A tANS code in a file older than format 7 is damage (§7: a 6.x file's codes are 0 to 8),
/// though this reader could decode it: the voids vector, its commit record relabelled 6.2
/// and resealed (its layout is 6.2's in every other byte), fails `verify` on the payloads
/// alone, and reading a block with a tANS code is a corrupt-file error naming I-9.
#[test]
fn a_tans_code_in_a_6_2_file_is_corrupt() {
    let mut bytes = std::fs::read(dir().join("hills-20x13-voids.fmrh")).unwrap();
    let store = fmrh::store::Store::from_bytes(bytes.clone()).unwrap();
    let d = *store.domain();
    let (cols, rows) = d.nodes_across(d.finest_level());
    let tans = (0..rows)
        .flat_map(|y| (0..cols).map(move |x| (x, y)))
        .find(|&(x, y)| {
            let b = store.stored_block(x, y).unwrap();
            store.payload(b.payload).unwrap()[4] >= 9
        })
        .expect("a block with a tANS code");
    assert!(store.block(tans.0, tans.1).is_ok());
    drop(store);
    bytes[8..10].copy_from_slice(&6u16.to_le_bytes());
    bytes[10..12].copy_from_slice(&2u16.to_le_bytes());
    let crc = crc32fast::hash(&bytes[..252]);
    bytes[252..256].copy_from_slice(&crc.to_le_bytes());
    let store = fmrh::store::Store::from_bytes(bytes.clone()).unwrap();
    assert_eq!(store.state().format_version, (6, 2));
    let err = store.block(tans.0, tans.1).expect_err("refused");
    assert!(
        matches!(err, fmrh::Error::Corrupt { .. })
            && err.to_string().contains("older than format 7"),
        "{err}"
    );
    let report =
        fmrh::store::verify(fmrh::store::Bytes(bytes), fmrh::store::VerifyMode::Full).unwrap();
    let failed = failed_checks(&report);
    assert_eq!(failed, ["Payload"], "{report:?}");
}

/// Bits of a byte run as container §7's tANS stream reads them: bit `i` is bit `i mod 8` of
/// byte `⌊i/8⌋`, a field of `m` bits is read low first; `None` past the last byte.
struct SpecBits<'a> {
    bytes: &'a [u8],
    pos: usize,
}

impl SpecBits<'_> {
    fn read(&mut self, m: u32) -> Option<u64> {
        let mut v = 0u64;
        for j in 0..m {
            let byte = *self.bytes.get(self.pos / 8)?;
            v |= u64::from((byte >> (self.pos % 8)) & 1) << j;
            self.pos += 1;
        }
        Some(v)
    }
}

/// A LEB128 varint as §7 allows it (at most 5 bytes, no byte of zeros last but a lone one)
/// and the bytes it took.
fn spec_varint(bytes: &[u8]) -> Option<(u64, usize)> {
    let mut v = 0u64;
    for (i, &b) in bytes.iter().take(5).enumerate() {
        v |= u64::from(b & 0x7f) << (7 * i);
        if b & 0x80 == 0 {
            return (b != 0 || i == 0).then_some((v, i + 1));
        }
    }
    None
}

/// The codes of the tANS stream `stream` (the whole of it), read by container.md §7 alone
/// (written from the spec's text, sharing nothing with `src/codec/tans.rs`): `None` where
/// the spec calls the stream corrupt. `n` is the count the layout gives, or `None` to take
/// the stream's own.
fn spec_tans(stream: &[u8], n: Option<u64>) -> Option<Vec<u32>> {
    let (count, at) = spec_varint(stream)?;
    if n.is_some_and(|n| n != count) {
        return None;
    }
    let body = &stream[at..];
    if count == 0 {
        return body.is_empty().then(Vec::new);
    }
    let mut r = SpecBits {
        bytes: body,
        pos: 0,
    };
    let l = r.read(3)? as u32 + 5;
    let symbols = r.read(7)? as usize + 1;
    let size = 1u64 << l;
    let mut weights = vec![0u64; symbols];
    let mut sum = 0;
    for w in weights.iter_mut().take(symbols - 1) {
        let mut z = 0;
        while r.read(1)? == 0 {
            z += 1;
        }
        *w = (1u64 << z) + r.read(z)? - 1;
        sum += *w;
        if sum >= size {
            return None;
        }
    }
    weights[symbols - 1] = size - sum;
    // The spread: position p gets symbol s as its number k.
    let step = size / 2 + size / 8 + 3;
    let mut table = vec![(0usize, 0u64); size as usize];
    let mut p = 0u64;
    for (s, &w) in weights.iter().enumerate() {
        for k in w..2 * w {
            table[p as usize] = (s, k);
            p = (p + step) % size;
        }
    }
    let mut states = [0u64; 4];
    for state in &mut states {
        *state = r.read(l)?;
    }
    // A symbol's first code and its extra bits.
    let first = |s: usize| -> (u64, u32) {
        if s < 16 {
            (s as u64, 0)
        } else {
            let b = 4 + (s as u32 - 16) / 4;
            let m = (s as u64 - 16) % 4;
            ((4 + m) << (b - 2), b - 2)
        }
    };
    let mut codes = Vec::new();
    for i in 0..count as usize {
        let state = &mut states[i % 4];
        let (s, k) = table[*state as usize];
        let (base, extra) = first(s);
        codes.push(u32::try_from(base + r.read(extra)?).ok()?);
        let bits = l - (63 - k.leading_zeros());
        *state = (k << bits) - size + r.read(bits)?;
    }
    let ends = states.iter().all(|&s| s == 0)
        && r.pos.div_ceil(8) == body.len()
        && (r.pos.is_multiple_of(8) || body[body.len() - 1] >> (r.pos % 8) == 0);
    ends.then_some(codes)
}

/// A void flag and bitmap (§7) of `n` values in rows of `w`: the void bits and what follows.
fn spec_voids(bytes: &[u8], n: usize, w: usize) -> Option<(Vec<bool>, &[u8])> {
    let (&flag, rest) = bytes.split_first()?;
    match flag {
        0 => Some((vec![false; n], rest)),
        1 => {
            let len = n.div_ceil(8);
            let m = (0..n).map(|i| rest[i / 8] >> (i % 8) & 1 == 1).collect();
            Some((m, rest.get(len..)?))
        }
        2 => {
            // Runs of t[i] = m[i] XOR m[i - w], zeros first, summing to n.
            let (mut t, mut at, mut bit) = (Vec::with_capacity(n), 0, false);
            while t.len() < n {
                let (run, len) = spec_varint(&rest[at..])?;
                at += len;
                t.extend(std::iter::repeat_n(bit, run as usize));
                bit = !bit;
            }
            let mut m = vec![false; n];
            for i in 0..n {
                m[i] = t[i] ^ (i >= w && m[i - w]);
            }
            Some((m, &rest[at..]))
        }
        _ => None,
    }
}

/// The tANS stream of a code of encoding 9 to 15 (§7) of `n` values in rows of `w`, after
/// its step, void flag and factor: (stream, factor, voids); `None` for the other ids.
fn spec_stream_of(code: &[u8], n: usize, w: usize) -> Option<(&[u8], u64, Vec<bool>)> {
    let body = &code[1..];
    match code[0] {
        9 | 11 | 13 | 15 => {
            let (voids, rest) = spec_voids(&body[8..], n, w)?;
            let (f, len) = spec_varint(rest)?;
            Some((&rest[len..], f, voids))
        }
        10 => Some((body, 1, vec![false; n])),
        12 | 14 => {
            let (voids, rest) = spec_voids(body, n, w)?;
            Some((rest, 1, voids))
        }
        _ => None,
    }
}

/// A code of a vector: its bytes, its values, its row width, and the values the reader
/// returns for it when it is coded alone.
type SpecCode = (Vec<u8>, usize, usize, Option<Vec<f32>>);

/// Format 7's tANS streams, read by container.md §7 alone (`spec_tans` above): every tANS
/// stream of every vector (block samples, stand-ins, grid heights) decodes by the spec, its
/// end conditions hold, and its codes are the codec's; encoding 9's and 10's counts are
/// their layouts'; and every encoding 9 code (alone, planar predictor over `k`, the common
/// factor, voids at their prediction) rebuilds its values bit for bit as the reader returns
/// them. A second reader of the stream, written from the spec's text, agrees with the
/// writer on every byte of the vectors.
#[test]
fn the_vectors_tans_streams_decode_by_the_spec_alone() {
    let (mut streams, mut rebuilt) = (0, 0);
    for v in vectors() {
        let store = fmrh::store::Store::open(&dir().join(format!("{}.fmrh", v.name))).unwrap();
        let d = *store.domain();
        let (cols, rows) = d.nodes_across(d.finest_level());
        let mut codes: Vec<SpecCode> = Vec::new();
        for y in 0..rows {
            for x in 0..cols {
                let b = store.stored_block(x, y).unwrap();
                let bytes = store.payload(b.payload).unwrap();
                let a = u32::from_le_bytes(bytes[..4].try_into().unwrap()) as usize;
                let block = store.block(x, y).unwrap();
                let view = block.view();
                let (w, h) = (b.width as usize, b.height as usize);
                let samples: Vec<f32> = view.samples().iter().map(|s| s.get()).collect();
                let alone = b.against.is_none().then_some(samples);
                codes.push((bytes[4..4 + a].to_vec(), w * h, w, alone));
                if b.void_count > 0 {
                    let stand_ins: Vec<f32> = view.stand_ins().iter().map(|s| s.get()).collect();
                    let n = b.void_count as usize;
                    codes.push((bytes[4 + a..].to_vec(), n, n, Some(stand_ins)));
                }
            }
        }
        for n in store
            .nodes()
            .unwrap()
            .iter()
            .filter(|n| n.level < d.finest_level())
        {
            let bytes = store.payload(n.payload).unwrap();
            let a = u32::from_le_bytes(bytes[..4].try_into().unwrap()) as usize;
            let (gw, gh) = d.grid_dims(n.level, n.x, n.y);
            let kw = fmrh::format::payload::kept_width(gw, n.grid_thin) as usize;
            codes.push((bytes[4..4 + a].to_vec(), kw * gh as usize, kw, None));
        }
        for (code, n, w, alone) in codes {
            let Some((stream, f, voids)) = spec_stream_of(&code, n, w) else {
                continue;
            };
            streams += 1;
            let count = matches!(code[0], 9 | 10).then_some(n as u64);
            let ours = spec_tans(stream, count).unwrap_or_else(|| {
                panic!(
                    "{}: a stream of encoding {} the spec refuses",
                    v.name, code[0]
                )
            });
            let mut theirs = vec![0u32; ours.len()];
            fmrh::codec::tans::Decoder::default()
                .decode(stream, &mut theirs, |c| c)
                .unwrap();
            assert_eq!(ours, theirs, "{}", v.name);
            if let (9, Some(values)) = (code[0], alone) {
                let q = f64::from_le_bytes(code[1..9].try_into().unwrap());
                let mut k = vec![0i64; n];
                for i in 0..n {
                    let (c, r) = (i % w, i / w);
                    let p = match (c, r) {
                        (0, 0) => 0,
                        (_, 0) => k[i - 1],
                        (0, _) => k[i - w],
                        _ => k[i - 1] + k[i - w] - k[i - w - 1],
                    };
                    let z = ours[i];
                    let residual =
                        i64::from(((z >> 1) ^ 0u32.wrapping_sub(z & 1)) as i32) * f as i64;
                    k[i] = if voids[i] { p } else { p + residual };
                    let want = if voids[i] {
                        f32::from_bits(0x7FC0_0000)
                    } else {
                        (k[i] as f64 * q) as f32
                    };
                    assert_eq!(values[i].to_bits(), want.to_bits(), "{} value {i}", v.name);
                }
                rebuilt += 1;
            }
        }
    }
    assert!(
        streams > 0 && rebuilt > 0,
        "{streams} streams, {rebuilt} rebuilt"
    );
}
