//! `Terrain::cut` (the blocks over a window of the coarsest error level within a bound, no
//! camera) covers the window exactly once (every sample in some block, no two blocks sharing
//! more than an edge), gives only blocks within the bound, and, because an error level is a
//! cut of the whole tree, gives two overlapping windows the very same block (rectangle,
//! level, error and heights) wherever they overlap: what lets tiles of another pyramid, cut
//! from neighbouring windows, agree along their edges. Fields are random (noise, hills,
//! cliffs, spikes, flat, voids); windows and bounds too.

mod common;

use common::cuts::{same_block, window};
use fmrh::types::SampleRect;
use fmrh::{CreateOptions, Terrain};
use proptest::prelude::*;

fn overlap_area(a: &SampleRect, b: &SampleRect) -> u64 {
    let w = a.col1.min(b.col1).saturating_sub(a.col0.max(b.col0));
    let h = a.row1.min(b.row1).saturating_sub(a.row0.max(b.row0));
    w * h
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(48))]

    #[test]
    fn a_cut_covers_its_window_once_within_its_bound(
        w in 2u32..300,
        h in 2u32..300,
        character in common::fields::character(),
        voids in prop_oneof![Just(0.0), 0.0f64..0.3],
        seed in any::<u64>(),
        a in (0.0f64..1.0, 0.0f64..1.0, 0.0f64..1.0, 0.0f64..1.0),
        b in (0.0f64..1.0, 0.0f64..1.0, 0.0f64..1.0, 0.0f64..1.0),
        bound in prop_oneof![Just(0.0), 0.0f64..400.0],
    ) {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("t.fmrh");
        let field = common::fields::make(w, h, character, voids, seed);
        fmrh::create(&path, field, &CreateOptions { block_size: 17, ..CreateOptions::default() })
            .unwrap();
        let terrain = Terrain::open(&path).unwrap();
        let (wa, wb) = (window(w, h, a), window(w, h, b));
        let (ca, cb) = (terrain.cut(wa, bound).unwrap(), terrain.cut(wb, bound).unwrap());
        for (win, cut) in [(&wa, &ca), (&wb, &cb)] {
            for block in &cut.blocks {
                prop_assert!(block.error <= bound, "block error {} past {bound}", block.error);
                prop_assert!(block.rect.intersect(win).is_some(), "a block off the window");
            }
            for (i, x) in cut.blocks.iter().enumerate() {
                for y in &cut.blocks[i + 1..] {
                    prop_assert_eq!(overlap_area(&x.rect, &y.rect), 0, "blocks overlap");
                }
            }
            for row in win.row0..=win.row1 {
                for col in win.col0..=win.col1 {
                    prop_assert!(
                        cut.blocks.iter().any(|b| b.rect.col0 <= col && col <= b.rect.col1
                            && b.rect.row0 <= row && row <= b.rect.row1),
                        "sample ({col}, {row}) is in no block"
                    );
                }
            }
        }
        // Where the windows overlap, the blocks are the same.
        for x in &ca.blocks {
            for y in &cb.blocks {
                if overlap_area(&x.rect, &y.rect) > 0 || (x.rect == y.rect) {
                    prop_assert!(same_block(x, y), "two cuts disagree at {:?} / {:?}", x.rect, y.rect);
                }
            }
        }
    }
}

#[test]
fn a_negative_or_nan_bound_is_refused() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("t.fmrh");
    let field = fmrh::Heightfield::from_fn(40, 40, |x, y| (x + y) as f32).unwrap();
    fmrh::create(&path, field, &CreateOptions::default()).unwrap();
    let terrain = Terrain::open(&path).unwrap();
    let w = SampleRect {
        col0: 0,
        row0: 0,
        col1: 39,
        row1: 39,
    };
    for bound in [-1.0, f64::NAN] {
        assert!(matches!(
            terrain.cut(w, bound),
            Err(fmrh::Error::InvalidArgument(_))
        ));
    }
    let outside = SampleRect { col1: 40, ..w };
    assert!(terrain.cut(outside, 1.0).is_err());
}
