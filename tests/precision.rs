//! Error-bounded storage (`fmrh build --precision Q`; model §4, format 2.1) keeps its promise
//! against the *source*, not the stored copy: every stored height lies within `Q/2` of the
//! source height; every node's recorded error bounds the distance from its surface to every
//! source sample under it (measured here again, from scratch); scenes over such a file cover
//! their region once and reconstruct the source within each block's error, and a block that
//! misses `tau` does so only because it is as exact as storage allows; transactions keep the
//! precision. The named hard cases: a step larger than a node's own error, a block constant
//! after quantisation, integer data with one fractional sample, `-0.0`, subnormals, ±3.4e38
//! and NaN payloads (bit for bit without a precision), and a patch that changes a block's
//! best codec.

mod common;

use std::io::Cursor;

use glam::DVec3;
use proptest::prelude::*;

use common::fields::{any_field, Rng};
use common::views;
use fmrh::codec::Encoding;
use fmrh::model::surface::surface;
use fmrh::model::{BuildOptions, Model, Precision, SampleRect, Thresholds};
use fmrh::scene::{reconstruct, Camera, Mode, SceneOptions, Terrain};
use fmrh::store::{write_to, Bytes, WriteOptions};
use fmrh::{store::Store, Heightfield};

fn with_precision(q: f64) -> BuildOptions {
    BuildOptions {
        precision: Some(Precision::new(q).unwrap()),
        ..BuildOptions::default()
    }
}

/// Lossless, with blocks of `b` samples.
fn blocks_of(b: u32) -> BuildOptions {
    BuildOptions {
        block_size: b,
        ..BuildOptions::default()
    }
}

/// A precision of `q`, with blocks of `b` samples.
fn precise_blocks(q: f64, b: u32) -> BuildOptions {
    BuildOptions {
        block_size: b,
        ..with_precision(q)
    }
}

fn store_of(model: &Model, source: &Heightfield) -> Store<Bytes<Vec<u8>>> {
    let mut out = Cursor::new(Vec::new());
    write_to(model, &source.metadata, &WriteOptions::default(), &mut out).unwrap();
    Store::from_bytes(out.into_inner()).unwrap()
}

/// The largest `|surface - source|` of node `index` over the valid source samples of its
/// footprint, from the stored grid, cell by cell (model §4's surface).
fn error_against_source(model: &Model, source: &Heightfield, index: u32) -> f64 {
    let d = model.domain();
    let n = model.tree().node(index);
    let fp = d.footprint(n.level, n.x, n.y);
    let s = d.stride(n.level);
    let b = u64::from(d.block_size());
    let grid = model.node_grid(index);
    let g = |i: u64, j: u64| grid.heights[(j * b + i) as usize];
    let (w, h) = (u64::from(source.width()), u64::from(source.height()));
    let mut worst = 0.0f64;
    for row in fp.row0..=fp.row1.min(h - 1) {
        for col in fp.col0..=fp.col1.min(w - 1) {
            let v = source.samples()[(row * w + col) as usize];
            if v.is_nan() {
                continue;
            }
            let (ci, cj) = (
                ((col - fp.col0) / s).min(b - 2),
                ((row - fp.row0) / s).min(b - 2),
            );
            let (u, vv) = (col - fp.col0 - ci * s, row - fp.row0 - cj * s);
            let z = surface(
                g(ci, cj),
                g(ci + 1, cj),
                g(ci, cj + 1),
                g(ci + 1, cj + 1),
                s,
                u,
                vv,
            );
            worst = worst.max((f64::from(v) - z).abs());
        }
    }
    worst
}

fn check_against_source(model: &Model, source: &Heightfield, q: f64) {
    let bound = q * 0.5625;
    for (i, n) in model.tree().nodes().iter().enumerate() {
        let e = error_against_source(model, source, i as u32);
        assert!(
            e <= n.static_error,
            "node {i} (level {}): {e} from the source > its recorded error {}",
            n.level,
            n.static_error
        );
        assert!(n.static_error <= n.monotone_error);
    }
    let raster = model.raster();
    let w = u64::from(source.width());
    for (k, v) in source.samples().iter().enumerate() {
        let (col, row) = (k as u64 % w, k as u64 / w);
        match raster.original(col, row) {
            Some(stored) => {
                assert!(
                    (f64::from(stored) - f64::from(*v)).abs() <= bound,
                    "{v} -> {stored}"
                )
            }
            None => assert!(v.is_nan()),
        }
    }
}

proptest! {
    #![proptest_config(ProptestConfig { cases: 40, ..ProptestConfig::default() })]

    /// Node errors bound the source, whatever the field (voids, cliffs, flats) and step.
    #[test]
    fn node_errors_bound_the_source(
        field in any_field(48),
        q in prop::sample::select(vec![0.01, 0.3, 1.0, 7.0]),
        b in prop::sample::select(vec![9u32, 17]),
    ) {
        let model = Model::build(field.clone(), &BuildOptions { block_size: b, ..with_precision(q) }).unwrap();
        check_against_source(&model, &field, q);
        // Every cluster's threshold is at least the storage error, and its cut within it.
        for c in model.clusters() {
            prop_assert!(c.threshold >= q * 0.5625);
            prop_assert!(c.max_error <= c.threshold);
        }
        let store = store_of(&model, &field);
        prop_assert_eq!(store.header().precision, Some(Precision::new(q).unwrap()));
        let report = fmrh::store::verify(Bytes(store.source().0.clone()), fmrh::store::VerifyMode::Full).unwrap();
        prop_assert!(report.valid, "{:?}", report);
    }
}

fn puget_precise() -> &'static views::Fixture {
    static F: std::sync::OnceLock<views::Fixture> = std::sync::OnceLock::new();
    F.get_or_init(|| views::fixture(views::puget_1k(), &with_precision(2.0)))
}

/// On a real DEM stored to 2 m: view scenes cover what they see and reconstruct the source
/// within each block's error; a block over `tau` is as exact as storage allows.
#[test]
fn view_scenes_reconstruct_the_source_within_block_errors() {
    let f = puget_precise();
    check_against_source(&f.model, &f.source, 2.0);
    let terrain = Terrain::new(&f.store).unwrap();
    assert_eq!(terrain.storage_error(), 1.125);
    let mut rng = Rng::new(11);
    let mut over_tau = 0;
    let z = f64::from(f.model.raster().value(500, 500));
    let low = Camera::looking_at(
        DVec3::new(500.0 * 160.0, 500.0 * 160.0, z + 30.0),
        DVec3::new(600.0 * 160.0, 520.0 * 160.0, z),
    );
    for k in 0..24 {
        let cam = if k % 6 == 0 {
            low
        } else {
            views::random_camera(&f.model, terrain.frame(), &mut rng)
        };
        let tau = [0.5, 1.0, 2.0, 4.0][k % 4];
        let options = SceneOptions {
            tau,
            mode: Mode::View,
            window: None,
            gap: fmrh::scene::DEFAULT_GAP,
        };
        let scene = terrain.scene(&cam, &options).unwrap();
        for b in &scene.blocks {
            assert!(
                b.error >= 1.0 || b.error == 0.0,
                "{b:?} beats the storage error"
            );
            if b.screen_error > tau {
                assert!(b.error <= terrain.storage_error(), "{b:?} misses tau {tau}");
                over_tau += 1;
            }
        }
        let Some(window) = scene.window else {
            continue;
        };
        let rec = reconstruct(&f.store, &scene, window).unwrap();
        let w = (window.col1 - window.col0 + 1) as usize;
        for (i, (v, bound)) in rec.values.iter().zip(&rec.bound).enumerate() {
            let (col, row) = (window.col0 + (i % w) as u64, window.row0 + (i / w) as u64);
            let h = f.source.samples()[(row * 1025 + col) as usize];
            if !h.is_nan() && !v.is_nan() {
                assert!((f64::from(h) - v).abs() <= *bound, "({col}, {row})");
            }
        }
    }
    // A camera 30 m above the ground asks for more than 1 m of storage error allows.
    assert!(over_tau > 0, "no camera reached the storage floor");
}

/// Uniform scenes never go below the storage error: a bound below it takes the finest
/// cluster (as exact as anything stored), and the reconstruction is within the threshold of
/// the source.
#[test]
fn uniform_scenes_stop_at_the_storage_error() {
    let f = puget_precise();
    let terrain = Terrain::new(&f.store).unwrap();
    let z = f64::from(f.model.raster().value(500, 500));
    let cam = Camera::looking_at(
        DVec3::new(500.0 * 160.0, 500.0 * 160.0, z + 30.0),
        DVec3::new(600.0 * 160.0, 520.0 * 160.0, z),
    );
    let window = SampleRect {
        col0: 400,
        row0: 400,
        col1: 650,
        row1: 600,
    };
    let options = SceneOptions {
        tau: 0.1,
        mode: Mode::Uniform,
        window: Some(window),
        gap: fmrh::scene::DEFAULT_GAP,
    };
    let scene = terrain.scene(&cam, &options).unwrap();
    assert!(scene.stats.allowed_error.unwrap() < 1.125);
    assert_eq!(scene.stats.cluster, Some(0));
    assert_eq!(scene.stats.threshold, Some(1.125));
    views::assert_window_cover(&f.model, &scene.blocks, &window);
    let rec = reconstruct(&f.store, &scene, window).unwrap();
    let w = (window.col1 - window.col0 + 1) as usize;
    for (i, v) in rec.values.iter().enumerate() {
        let (col, row) = (window.col0 + (i % w) as u64, window.row0 + (i / w) as u64);
        let h = f.source.samples()[(row * 1025 + col) as usize];
        assert!((f64::from(h) - v).abs() <= 1.125);
    }
}

/// Thresholds below the storage error cannot be met and are refused.
#[test]
fn thresholds_below_the_storage_error_are_refused() {
    let field =
        Heightfield::from_fn(40, 40, |x, y| (x as f32 * 0.37).sin() + y as f32 * 0.013).unwrap();
    let options = BuildOptions {
        thresholds: Thresholds::Explicit(vec![0.0, 1.0]),
        ..with_precision(0.5)
    };
    let err = Model::build(field, &options).unwrap_err();
    assert!(err.to_string().contains("storage error"), "{err}");
}

/// A step far larger than the terrain's relief: a gentle slope quantises to a few steps, every
/// error carries the 5.625 m bound, and the source is still within it everywhere.
#[test]
fn step_larger_than_a_nodes_own_error() {
    let field =
        Heightfield::from_fn(65, 65, |x, y| 100.0 + x as f32 * 0.013 + y as f32 * 0.007).unwrap();
    let lossless = Model::build(field.clone(), &BuildOptions::default()).unwrap();
    let model = Model::build(field.clone(), &with_precision(10.0)).unwrap();
    assert!(lossless.max_error() < 5.0);
    assert!(model.max_error() >= 5.625);
    check_against_source(&model, &field, 10.0);
    let store = store_of(&model, &field);
    let all = store.read_window(store.domain().data_rect()).unwrap();
    assert!(all.samples().iter().all(|&v| v == 100.0));
}

/// The encoding of block `(x, y)`'s samples; checks that it is one coded against the parent's
/// grid exactly when the block record names that grid (format 4).
fn encoding_of<S: fmrh::store::Source>(store: &Store<S>, x: u32, y: u32) -> Encoding {
    let b = store.stored_block(x, y).unwrap();
    let bytes = store.payload(b.payload).unwrap();
    // Format 7's codes named by their pco twin (the same prediction and layout; 15 is 11
    // predicted in integers), so the checks below hold for either coder.
    let e = match Encoding::of(&bytes[4..]).unwrap() {
        Encoding::LatticeFromParentCodes => Encoding::LatticeFromParent,
        e => e.shape(),
    };
    let from_parent = matches!(
        e,
        Encoding::LatticeFromParent
            | Encoding::FloatFromParent
            | Encoding::LatticePlanarFromParent
            | Encoding::FloatPlanarFromParent
    );
    assert_eq!(from_parent, b.against.is_some(), "block ({x}, {y}): {e:?}");
    e
}

/// Whether `e` codes heights as indexes on a lattice (alone or against the parent's grid).
fn on_lattice(e: Encoding) -> bool {
    matches!(
        e,
        Encoding::Lattice | Encoding::LatticeFromParent | Encoding::LatticePlanarFromParent
    )
}

/// Heights within a few centimetres of 100 m are one constant at a 0.1 m step.
#[test]
fn block_constant_after_quantisation() {
    let mut rng = Rng::new(3);
    let field =
        Heightfield::from_fn(33, 33, |_, _| 100.0 + (rng.unit() as f32 - 0.5) * 0.08).unwrap();
    let lossless = store_of(
        &Model::build(field.clone(), &blocks_of(17)).unwrap(),
        &field,
    );
    assert_ne!(encoding_of(&lossless, 0, 0), Encoding::Constant);
    let model = Model::build(field.clone(), &precise_blocks(0.1, 17)).unwrap();
    check_against_source(&model, &field, 0.1);
    let store = store_of(&model, &field);
    for y in 0..2 {
        for x in 0..2 {
            assert_eq!(encoding_of(&store, x, y), Encoding::Constant);
        }
    }
    let bytes = |s: &Store<Bytes<Vec<u8>>>| s.layout().unwrap().block_bytes;
    assert!(
        bytes(&store) * 10 < bytes(&lossless),
        "{} vs {}",
        bytes(&store),
        bytes(&lossless)
    );
}

/// Integer data with one fractional sample: lossless, it comes back bit for bit (the lattice
/// moves to that sample's step); with a step of 1, that sample alone moves, by at most 0.5.
#[test]
fn integer_data_with_one_fractional_sample() {
    let field = Heightfield::from_fn(33, 33, |x, y| {
        if (x, y) == (7, 20) {
            513.25
        } else {
            ((x * 7 + y * 3) % 50) as f32 + 500.0
        }
    })
    .unwrap();
    let lossless = store_of(
        &Model::build(field.clone(), &blocks_of(17)).unwrap(),
        &field,
    );
    let back = lossless.read_window(lossless.domain().data_rect()).unwrap();
    assert_eq!(back.samples(), field.samples());
    assert!(on_lattice(encoding_of(&lossless, 0, 1)));

    let model = Model::build(field.clone(), &precise_blocks(1.0, 17)).unwrap();
    assert_eq!(model.storage_error_measured(), Some(0.25));
    let store = store_of(&model, &field);
    let back = store.read_window(store.domain().data_rect()).unwrap();
    for (k, (a, b)) in back.samples().iter().zip(field.samples()).enumerate() {
        if k == 20 * 33 + 7 {
            assert_eq!(*a, 513.0);
        } else {
            assert_eq!(a, b);
        }
    }
}

/// Without a precision the extremes of f32 come back bit for bit and any NaN becomes the
/// canonical void (format §7); with one, -0.0 and subnormals become +0.0 and the extremes
/// stay as they are (no lattice reaches them).
#[test]
fn negative_zero_subnormals_extremes_and_nan_payloads() {
    let specials = [
        -0.0f32,
        0.0,
        f32::from_bits(1),
        -f32::from_bits(0x0000_0400),
        f32::MIN_POSITIVE,
        3.4e38,
        -3.4e38,
        f32::MAX,
        f32::MIN,
        f32::from_bits(0x7FC0_0001),
        f32::from_bits(0xFFC0_0000),
        f32::from_bits(0x7F80_0001),
    ];
    let field = Heightfield::from_fn(20, 20, |x, y| specials[((x + 3 * y) % 12) as usize]).unwrap();
    let lossless = store_of(
        &Model::build(field.clone(), &BuildOptions::default()).unwrap(),
        &field,
    );
    let back = lossless.read_window(lossless.domain().data_rect()).unwrap();
    for (a, b) in back.samples().iter().zip(field.samples()) {
        if b.is_nan() {
            assert_eq!(a.to_bits(), fmrh::codec::VOID_BITS);
        } else {
            assert_eq!(a.to_bits(), b.to_bits(), "{b:e}");
        }
    }
    let model = Model::build(field.clone(), &with_precision(0.1)).unwrap();
    check_against_source(&model, &field, 0.1);
    let store = store_of(&model, &field);
    let back = store.read_window(store.domain().data_rect()).unwrap();
    for (a, b) in back.samples().iter().zip(field.samples()) {
        if b.is_nan() {
            assert!(a.is_nan());
        } else if b.abs() < 1.0 {
            assert_eq!(a.to_bits(), 0.0f32.to_bits(), "{b:e}");
        } else {
            assert_eq!(a.to_bits(), b.to_bits(), "{b:e}");
        }
    }
}

/// A transaction on a file with a precision stores its patch to that step, keeps the header's
/// precision, and changes a block's codec when the best one changes: integers (lattice) to
/// floats off the lattice and back; losslessly, floats (float codec) to one constant.
#[test]
fn patches_keep_the_precision_and_change_the_best_codec() {
    let dir = tempfile::tempdir().unwrap();
    let field = Heightfield::from_fn(65, 65, |x, y| ((x * 3 + y * 5) % 40) as f32).unwrap();
    let path = dir.path().join("p.fmrh");
    fmrh::create(
        &path,
        field.clone(),
        &fmrh::CreateOptions {
            block_size: 33,
            precision: Some(0.01),
            ..Default::default()
        },
    )
    .unwrap();
    let noisy = {
        let mut rng = Rng::new(9);
        Heightfield::from_fn(33, 33, |_, _| (rng.unit() * 1000.0) as f32).unwrap()
    };
    let c = fmrh::store::Container::open(&path).unwrap();
    let mut txn = c.begin_write().unwrap();
    txn.replace_region(0, 0, &noisy).unwrap();
    txn.commit().unwrap();
    drop(c);
    let store = Store::open(&path).unwrap();
    assert_eq!(
        store.header().precision,
        Some(Precision::new(0.01).unwrap())
    );
    let back = store
        .read_window(SampleRect {
            col0: 0,
            row0: 0,
            col1: 32,
            row1: 32,
        })
        .unwrap();
    for (a, b) in back.samples().iter().zip(noisy.samples()) {
        assert!((f64::from(*a) - f64::from(*b)).abs() <= 0.01 * 0.5625);
    }
    assert!(on_lattice(encoding_of(&store, 0, 0)));
    drop(store);
    let report = fmrh::store::verify(
        fmrh::store::FileSource::open(&path).unwrap(),
        fmrh::store::VerifyMode::Full,
    )
    .unwrap();
    assert!(report.valid, "{report:?}");

    // Lossless: an integer block becomes floats, then a constant.
    let path = dir.path().join("l.fmrh");
    fmrh::create(
        &path,
        field.clone(),
        &fmrh::CreateOptions {
            block_size: 33,
            ..Default::default()
        },
    )
    .unwrap();
    assert!(on_lattice(encoding_of(&Store::open(&path).unwrap(), 1, 1)));
    let c = fmrh::store::Container::open(&path).unwrap();
    let mut txn = c.begin_write().unwrap();
    txn.replace_region(32, 32, &noisy).unwrap();
    txn.commit().unwrap();
    let s = Store::open(&path).unwrap();
    assert!(matches!(
        encoding_of(&s, 1, 1),
        Encoding::FloatPco
            | Encoding::FloatPredicted
            | Encoding::Raw
            | Encoding::FloatFromParent
            | Encoding::FloatPlanarFromParent
    ));
    let back = s
        .read_window(SampleRect {
            col0: 32,
            row0: 32,
            col1: 64,
            row1: 64,
        })
        .unwrap();
    assert_eq!(back.samples(), noisy.samples());
    drop(s);
    let mut txn = c.begin_write().unwrap();
    txn.replace_region(32, 32, &Heightfield::from_fn(33, 33, |_, _| 12.5).unwrap())
        .unwrap();
    txn.commit().unwrap();
    assert_eq!(
        encoding_of(&Store::open(&path).unwrap(), 1, 1),
        Encoding::Constant
    );
}

/// `fmrh build --precision`: a float DEM shrinks, every height stays within Q/2 (measured
/// and reported), `info` and `verify --full` agree; integer data keeps its bits with a note;
/// a step that is not a usable number is refused before anything is written.
#[test]
fn cli_build_with_a_precision() {
    let dir = tempfile::tempdir().unwrap();
    let src = common::bundled_dir().join("gdal-rs-dem-hills/dem-hills.tiff");
    let (lossless, precise) = (dir.path().join("l.fmrh"), dir.path().join("p.fmrh"));
    let l = common::ok_json(&common::fmrh(&[
        "build",
        "-q",
        "--json",
        src.to_str().unwrap(),
        "-o",
        lossless.to_str().unwrap(),
    ]));
    let p = common::ok_json(&common::fmrh(&[
        "build",
        "-q",
        "--json",
        "--precision",
        "0.1",
        src.to_str().unwrap(),
        "-o",
        precise.to_str().unwrap(),
    ]));
    assert!(l["precision"].is_null());
    assert_eq!(p["precision"], 0.1);
    let measured = p["storage_error_measured"].as_f64().unwrap();
    assert!(measured > 0.0 && measured <= 0.05625, "{measured}");
    let size = |v: &serde_json::Value| v["output"]["file_length"].as_u64().unwrap();
    assert!(size(&p) * 3 < size(&l) * 2, "{} vs {}", size(&p), size(&l));
    let info = common::ok_json(&common::fmrh(&[
        "info",
        "--json",
        precise.to_str().unwrap(),
    ]));
    assert_eq!(info["precision"], 0.1);
    let v = common::fmrh(&["verify", "--full", precise.to_str().unwrap()]);
    assert!(v.status.success(), "{}", String::from_utf8_lossy(&v.stdout));
    // Every stored height within the bound of the source.
    let source = fmrh::ingest::load(&src, &Default::default()).unwrap();
    let store = Store::open(&precise).unwrap();
    let back = store.read_window(store.domain().data_rect()).unwrap();
    for (a, b) in back.samples().iter().zip(source.samples()) {
        if b.is_nan() {
            assert!(a.is_nan());
        } else {
            assert!(
                (f64::from(*a) - f64::from(*b)).abs() <= 0.05625,
                "{a} vs {b}"
            );
        }
    }

    // SRTM heights are integers: a step of 1 changes nothing and is dropped, with a note.
    let hgt = common::bundled_dir().join("srtm3-pyhgtmap/N43E007.hgt.gz");
    let out = dir.path().join("i.fmrh");
    let run = common::fmrh(&[
        "build",
        "-q",
        "--json",
        "--precision",
        "1",
        hgt.to_str().unwrap(),
        "-o",
        out.to_str().unwrap(),
    ]);
    assert!(String::from_utf8_lossy(&run.stderr).contains("bit for bit"));
    assert!(common::ok_json(&run)["precision"].is_null());

    for bad in ["0", "-0.1", "nan", "inf", "1e-9", "x"] {
        let target = dir.path().join(format!("bad-{bad}.fmrh"));
        let run = common::fmrh(&[
            "build",
            "-q",
            &format!("--precision={bad}"),
            src.to_str().unwrap(),
            "-o",
            target.to_str().unwrap(),
        ]);
        assert!(!run.status.success(), "{bad}");
        assert!(!String::from_utf8_lossy(&run.stderr).is_empty(), "{bad}");
        assert!(!target.exists(), "{bad}");
    }
}
