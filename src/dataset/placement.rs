//! Where the tiles of a dataset lie in its one sample grid (issue 16,
//! `docs/datasets-design.md` §1). The module knows nothing of files: it takes a layout's
//! text, or the tiles' georeferences and sizes, and answers with rectangles, or with an error
//! that names the line or the tiles at fault.
//!
//! Tiles may share an edge (SRTM's 3601-sample tiles repeat their border row and column) or
//! meet without overlapping. They never overlap by more than one row or column, so the
//! dataset's grid has one owner per sample away from the shared edges. Holes are allowed.

use crate::heightfield::Georeference;
use crate::model::SampleRect;

/// A layout line: `path,col0,row0`.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct LayoutLine {
    /// The tile's file, as the layout names it.
    pub path: String,
    /// Its first column in dataset samples.
    pub col0: u64,
    /// Its first row in dataset samples.
    pub row0: u64,
}

/// Why tiles cannot be placed.
#[derive(Clone, Debug, PartialEq, thiserror::Error)]
pub enum PlacementError {
    /// A layout line that is not `path,col0,row0`.
    #[error("layout line {line}: {detail}")]
    Layout {
        /// 1-based line number.
        line: usize,
        /// What is wrong.
        detail: String,
    },
    /// Two tiles overlap by more than a shared edge row or column.
    #[error(
        "tiles {a} and {b} overlap in {cols} x {rows} samples from column {col0}, row {row0}: \
         neighbours may share one edge row or column, no more"
    )]
    Overlap {
        /// The first tile (its index).
        a: usize,
        /// The second tile.
        b: usize,
        /// First column of the overlap.
        col0: u64,
        /// First row of the overlap.
        row0: u64,
        /// Columns of the overlap.
        cols: u64,
        /// Rows of the overlap.
        rows: u64,
    },
    /// Georeferences that do not put the tiles on one grid.
    #[error("tile {tile}: {detail}")]
    Georeference {
        /// The tile at fault (its index).
        tile: usize,
        /// What is wrong.
        detail: String,
    },
}

/// Parses a layout: one tile a line, `path,col0,row0`, offsets in dataset samples. Blank
/// lines and lines starting with `#` are skipped; a path may not be empty and may hold no
/// comma.
pub fn parse_layout(text: &str) -> Result<Vec<LayoutLine>, PlacementError> {
    let mut out = Vec::new();
    for (i, raw) in text.lines().enumerate() {
        let line = raw.trim();
        if line.is_empty() || line.starts_with('#') {
            continue;
        }
        let bad = |detail: String| PlacementError::Layout {
            line: i + 1,
            detail,
        };
        let fields: Vec<&str> = line.split(',').map(str::trim).collect();
        let [path, col0, row0] = fields[..] else {
            return Err(bad(format!(
                "{} fields, expected path,col0,row0",
                fields.len()
            )));
        };
        if path.is_empty() {
            return Err(bad("an empty path".into()));
        }
        let offset = |what: &str, v: &str| {
            v.parse::<u64>()
                .map_err(|_| bad(format!("{what} {v:?} is not a whole number of samples")))
        };
        out.push(LayoutLine {
            path: path.to_string(),
            col0: offset("col0", col0)?,
            row0: offset("row0", row0)?,
        });
    }
    Ok(out)
}

/// How far from a whole step a georeferenced offset may lie (in steps): sources print
/// origins to about 10 significant digits.
const STEP_TOLERANCE: f64 = 1e-6;

/// Places tiles by their georeferences: `(georeference, width, height)` per tile, all in one
/// CRS with one step, their origins a whole number of steps apart. Returns each tile's
/// `(col0, row0)`, the westmost and northmost tile at 0 (rows count down the step's
/// direction, so a north-up grid's negative step puts the northmost tile first).
pub fn place_by_georeference(
    tiles: &[(Georeference, u32, u32)],
) -> Result<Vec<(u64, u64)>, PlacementError> {
    let Some((first, _, _)) = tiles.first() else {
        return Ok(Vec::new());
    };
    let step = first.step;
    if !(step[0].is_finite() && step[1].is_finite() && step[0] != 0.0 && step[1] != 0.0) {
        return Err(PlacementError::Georeference {
            tile: 0,
            detail: format!("step {step:?} is not finite and non-zero"),
        });
    }
    let mut offsets = Vec::with_capacity(tiles.len());
    for (i, (g, _, _)) in tiles.iter().enumerate() {
        let bad = |detail: String| PlacementError::Georeference { tile: i, detail };
        if g.crs != first.crs {
            return Err(bad(format!(
                "CRS {:?}, where tile 0 has {:?}",
                g.crs, first.crs
            )));
        }
        for a in 0..2 {
            if (g.step[a] - step[a]).abs() > STEP_TOLERANCE * step[a].abs() {
                return Err(bad(format!(
                    "step {:?}, where tile 0 has {step:?}: a dataset has one grid",
                    g.step
                )));
            }
        }
        let mut at = [0i64; 2];
        for a in 0..2 {
            let steps = (g.origin[a] - first.origin[a]) / step[a];
            let whole = steps.round();
            if !steps.is_finite()
                || (steps - whole).abs() > STEP_TOLERANCE * whole.abs().max(1.0)
                || whole.abs() > (1u64 << 52) as f64
            {
                return Err(bad(format!(
                    "origin {:?} is {steps} steps from tile 0's along axis {a}, not a whole number",
                    g.origin
                )));
            }
            at[a] = whole as i64;
        }
        offsets.push(at);
    }
    let min = |a: usize| offsets.iter().map(|o| o[a]).min().unwrap_or(0);
    let (c, r) = (min(0), min(1));
    Ok(offsets
        .iter()
        .map(|o| ((o[0] - c).unsigned_abs(), (o[1] - r).unsigned_abs()))
        .collect())
}

/// The rectangle of a tile at `(col0, row0)` with `width × height` samples.
pub fn rect(col0: u64, row0: u64, width: u32, height: u32) -> SampleRect {
    SampleRect {
        col0,
        row0,
        col1: col0 + u64::from(width.max(1)) - 1,
        row1: row0 + u64::from(height.max(1)) - 1,
    }
}

/// Checks that no two tiles overlap by more than a shared edge: any overlap is one column
/// wide or one row high. Returns the shared edges, `(a, b, overlap)` with `a < b`, for the
/// edge-agreement check and the adjacency tables.
pub fn check_tiling(
    tiles: &[SampleRect],
) -> Result<Vec<(usize, usize, SampleRect)>, PlacementError> {
    let mut order: Vec<usize> = (0..tiles.len()).collect();
    order.sort_by_key(|&i| (tiles[i].col0, tiles[i].row0));
    let mut shared = Vec::new();
    // A sweep along columns: a tile meets only the tiles whose columns began before it ends.
    for (k, &a) in order.iter().enumerate() {
        for &b in &order[k + 1..] {
            if tiles[b].col0 > tiles[a].col1 {
                break;
            }
            let Some(o) = tiles[a].intersect(&tiles[b]) else {
                continue;
            };
            let (cols, rows) = (o.col1 - o.col0 + 1, o.row1 - o.row0 + 1);
            let (a, b) = (a.min(b), a.max(b));
            if cols > 1 && rows > 1 {
                return Err(PlacementError::Overlap {
                    a,
                    b,
                    col0: o.col0,
                    row0: o.row0,
                    cols,
                    rows,
                });
            }
            shared.push((a, b, o));
        }
    }
    shared.sort_by_key(|&(a, b, _)| (a, b));
    Ok(shared)
}

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;

    #[test]
    fn a_layout_parses_and_names_its_bad_lines() {
        let ok = parse_layout("# tiles\nN43E006.hgt, 0, 0\n\nN43E007.hgt,1200,0\n").unwrap();
        assert_eq!(ok.len(), 2);
        assert_eq!(ok[1].col0, 1200);
        for (text, line) in [
            ("a.fmrh,1\n", 1),
            ("a.fmrh,0,0\nb.fmrh,-3,0\n", 2),
            ("a.fmrh,0,0,7\n", 1),
            ("\n,0,0\n", 2),
            ("a,1.5,0\n", 1),
        ] {
            match parse_layout(text) {
                Err(PlacementError::Layout { line: l, .. }) => assert_eq!(l, line, "{text:?}"),
                other => panic!("{text:?}: {other:?}"),
            }
        }
    }

    fn srtm(lon: f64, lat: f64) -> Georeference {
        Georeference {
            crs: Some("EPSG:4326".into()),
            origin: [lon, lat + 1.0],
            step: [1.0 / 1200.0, -1.0 / 1200.0],
        }
    }

    #[test]
    fn srtm_neighbours_share_an_edge() {
        let tiles = [
            (srtm(7.0, 43.0), 1201, 1201),
            (srtm(6.0, 43.0), 1201, 1201),
            (srtm(6.0, 42.0), 1201, 1201),
        ];
        let at = place_by_georeference(&tiles).unwrap();
        assert_eq!(at, vec![(1200, 0), (0, 0), (0, 1200)]);
        let rects: Vec<SampleRect> = tiles
            .iter()
            .zip(&at)
            .map(|((_, w, h), &(c, r))| rect(c, r, *w, *h))
            .collect();
        let shared = check_tiling(&rects).unwrap();
        assert_eq!(shared.len(), 3, "two edges and a corner: {shared:?}");
        let (_, _, edge) = shared.iter().find(|s| (s.0, s.1) == (0, 1)).unwrap();
        assert_eq!(
            (edge.col0, edge.col1, edge.row0, edge.row1),
            (1200, 1200, 0, 1200)
        );
    }

    #[test]
    fn georeferences_off_one_grid_are_refused() {
        let mut other_step = srtm(7.0, 43.0);
        other_step.step = [1.0 / 3600.0, -1.0 / 3600.0];
        let mut other_crs = srtm(7.0, 43.0);
        other_crs.crs = Some("EPSG:32632".into());
        let mut off_grid = srtm(7.0, 43.0);
        off_grid.origin[0] += 0.4 / 1200.0;
        for (bad, what) in [
            (other_step, "step"),
            (other_crs, "CRS"),
            (off_grid, "whole"),
        ] {
            match place_by_georeference(&[(srtm(6.0, 43.0), 1201, 1201), (bad, 1201, 1201)]) {
                Err(e @ PlacementError::Georeference { tile: 1, .. }) => {
                    assert!(e.to_string().contains(what), "{e}")
                }
                other => panic!("{what}: {other:?}"),
            }
        }
    }

    #[test]
    fn tiles_overlapping_by_two_rows_are_refused_naming_both() {
        let tiles = [
            rect(0, 0, 100, 100),
            rect(0, 98, 100, 100),
            rect(99, 0, 50, 50),
        ];
        match check_tiling(&tiles) {
            Err(PlacementError::Overlap {
                a: 0,
                b: 1,
                rows: 2,
                cols: 100,
                ..
            }) => {}
            other => panic!("{other:?}"),
        }
    }

    proptest! {
        /// Any grid of tiles cut at random columns and rows, neighbours sharing their edge
        /// (or, when `gap`, meeting without it), with random holes: the tiling checks, and
        /// its shared edges are exactly the neighbours' one-sample overlaps.
        #[test]
        fn any_cut_grid_checks(
            cuts_x in proptest::collection::btree_set(2u64..400, 0..4),
            cuts_y in proptest::collection::btree_set(2u64..400, 0..4),
            gap in any::<bool>(),
            holes in proptest::collection::vec(any::<bool>(), 25),
            nudge in any::<bool>(),
        ) {
            let xs: Vec<u64> = std::iter::once(0).chain(cuts_x).chain(std::iter::once(500)).collect();
            let ys: Vec<u64> = std::iter::once(0).chain(cuts_y).chain(std::iter::once(500)).collect();
            let mut tiles = Vec::new();
            for (j, w) in ys.windows(2).enumerate() {
                for (i, v) in xs.windows(2).enumerate() {
                    if holes[(j * 5 + i) % 25] && (i, j) != (0, 0) {
                        continue;
                    }
                    // Sharing the edge: the tile ends on the next one's first sample.
                    let end = |next: u64| if gap { next - 1 } else { next };
                    tiles.push(SampleRect { col0: v[0], row0: w[0], col1: end(v[1]), row1: end(w[1]) });
                }
            }
            let shared = check_tiling(&tiles).unwrap();
            for &(a, b, o) in &shared {
                prop_assert!(!gap);
                prop_assert!(o.col0 == o.col1 || o.row0 == o.row1);
                prop_assert_eq!(tiles[a].intersect(&tiles[b]), Some(o));
            }
            // Pushing a tile one sample further into its east neighbour is refused.
            if nudge && !gap {
                if let Some(i) = (0..tiles.len()).find(|&i| tiles.iter().any(|t| t.col0 == tiles[i].col1 && t.row0 == tiles[i].row0)) {
                    let mut bad = tiles.clone();
                    bad[i].col1 += 1;
                    if bad[i].row1 > bad[i].row0 {
                        let refused = matches!(check_tiling(&bad), Err(PlacementError::Overlap { .. }));
                        prop_assert!(refused);
                    }
                }
            }
        }
    }
}
