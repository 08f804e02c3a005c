//! Shared edges (issue 16, `docs/datasets-design.md` §1): where two neighbouring tiles repeat
//! a row or column of samples, as SRTM's do, both files must hold the same samples there, or
//! the dataset would draw a seam whose height depends on which tile a scene took it from.
//! Samples agree when their bits do, and any two voids agree (a void is any NaN). A
//! disagreement is an error naming both tiles and the first differing sample, unless a
//! [`SeamPolicy`] says how to settle it; the module knows nothing of files.

use crate::heightfield::Heightfield;
use crate::model::SampleRect;

/// How `fmrh dataset build --seam` settles neighbours that disagree on a shared edge.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum SeamPolicy {
    /// Refuse: the build fails naming both tiles and the first differing sample.
    #[default]
    Strict,
    /// The tile listed first keeps its samples; the other is rewritten to agree.
    First,
    /// Both take the mean of the two (in `f64`, rounded once to `f32`); a void on either side
    /// makes the sample a void in both.
    Mean,
}

impl std::str::FromStr for SeamPolicy {
    type Err = String;

    fn from_str(s: &str) -> Result<Self, String> {
        match s {
            "strict" => Ok(SeamPolicy::Strict),
            "first" => Ok(SeamPolicy::First),
            "mean" => Ok(SeamPolicy::Mean),
            other => Err(format!("seam policy {other:?}: strict, first or mean")),
        }
    }
}

/// A tile's samples and where its first sample lies in the dataset's grid.
#[derive(Clone, Copy, Debug)]
pub struct Placed<'a> {
    /// The samples.
    pub field: &'a Heightfield,
    /// Dataset column of its column 0.
    pub col0: u64,
    /// Dataset row of its row 0.
    pub row0: u64,
}

impl Placed<'_> {
    /// The sample at dataset `(col, row)`, which the caller knows lies inside.
    fn at(&self, col: u64, row: u64) -> f32 {
        let (x, y) = (col - self.col0, row - self.row0);
        self.field.samples()[(y * u64::from(self.field.width()) + x) as usize]
    }
}

/// The first sample of `shared` (row-major) where two tiles disagree.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Disagreement {
    /// Dataset column.
    pub col: u64,
    /// Dataset row.
    pub row: u64,
    /// The first tile's sample.
    pub a: f32,
    /// The second tile's sample.
    pub b: f32,
}

fn agree(a: f32, b: f32) -> bool {
    a.to_bits() == b.to_bits() || (a.is_nan() && b.is_nan())
}

/// The first sample of `shared` (an overlap of the two tiles, in dataset samples) where `a`
/// and `b` disagree, in row-major order; `None` when they agree everywhere.
pub fn first_difference(a: Placed<'_>, b: Placed<'_>, shared: &SampleRect) -> Option<Disagreement> {
    for row in shared.row0..=shared.row1 {
        for col in shared.col0..=shared.col1 {
            let (va, vb) = (a.at(col, row), b.at(col, row));
            if !agree(va, vb) {
                return Some(Disagreement {
                    col,
                    row,
                    a: va,
                    b: vb,
                });
            }
        }
    }
    None
}

/// The samples both tiles take along `shared` (row-major) under `policy`; `Err` with the
/// first disagreement under [`SeamPolicy::Strict`] (and `Ok` with the common samples when
/// they agree, whatever the policy).
pub fn settle(
    a: Placed<'_>,
    b: Placed<'_>,
    shared: &SampleRect,
    policy: SeamPolicy,
) -> Result<Vec<f32>, Disagreement> {
    if let (SeamPolicy::Strict, Some(d)) = (policy, first_difference(a, b, shared)) {
        return Err(d);
    }
    let mut out = Vec::with_capacity(shared.samples() as usize);
    for row in shared.row0..=shared.row1 {
        for col in shared.col0..=shared.col1 {
            let (va, vb) = (a.at(col, row), b.at(col, row));
            out.push(match policy {
                _ if agree(va, vb) => va,
                SeamPolicy::Strict | SeamPolicy::First => va,
                SeamPolicy::Mean if va.is_nan() || vb.is_nan() => f32::NAN,
                SeamPolicy::Mean => ((f64::from(va) + f64::from(vb)) / 2.0) as f32,
            });
        }
    }
    Ok(out)
}

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;

    fn tiles() -> (Heightfield, Heightfield) {
        // Two 4 x 3 tiles side by side sharing column 3 of the first (column 0 of the second).
        let a = Heightfield::from_fn(4, 3, |x, y| (10 * y + x) as f32).unwrap();
        let b = Heightfield::from_fn(4, 3, |x, y| (10 * y + x + 3) as f32).unwrap();
        (a, b)
    }

    /// `a` at the origin and `b` east of it, sharing `a`'s last column.
    fn side_by_side<'a>(a: &'a Heightfield, b: &'a Heightfield) -> (Placed<'a>, Placed<'a>) {
        let pa = Placed {
            field: a,
            col0: 0,
            row0: 0,
        };
        let pb = Placed {
            field: b,
            col0: u64::from(a.width() - 1),
            row0: 0,
        };
        (pa, pb)
    }

    fn edge() -> SampleRect {
        SampleRect {
            col0: 3,
            row0: 0,
            col1: 3,
            row1: 2,
        }
    }

    #[test]
    fn agreeing_neighbours_settle_to_their_samples() {
        let (a, b) = tiles();
        let (pa, pb) = side_by_side(&a, &b);
        assert_eq!(first_difference(pa, pb, &edge()), None);
        assert_eq!(
            settle(pa, pb, &edge(), SeamPolicy::Strict),
            Ok(vec![3.0, 13.0, 23.0])
        );
    }

    #[test]
    fn a_disagreement_is_named_or_settled_by_the_policy() {
        let (a, _) = tiles();
        let b = Heightfield::from_fn(4, 3, |x, y| match (x, y) {
            (0, 1) => 20.0,
            (0, 2) => f32::NAN,
            _ => (10 * y + x + 3) as f32,
        })
        .unwrap();
        let (pa, pb) = side_by_side(&a, &b);
        let d = Disagreement {
            col: 3,
            row: 1,
            a: 13.0,
            b: 20.0,
        };
        assert_eq!(first_difference(pa, pb, &edge()), Some(d));
        assert_eq!(settle(pa, pb, &edge(), SeamPolicy::Strict), Err(d));
        assert_eq!(
            settle(pa, pb, &edge(), SeamPolicy::First),
            Ok(vec![3.0, 13.0, 23.0])
        );
        let mean = settle(pa, pb, &edge(), SeamPolicy::Mean).unwrap();
        assert_eq!(&mean[..2], &[3.0, 16.5]);
        assert!(mean[2].is_nan(), "a void on either side wins");
        assert_eq!("mean".parse::<SeamPolicy>(), Ok(SeamPolicy::Mean));
        assert!("average".parse::<SeamPolicy>().is_err());
    }

    proptest! {
        /// Any two tiles cut from one field with a shared column agree on it; changing any one
        /// sample of the shared column in one tile is found, at that sample.
        #[test]
        fn a_cut_field_agrees_and_any_change_is_found(
            w in 3u32..20, h in 1u32..20, cut in 1u32..18, seed in any::<u32>(),
            at in any::<prop::sample::Index>(), void in any::<bool>(),
        ) {
            let cut = cut.min(w - 2);
            let field = Heightfield::from_fn(w, h, |x, y| ((x * 31 + y * 17 + seed) % 97) as f32).unwrap();
            let left = Heightfield::from_fn(cut + 1, h, |x, y| field.get(x, y).unwrap()).unwrap();
            let right = Heightfield::from_fn(w - cut, h, |x, y| field.get(x + cut, y).unwrap()).unwrap();
            let shared = SampleRect { col0: u64::from(cut), row0: 0, col1: u64::from(cut), row1: u64::from(h - 1) };
            let pa = Placed { field: &left, col0: 0, row0: 0 };
            let pb = Placed { field: &right, col0: u64::from(cut), row0: 0 };
            prop_assert_eq!(first_difference(pa, pb, &shared), None);
            let row = at.index(h as usize) as u32;
            let changed = Heightfield::from_fn(w - cut, h, |x, y| {
                let v = right.get(x, y).unwrap();
                if (x, y) == (0, row) { if void { f32::NAN } else { v + 0.5 } } else { v }
            }).unwrap();
            let pc = Placed { field: &changed, col0: u64::from(cut), row0: 0 };
            let d = first_difference(pa, pc, &shared).unwrap();
            prop_assert_eq!((d.col, d.row), (u64::from(cut), u64::from(row)));
        }
    }
}
