//! `Terrain::read_within` (the surface over a window drawn by the coarsest error level within
//! a bound) keeps its promise at every sample: each real sample is within the bound (and
//! within the reported `max_error`, itself within the bound) of what `Terrain::read` gives,
//! plus the rounding of an `f64` surface to `f32`; a bound of 0 gives the stored samples bit
//! for bit; two windows read the same surface where they overlap (a level is a cut of the
//! whole tree); and `at_stride` is every `stride`-th sample of it. Containers with random
//! fields (noise, hills, cliffs, spikes, flat, voids), windows and bounds; and a dataset of
//! tiles with a hole, whose samples no tile covers are NaN.

mod common;

use common::cuts::window;
use common::fields::{self, Character};
use common::tiles;
use fmrh::types::SampleRect;
use fmrh::{CreateOptions, Terrain};
use proptest::prelude::*;

/// How far an `f64` surface rounded to `f32` may move: half an ulp of the larger value.
fn rounding(a: f32, b: f32) -> f64 {
    f64::from(a.abs().max(b.abs())) * f64::from(f32::EPSILON)
}

/// Checks `terrain.read_within(window, bound)` against `terrain.read(window)`; returns it.
fn check(terrain: &Terrain, window: SampleRect, bound: f64) -> fmrh::types::Approximation {
    let exact = terrain.read(Some(window)).unwrap();
    let within = terrain.read_within(Some(window), bound).unwrap();
    assert_eq!(within.window, window);
    assert!(
        within.max_error <= bound,
        "{} past {bound}",
        within.max_error
    );
    assert!(within.stride.is_power_of_two());
    assert_eq!(
        (within.heights.width(), within.heights.height()),
        (exact.width(), exact.height())
    );
    for (i, (&a, &e)) in within
        .heights
        .samples()
        .iter()
        .zip(exact.samples())
        .enumerate()
    {
        if e.is_nan() {
            continue;
        }
        let off = (f64::from(a) - f64::from(e)).abs();
        assert!(
            off <= within.max_error + rounding(a, e),
            "sample {i}: {a} drawn, {e} stored, {off} apart, max_error {}",
            within.max_error
        );
        if bound == 0.0 {
            assert_eq!(a.to_bits(), e.to_bits(), "sample {i} at bound 0");
        }
    }
    let own = within.at_stride().unwrap();
    let s = own.stride as usize;
    assert_eq!(s as u64, within.stride);
    let w = within.heights.width() as usize;
    for (j, row) in own
        .heights
        .samples()
        .chunks(own.heights.width() as usize)
        .enumerate()
    {
        for (i, &v) in row.iter().enumerate() {
            let full = within.heights.samples()[j * s * w + i * s];
            assert!(v.to_bits() == full.to_bits(), "strided ({i}, {j})");
        }
    }
    assert_eq!(own.heights.width() as usize, w.div_ceil(s));
    within
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(40))]

    #[test]
    fn a_container_reads_within_its_bound_and_windows_agree(
        w in 2u32..260,
        h in 2u32..260,
        character in fields::character(),
        voids in prop_oneof![Just(0.0), 0.0f64..0.3],
        seed in any::<u64>(),
        a in (0.0f64..1.0, 0.0f64..1.0, 0.0f64..1.0, 0.0f64..1.0),
        b in (0.0f64..1.0, 0.0f64..1.0, 0.0f64..1.0, 0.0f64..1.0),
        bound in prop_oneof![Just(0.0), 0.0f64..400.0],
    ) {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("t.fmrh");
        let field = fields::make(w, h, character, voids, seed);
        fmrh::create(&path, field, &CreateOptions { block_size: 17, ..CreateOptions::default() })
            .unwrap();
        let terrain = Terrain::open(&path).unwrap();
        let (wa, wb) = (window(w, h, a), window(w, h, b));
        let (ra, rb) = (check(&terrain, wa, bound), check(&terrain, wb, bound));
        // Where the windows overlap they read the same surface.
        if let Some(o) = wa.intersect(&wb) {
            for row in o.row0..=o.row1 {
                for col in o.col0..=o.col1 {
                    let at = |win: &SampleRect, r: &fmrh::types::Approximation| {
                        let ww = win.col1 - win.col0 + 1;
                        r.heights.samples()[((row - win.row0) * ww + col - win.col0) as usize]
                    };
                    prop_assert_eq!(at(&wa, &ra).to_bits(), at(&wb, &rb).to_bits());
                }
            }
        }
    }
}

#[test]
fn a_dataset_reads_within_its_bound_and_its_holes_are_nan() {
    let dir = tempfile::tempdir().unwrap();
    let field = fields::make(61, 45, Character::Hills, 0.05, 7);
    // Three tiles of a 2×2 split; the fourth (south-east) is a hole.
    let rects = tiles::split(&field, &[32], &[24], &[3]);
    let ds = tiles::build(dir.path(), &field, &rects, &tiles::options(None));
    let terrain = Terrain::open(&ds).unwrap();
    let whole = SampleRect {
        col0: 0,
        row0: 0,
        col1: 60,
        row1: 44,
    };
    for bound in [0.0, 0.5, 3.0, 40.0, 1e9] {
        let within = check(&terrain, whole, bound);
        for row in 0..=44u64 {
            for col in 0..=60u64 {
                let v = within.heights.samples()[(row * 61 + col) as usize];
                let covered = rects
                    .iter()
                    .any(|r| r.col0 <= col && col <= r.col1 && r.row0 <= row && row <= r.row1);
                assert_eq!(v.is_nan(), !covered, "({col}, {row}) at bound {bound}");
            }
        }
    }
    // The coarsest bound reads coarser grids than the exact one.
    assert_eq!(terrain.read_within(None, 0.0).unwrap().stride, 1);
    assert!(terrain.read_within(None, 1e9).unwrap().stride > 1);
}

#[test]
fn bad_bounds_and_windows_are_refused() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("t.fmrh");
    let field = fmrh::Heightfield::from_fn(40, 30, |x, y| (x * y) as f32).unwrap();
    fmrh::create(&path, field, &CreateOptions::default()).unwrap();
    let terrain = Terrain::open(&path).unwrap();
    for bound in [-1.0, f64::NAN] {
        assert!(matches!(
            terrain.read_within(None, bound),
            Err(fmrh::Error::InvalidArgument(_))
        ));
    }
    let outside = SampleRect {
        col0: 0,
        row0: 0,
        col1: 40,
        row1: 29,
    };
    assert!(matches!(
        terrain.read_within(Some(outside), 1.0),
        Err(fmrh::Error::InvalidArgument(_))
    ));
}
