//! Thinned grids (format 6, `fmrh::model::thinning`): a longitude-latitude grid's coarse
//! nodes may store every `k`-th column only, and a reader expands them back. Checked here,
//! on random fields (voids, cliffs, flats, noise) placed near either pole:
//!
//! * every node's stored static error is exactly the largest distance from a valid sample to
//!   the surface of the grid *the reader returns* (expanded), recomputed cell by cell here;
//! * which nodes are thinned follows the rule of model §4a, no more, no fewer, and no node's
//!   `e*` exceeds the square tree's (so no cut is deeper);
//! * `verify --full` passes, and an edit (a transaction) gives exactly the nodes a fresh
//!   build of the edited samples gives, thinning included;
//! * a smooth polar grid stores fewer grid bytes thinned than square, and the CLI builds,
//!   reports and verifies it, and builds it square with `--no-thin`;
//! * thinning flags in a file that says it is format 5 are corruption, not data;
//! * and every kind of random field does thin somewhere, so none of this is vacuous.

mod common;

use common::fields::any_field;
use fmrh::heightfield::{Georeference, Metadata};
use fmrh::model::measure::measure_node;
use fmrh::model::surface::surface;
use fmrh::model::thinning::{
    candidate_log2, expand_row, keeps_thinned, kept_columns, LatLonSpacing,
};
use fmrh::model::{BuildOptions, Model, Thresholds};
use fmrh::store::Source;
use fmrh::{store::Store, Heightfield};
use proptest::prelude::*;

/// `field` placed at longitude 20°, its first row at `lat0`, rows 0.01° apart southwards
/// and columns `dlon` apart.
fn placed(mut field: Heightfield, lat0: f64, dlon: f64) -> Heightfield {
    field.metadata = Metadata {
        spacing_m: None,
        georeference: Some(Georeference {
            crs: Some("EPSG:4326".into()),
            origin: [20.0, lat0],
            step: [dlon, -0.01],
        }),
        units: None,
        source_format: "test".into(),
        ..Metadata::default()
    };
    field
}

fn spacing_of(field: &Heightfield) -> LatLonSpacing {
    LatLonSpacing::of_georeference(field.metadata.georeference.as_ref().unwrap()).unwrap()
}

fn create(field: &Heightfield, b: u32, dir: &std::path::Path) -> std::path::PathBuf {
    let file = dir.join("polar.fmrh");
    fmrh::create(
        &file,
        field.clone(),
        &fmrh::CreateOptions {
            block_size: b,
            ..fmrh::CreateOptions::default()
        },
    )
    .unwrap();
    file
}

/// The largest `|h − S|` over the valid samples of node `n`'s footprint, `S` the surface
/// (model §4) of the grid `store` returns for it.
fn drawn_error<S: Source>(
    store: &Store<S>,
    field: &Heightfield,
    n: &fmrh::format::StoredNode,
) -> f64 {
    let d = *store.domain();
    let grid = store.grid(n).unwrap();
    let view = grid.view();
    let (s, b) = (d.stride(n.level), u64::from(d.block_size()));
    let fp = d.footprint(n.level, n.x, n.y);
    let mut worst = 0.0f64;
    for row in fp.row0..=fp.row1.min(u64::from(d.height() - 1)) {
        for col in fp.col0..=fp.col1.min(u64::from(d.width() - 1)) {
            let h = field.samples()[(row * u64::from(d.width()) + col) as usize];
            if h.is_nan() {
                continue;
            }
            let (i, j) = (
                ((col - fp.col0) / s).min(b - 2),
                ((row - fp.row0) / s).min(b - 2),
            );
            let (u, v) = (col - fp.col0 - i * s, row - fp.row0 - j * s);
            let (i, j) = (i as u32, j as u32);
            let z = surface(
                view.height(i, j),
                view.height(i + 1, j),
                view.height(i, j + 1),
                view.height(i + 1, j + 1),
                s,
                u,
                v,
            );
            worst = worst.max((f64::from(h) - z).abs());
        }
    }
    worst
}

/// Checks a stored container of `field` (lossless) against the properties above.
fn check_thinned(file: &std::path::Path, field: &Heightfield) -> Result<usize, TestCaseError> {
    let store = Store::open(file).unwrap();
    let d = *store.domain();
    prop_assert!(store.header().thinned_by_area);
    let spacing = spacing_of(field);
    let model = Model::build(
        field.clone(),
        &BuildOptions {
            block_size: d.block_size(),
            thin: fmrh::model::ThinByArea::Off,
            ..BuildOptions::default()
        },
    )
    .unwrap();
    let raster = model.raster();
    // Thinning never raises an error (model §4a): every node's e* is at most the square
    // tree's, so the thinned tree is the square one or smaller, and no cut is deeper.
    let square_at: std::collections::HashMap<(u8, u32, u32), f64> = model
        .tree()
        .nodes()
        .iter()
        .map(|n| ((n.level, n.x, n.y), n.monotone_error))
        .collect();
    for n in store.nodes().unwrap() {
        let sq = square_at.get(&(n.level, n.x, n.y));
        prop_assert!(
            sq.is_some_and(|&e| n.monotone_error <= e),
            "node {:?}: e* {} against square {:?}",
            (n.level, n.x, n.y),
            n.monotone_error,
            sq
        );
    }
    let mut thinned = 0;
    for n in store
        .nodes()
        .unwrap()
        .iter()
        .filter(|n| n.level < d.finest_level())
    {
        let e = drawn_error(&store, field, n);
        prop_assert_eq!(
            e.to_bits(),
            n.static_error.to_bits(),
            "node {:?}: drawn error",
            (n.level, n.x, n.y)
        );
        let candidate = candidate_log2(&spacing, &d, n.level, n.x, n.y);
        let square = measure_node(raster, &d, n.level, (n.x, n.y), 0).error;
        if candidate == 0 {
            prop_assert_eq!(n.grid_thin, 0);
            continue;
        }
        let thin = measure_node(raster, &d, n.level, (n.x, n.y), candidate).error;
        let want = if keeps_thinned(square, thin) {
            candidate
        } else {
            0
        };
        prop_assert_eq!(
            n.grid_thin,
            want,
            "node {:?}: square {} thinned {}",
            (n.level, n.x, n.y),
            square,
            thin
        );
        thinned += usize::from(want > 0);
    }
    let report = fmrh::store::verify(
        fmrh::store::FileSource::open(file).unwrap(),
        fmrh::store::VerifyMode::Full,
    )
    .unwrap();
    prop_assert!(report.valid, "{:?}", report);
    Ok(thinned)
}

fn polar() -> impl Strategy<Value = (f64, f64)> {
    // Latitude of the first row (north or south), and the column step in degrees.
    (
        prop_oneof![55.0f64..89.0, -88.0f64..-55.0],
        prop_oneof![Just(0.01f64), Just(0.005), 0.002f64..0.02],
    )
}

proptest! {
    #![proptest_config(ProptestConfig { cases: 48, ..ProptestConfig::default() })]

    #[test]
    fn thinned_grids_are_drawn_as_their_errors_say(
        field in any_field(70), b in prop_oneof![Just(9u32), Just(17)], (lat0, dlon) in polar(),
    ) {
        let field = placed(field, lat0, dlon);
        let dir = tempfile::tempdir().unwrap();
        let file = create(&field, b, dir.path());
        check_thinned(&file, &field)?;
    }

    #[test]
    fn edits_of_thinned_containers_equal_fresh_builds(
        field in any_field(60), (lat0, dlon) in polar(),
        at in (0.0f64..1.0, 0.0f64..1.0), size in (1u32..20, 1u32..20), seed in any::<u64>(),
    ) {
        let field = placed(field, lat0, dlon);
        let dir = tempfile::tempdir().unwrap();
        let file = create(&field, 9, dir.path());
        let (w, h) = (field.width(), field.height());
        let (pw, ph) = (size.0.min(w), size.1.min(h));
        let (c0, r0) = (((w - pw) as f64 * at.0) as u32, ((h - ph) as f64 * at.1) as u32);
        let patch = common::fields::make(pw, ph, common::fields::Character::Hills, 0.1, seed);
        let thresholds: Vec<f64> = Store::open(&file).unwrap().clusters().iter().map(|c| c.threshold).collect();
        let c = fmrh::store::Container::open(&file).unwrap();
        let mut txn = c.begin_write().unwrap();
        txn.replace_region(u64::from(c0), u64::from(r0), &patch).unwrap();
        txn.commit().unwrap();
        drop(c);
        let mut samples = field.samples().to_vec();
        for j in 0..ph {
            for i in 0..pw {
                samples[((r0 + j) * w + c0 + i) as usize] = patch.samples()[(j * pw + i) as usize];
            }
        }
        let mut edited = Heightfield::new(w, h, samples).unwrap();
        edited.metadata = field.metadata.clone();
        let fresh = Model::build(
            edited.clone(),
            &BuildOptions { block_size: 9, thresholds: Thresholds::Explicit(thresholds), ..BuildOptions::default() },
        ).unwrap();
        let store = Store::open(&file).unwrap();
        let stored = store.nodes().unwrap();
        prop_assert_eq!(stored.len(), fresh.tree().nodes().len());
        for (s, n) in stored.iter().zip(fresh.tree().nodes()) {
            prop_assert_eq!((s.key, s.level, s.x, s.y), (n.key, n.level, n.x, n.y));
            prop_assert_eq!(s.static_error.to_bits(), n.static_error.to_bits());
            prop_assert_eq!(s.monotone_error.to_bits(), n.monotone_error.to_bits());
            prop_assert_eq!(s.grid_thin, if n.level < store.domain().finest_level() { n.thin } else { 0 });
        }
        drop(store);
        check_thinned(&file, &edited)?;
    }

    /// The expansion keeps the kept columns bit for bit and reproduces a straight row within
    /// one rounding.
    #[test]
    fn expansion_keeps_kept_columns_and_lines(gw in 1u32..70, log_k in 1u8..6, a in -1e4f32..1e4, slope in -50f32..50.0) {
        let k = 1u32 << log_k;
        let line: Vec<f32> = (0..gw).map(|i| a + slope * i as f32).collect();
        let kept: Vec<f32> = kept_columns(gw, k).map(|i| line[i as usize]).collect();
        prop_assert_eq!(kept.len() as u32, fmrh::model::thinning::kept_count(gw, k));
        let mut out = vec![f32::NAN; gw as usize];
        expand_row(&kept, k, &mut out);
        for (i, (&o, &l)) in out.iter().zip(&line).enumerate() {
            if (i as u32).is_multiple_of(k) || i as u32 + 1 == gw {
                prop_assert_eq!(o.to_bits(), l.to_bits());
            } else {
                prop_assert!((f64::from(o) - f64::from(l)).abs() <= 1e-3 * (1.0 + f64::from(l.abs())), "{} vs {}", o, l);
            }
        }
    }
}

/// Ground at 80° N sampled as a longitude-latitude product does it (columns 0.01°, rows
/// 0.01°: on the ground 5.8 times closer east-west): its coarse grids are thinned where that
/// raises no error, the container's grids are smaller than square, and it draws within its
/// errors.
fn smooth_polar() -> Heightfield {
    let field = Heightfield::from_fn(257, 129, |x, y| {
        // Ground distance in row units: a column is 0.17 of a row at 80° N. Gentle waves,
        // and here and there a sharp peak, which is what a coarse node's error is made of.
        let (gx, gy) = (f64::from(x) * 0.1736, f64::from(y));
        let peak = if x % 37 == 5 && y % 23 == 7 {
            80.0
        } else {
            0.0
        };
        (500.0 + 20.0 * (gx * 0.1).sin() * (gy * 0.08).cos() + peak).round() as f32
    })
    .unwrap();
    placed(field, 80.6, 0.01)
}

#[test]
fn a_smooth_polar_grid_stores_fewer_grid_bytes_thinned() {
    let field = smooth_polar();
    let dir = tempfile::tempdir().unwrap();
    let file = create(&field, 17, dir.path());
    let thinned = check_thinned(&file, &field).unwrap();
    assert!(thinned > 0, "no node thinned");
    let square = dir.path().join("square.fmrh");
    fmrh::create(
        &square,
        field.clone(),
        &fmrh::CreateOptions {
            block_size: 17,
            thin: fmrh::model::ThinByArea::Off,
            ..fmrh::CreateOptions::default()
        },
    )
    .unwrap();
    let grid_bytes = |f: &std::path::Path| Store::open(f).unwrap().layout().unwrap().grid_bytes;
    let (t, s) = (grid_bytes(&file), grid_bytes(&square));
    assert!(t < s, "thinned grids {t} bytes, square {s}");
    assert!(!Store::open(&square).unwrap().header().thinned_by_area);
}

#[test]
fn the_cli_thins_geographic_grids_and_keeps_them_square_when_told() {
    let field = smooth_polar();
    let dir = tempfile::tempdir().unwrap();
    let raw: Vec<u8> = field
        .samples()
        .iter()
        .flat_map(|v| v.to_le_bytes())
        .collect();
    std::fs::write(dir.path().join("p.f32"), raw).unwrap();
    std::fs::write(
        dir.path().join("p.json"),
        format!(
            r#"{{"width": {}, "height": {}, "georeference": {{"crs": "EPSG:4326", "origin": [20.0, 80.6], "step": [0.01, -0.01]}}}}"#,
            field.width(),
            field.height()
        ),
    )
    .unwrap();
    let input = dir.path().join("p.f32");
    let build = |out: &str, extra: &[&str]| {
        let out = dir.path().join(out);
        let mut args = vec![
            "build",
            "--json",
            "--block-size",
            "17",
            "-o",
            out.to_str().unwrap(),
            input.to_str().unwrap(),
        ];
        args.extend_from_slice(extra);
        common::ok_json(&common::fmrh(&args))
    };
    let thin = build("t.fmrh", &[]);
    let counts = thin["thinned_nodes"]
        .as_array()
        .expect("thinned nodes reported");
    assert!(
        !counts.is_empty()
            && counts
                .iter()
                .all(|c| c["nodes"].as_u64().unwrap() > 0 && c["factor"].as_u64().unwrap() >= 2)
    );
    let square = build("s.fmrh", &["--no-thin"]);
    assert!(square.get("thinned_nodes").is_none(), "{square}");
    let v = common::ok_json(&common::fmrh(&[
        "verify",
        "--full",
        "--json",
        dir.path().join("t.fmrh").to_str().unwrap(),
    ]));
    assert_eq!(v["valid"], true, "{v}");
}

/// Regression guard for the version check: the same bytes with the commit record saying 5.0
/// hold node flags that 5.0 reserved, so the file is corrupt, and reading a thinned grid
/// fails as corruption, never as a misread grid.
#[test]
fn thinned_grids_in_a_file_that_says_format_5_are_corruption() {
    let field = smooth_polar();
    let dir = tempfile::tempdir().unwrap();
    let file = create(&field, 17, dir.path());
    let mut bytes = std::fs::read(&file).unwrap();
    assert_eq!(
        u16::from_le_bytes([bytes[8], bytes[9]]),
        fmrh::format::FORMAT_MAJOR
    );
    // 5.1, a minor newer than any 5.x this reader knows: bytes a newer minor may use (the
    // vertical datum, §5) are not checked then, so only the node flags, which major 6 gave
    // a meaning, make the file corrupt. (When the writer wrote 6.2, a relabelled major alone
    // read as 5.2, with the same effect.)
    bytes[8..10].copy_from_slice(&5u16.to_le_bytes());
    bytes[10..12].copy_from_slice(&1u16.to_le_bytes());
    let crc = crc32fast::hash(&bytes[..252]);
    bytes[252..256].copy_from_slice(&crc.to_le_bytes());
    let report = fmrh::store::verify(
        fmrh::store::Bytes(bytes.clone()),
        fmrh::store::VerifyMode::Fast,
    )
    .unwrap();
    assert!(!report.valid, "{report:?}");
    let store = Store::from_bytes(bytes).unwrap();
    let n = store
        .nodes()
        .unwrap()
        .into_iter()
        .find(|n| n.grid_thin > 0)
        .unwrap();
    let Err(err) = store.grid(&n) else {
        panic!("a thinned grid in a 5.0 file is read");
    };
    // Refused for its thinning (the node table), not for anything its ancestors hold.
    assert!(
        matches!(
            err,
            fmrh::Error::Corrupt {
                invariant: fmrh::types::Invariant::NodeTable,
                ..
            }
        ) && err.to_string().contains("thinned by"),
        "{err}"
    );
}

/// The random fields above do thin: every character of field, placed at 75° N, has grids
/// stored thinned, and every one of them draws as its error says (so the properties above
/// are not checked on square grids alone).
#[test]
fn every_kind_of_field_thins_somewhere() {
    use common::fields::{make, Character};
    for character in [
        Character::SmallIntegers,
        Character::Noise,
        Character::Hills,
        Character::Cliff,
        Character::Spikes,
        Character::Flat,
    ] {
        let mut thinned = 0;
        for seed in 0..4 {
            let field = placed(make(65, 40, character, 0.03, seed), 75.0, 0.01);
            let dir = tempfile::tempdir().unwrap();
            let file = create(&field, 9, dir.path());
            thinned += check_thinned(&file, &field).unwrap();
        }
        assert!(thinned > 0, "{character:?}: no grid thinned");
    }
}
