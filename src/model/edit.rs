//! Editing a built model in place: replace a rectangle of samples, and bring the raster, the
//! measurements, the FMRH and the clusters to exactly what a fresh build of the new samples
//! with the same block size and thresholds gives.
//!
//! **Why it can be incremental.** A node's measured error is the largest error of its
//! `b - 1` *bands* (model §4: band `k` is the strip of cells between grid rows `k` and
//! `k + 1`), and a band reads only the samples of its footprint's columns in rows
//! `row0 + k·s ..= row0 + (k+1)·s` (clamped at the data edge). Maxima, minima and counts are
//! exact under any grouping, so keeping every band's [`NodeStats`] and measuring again only
//! the bands that meet a changed sample gives every node's statistics bit for bit. `e*`,
//! pruning and the cuts are then recomputed from all nodes, which is linear in the nodes
//! (thousands), not in the samples (millions).
//!
//! **Mending.** A void's stand-in comes from its whole row or column (model §3), so a patch
//! can change stand-ins far outside itself. When voids are involved the raster is mended
//! again from scratch and compared, and the changed stand-ins join the dirty region (see
//! [`MendedRaster::replace`]).
//!
//! **Thinning by area** (format 6, [`super::thinning`]) follows the same rule as a build: a
//! node's candidate factor depends on its footprint alone, so the editor keeps, beside each
//! node's square bands, the bands of its grid thinned by that factor, and decides from the
//! two errors as [`super::tree::Measurements::thin_by_area`] does.
//!
//! **Thresholds** stay those the editor was given (for a container: the stored ones). A fresh
//! build of the same samples with [`Thresholds::Explicit`](super::Thresholds) of them gives
//! the same model.

use rayon::prelude::*;

use super::cluster;
use super::domain::{Domain, SampleRect};
use super::measure::{measure_band, NodeStats};
use super::precision::{self, Precision};
use super::raster::MendedRaster;
use super::thinning::{candidate_log2, keeps_thinned, LatLonSpacing};
use super::tree::{Fmrh, Measurements};
use super::Model;
use crate::error::{Error, Result};
use crate::heightfield::Heightfield;

/// A model that accepts sample replacements.
#[derive(Clone, Debug)]
pub struct ModelEditor {
    model: Model,
    thresholds: Vec<f64>,
    measured: Measurements,
    /// Per level, row-major nodes, `b - 1` bands each.
    bands: Vec<Vec<NodeStats>>,
    /// Per level, row-major nodes: `log₂` of the candidate thinning factor (empty levels
    /// when the model is not thinned).
    candidates: Vec<Vec<u8>>,
    /// As `bands`, for the grids thinned by their candidate factor (empty where it is 1).
    thin_bands: Vec<Vec<NodeStats>>,
}

/// One band of one node: `(level, x, y, band)`.
type BandId = (u8, u32, u32, u32);

impl ModelEditor {
    /// Builds the model of `heightfield` with blocks of `block_size` samples, exactly
    /// `thresholds` and the storage `precision` (validated as for [`Model::build`]), its
    /// nodes thinned by area with `thinning` if given (as a build with
    /// [`super::ThinByArea::Spacing`]). Heights are quantised to the precision here and in
    /// every patch, as a build would.
    pub fn new(
        heightfield: Heightfield,
        block_size: u32,
        thresholds: &[f64],
        precision: Option<Precision>,
        thinning: Option<LatLonSpacing>,
    ) -> Result<Self> {
        let domain = Domain::new(heightfield.width(), heightfield.height(), block_size)?;
        let thresholds =
            precision::check_thresholds(cluster::validate_thresholds(thresholds)?, precision)?;
        let heightfield = match precision {
            Some(p) => p.quantise_heightfield(heightfield).0,
            None => heightfield,
        };
        let raster = MendedRaster::new(heightfield)
            .with_storage_error(precision.map_or(0.0, Precision::bound));
        let per_node = domain.block_size() - 1;
        let candidates: Vec<Vec<u8>> = (0..domain.levels())
            .map(|level| match &thinning {
                Some(spacing) => {
                    let (cols, _) = domain.nodes_across(level);
                    (0..node_count(&domain, level))
                        .map(|i| {
                            let (x, y) = ((i % cols as usize) as u32, (i / cols as usize) as u32);
                            candidate_log2(spacing, &domain, level, x, y)
                        })
                        .collect()
                }
                None => Vec::new(),
            })
            .collect();
        let measure_all = |thinned: bool| -> Vec<Vec<NodeStats>> {
            (0..domain.levels())
                .map(|level| {
                    let cand = &candidates[usize::from(level)];
                    if thinned && cand.iter().all(|&c| c == 0) {
                        return Vec::new();
                    }
                    let (cols, _) = domain.nodes_across(level);
                    let count = node_count(&domain, level) * per_node as usize;
                    (0..count)
                        .into_par_iter()
                        .map(|i| {
                            let node = i / per_node as usize;
                            let (x, y) =
                                ((node % cols as usize) as u32, (node / cols as usize) as u32);
                            let k = u64::from(i as u32 % per_node);
                            let thin = if thinned { cand[node] } else { 0 };
                            if thinned && thin == 0 {
                                return NodeStats::EMPTY;
                            }
                            measure_band(&raster, &domain, level, (x, y), k, thin)
                        })
                        .collect()
                })
                .collect()
        };
        let bands = measure_all(false);
        let thin_bands = measure_all(true);
        // Each node's statistics and thinning, decided once from its two sets of bands.
        let decided: Vec<Vec<(NodeStats, u8)>> = (0..domain.levels())
            .map(|level| {
                (0..node_count(&domain, level))
                    .map(|node| node_stats(&bands, &candidates, &thin_bands, per_node, level, node))
                    .collect()
            })
            .collect();
        let mut measured = Measurements::from_stats(
            (0..domain.levels())
                .zip(&decided)
                .map(|(level, d)| {
                    let (cols, rows) = domain.nodes_across(level);
                    (cols, rows, d.iter().map(|n| n.0).collect())
                })
                .collect(),
        );
        for (m, d) in measured.levels.iter_mut().zip(&decided) {
            m.thin = d.iter().map(|n| n.1).collect();
        }
        let tree = Fmrh::prune(domain, &measured, thresholds[0]);
        let clusters = cluster::build_clusters(&tree, &thresholds);
        Ok(ModelEditor {
            model: Model {
                raster,
                tree,
                clusters,
                precision,
                storage_error_measured: None,
                thinning,
            },
            thresholds,
            measured,
            bands,
            candidates,
            thin_bands,
        })
    }

    /// The model as it stands.
    pub fn model(&self) -> &Model {
        &self.model
    }

    /// The cluster thresholds, ascending.
    #[cfg(any(test, feature = "testing"))]
    pub fn thresholds(&self) -> &[f64] {
        &self.thresholds
    }

    /// Replaces the samples of the rectangle whose north-west corner is `(col0, row0)` with
    /// `patch` (NaN = void). The rectangle must lie inside the data. Returns the rectangles
    /// whose mended heights or validity may have changed (the patch's, and for voids the
    /// stand-ins that moved): every node and block whose footprint meets none of them keeps
    /// its grid.
    pub fn replace(
        &mut self,
        col0: u64,
        row0: u64,
        patch: &Heightfield,
    ) -> Result<Vec<SampleRect>> {
        let d = *self.model.domain();
        let data = d.data_rect();
        let (pw, ph) = (u64::from(patch.width()), u64::from(patch.height()));
        let fits = |c0: u64, len: u64, end: u64| c0.checked_add(len).is_some_and(|e| e <= end + 1);
        if !fits(col0, pw, data.col1) || !fits(row0, ph, data.row1) {
            return Err(Error::InvalidArgument(format!(
                "a {pw} x {ph} patch at column {col0}, row {row0} does not fit inside the \
                 {} x {} data",
                data.col1 + 1,
                data.row1 + 1
            )));
        }
        let quantised;
        let patch = match self.model.precision {
            Some(p) => {
                quantised = p.quantise_heightfield(patch.clone()).0;
                &quantised
            }
            None => patch,
        };
        let dirty = self.model.raster.replace(col0, row0, patch);
        let mut todo: Vec<BandId> = Vec::new();
        for rect in &dirty {
            for level in 0..d.levels() {
                dirty_bands(&d, level, rect, &mut todo);
            }
        }
        todo.sort_unstable();
        todo.dedup();
        let raster = &self.model.raster;
        let candidates = &self.candidates;
        let per_node = (d.block_size() - 1) as usize;
        let measured: Vec<(NodeStats, Option<NodeStats>)> = todo
            .par_iter()
            .map(|&(level, x, y, k)| {
                let (cols, _) = d.nodes_across(level);
                let node = y as usize * cols as usize + x as usize;
                let thin = candidates[usize::from(level)]
                    .get(node)
                    .copied()
                    .unwrap_or(0);
                let square = measure_band(raster, &d, level, (x, y), u64::from(k), 0);
                let thinned =
                    (thin > 0).then(|| measure_band(raster, &d, level, (x, y), u64::from(k), thin));
                (square, thinned)
            })
            .collect();
        for (&(level, x, y, k), (square, thinned)) in todo.iter().zip(measured) {
            let (cols, _) = d.nodes_across(level);
            let at = (y as usize * cols as usize + x as usize) * per_node + k as usize;
            self.bands[usize::from(level)][at] = square;
            if let Some(t) = thinned {
                self.thin_bands[usize::from(level)][at] = t;
            }
        }
        let mut nodes: Vec<(u8, u32, u32)> = todo.iter().map(|&(l, x, y, _)| (l, x, y)).collect();
        nodes.dedup();
        for (level, x, y) in nodes {
            let lm = &mut self.measured.levels[usize::from(level)];
            let node = y as usize * lm.cols as usize + x as usize;
            let (stats, thin) = node_stats(
                &self.bands,
                &self.candidates,
                &self.thin_bands,
                per_node as u32,
                level,
                node,
            );
            lm.stats[node] = stats;
            if let Some(t) = lm.thin.get_mut(node) {
                *t = thin;
            }
        }
        self.measured.update_monotone();
        self.model.tree = Fmrh::prune(d, &self.measured, self.thresholds[0]);
        self.model.clusters = cluster::build_clusters(&self.model.tree, &self.thresholds);
        Ok(dirty)
    }
}

/// A node's statistics from its bands, and `log₂` of the factor its grid is stored thinned
/// by: its square bands' merge, with the thinned bands' error where the build's rule
/// ([`keeps_thinned`]) keeps it thinned.
fn node_stats(
    bands: &[Vec<NodeStats>],
    candidates: &[Vec<u8>],
    thin_bands: &[Vec<NodeStats>],
    per_node: u32,
    level: u8,
    node: usize,
) -> (NodeStats, u8) {
    let per_node = per_node as usize;
    let range = node * per_node..(node + 1) * per_node;
    let merge = |b: &[NodeStats]| b.iter().fold(NodeStats::EMPTY, |a, &b| a.merge(b));
    let level = usize::from(level);
    let square = merge(&bands[level][range.clone()]);
    let thin = candidates[level].get(node).copied().unwrap_or(0);
    if thin == 0 {
        return (square, 0);
    }
    let thinned = merge(&thin_bands[level][range]);
    if keeps_thinned(square.error, thinned.error) {
        (
            NodeStats {
                error: thinned.error,
                ..square
            },
            thin,
        )
    } else {
        (square, 0)
    }
}

/// Nodes that exist at `level`.
fn node_count(d: &Domain, level: u8) -> usize {
    let (cols, rows) = d.nodes_across(level);
    cols as usize * rows as usize
}

/// Appends the bands at `level` that read a sample of `rect`: band `k` of a node reads its
/// footprint's columns in rows `row0 + k·s ..= row0 + (k+1)·s`.
fn dirty_bands(d: &Domain, level: u8, rect: &SampleRect, out: &mut Vec<BandId>) {
    let span = d.node_cells(level);
    let s = d.stride(level);
    let (cols, rows) = d.nodes_across(level);
    // Node x spans columns x·span ..= (x+1)·span.
    let first = |lo: u64| (lo.div_ceil(span)).saturating_sub(1);
    let x0 = first(rect.col0);
    let y0 = first(rect.row0);
    let x1 = (rect.col1 / span).min(u64::from(cols) - 1);
    let y1 = (rect.row1 / span).min(u64::from(rows) - 1);
    let last_band = u64::from(d.block_size() - 2);
    for y in y0..=y1 {
        let fp_row0 = y * span;
        let k0 = if rect.row0 > fp_row0 {
            (rect.row0 - fp_row0 - 1) / s
        } else {
            0
        };
        let k1 = ((rect.row1 - fp_row0) / s).min(last_band);
        for x in x0..=x1 {
            for k in k0..=k1 {
                out.push((level, x as u32, y as u32, k as u32));
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::model::{BuildOptions, Thresholds};

    fn wavy(w: u32, h: u32, seed: f32) -> Heightfield {
        Heightfield::from_fn(w, h, |x, y| {
            ((x as f32 * 0.13 + seed).sin() * 20.0 + (y as f32 * 0.07).cos() * 15.0).round()
        })
        .unwrap()
    }

    fn assert_same(a: &Model, b: &Model) {
        assert_eq!(a.tree().nodes(), b.tree().nodes());
        assert_eq!(a.clusters(), b.clusters());
        assert_eq!(
            a.raster().to_heightfield().samples().len(),
            b.raster().to_heightfield().samples().len()
        );
    }

    /// A patch in the middle, one on the far corner, and one full of voids: each time the
    /// edited model equals a fresh build of the same samples.
    #[test]
    fn replacements_equal_rebuilds() {
        let (w, h) = (70u32, 45u32);
        let base = wavy(w, h, 0.0);
        let thresholds = [0.0, 0.5, 2.0, 8.0];
        let mut ed = ModelEditor::new(base.clone(), 9, &thresholds, None, None).unwrap();
        let mut samples = base.samples().to_vec();
        let patches = [
            (10u64, 7u64, wavy(13, 9, 1.0)),
            (w as u64 - 5, h as u64 - 4, wavy(5, 4, 2.0)),
            (
                30,
                20,
                Heightfield::from_fn(6, 6, |x, y| if (x + y) % 3 == 0 { f32::NAN } else { 5.0 })
                    .unwrap(),
            ),
            (0, 0, Heightfield::from_fn(w, 1, |_, _| 3.0).unwrap()),
        ];
        for (c0, r0, p) in &patches {
            ed.replace(*c0, *r0, p).unwrap();
            for j in 0..p.height() as u64 {
                for i in 0..p.width() as u64 {
                    samples[((r0 + j) * w as u64 + c0 + i) as usize] =
                        p.samples()[(j * p.width() as u64 + i) as usize];
                }
            }
            let fresh = Model::build(
                Heightfield::new(w, h, samples.clone()).unwrap(),
                &BuildOptions {
                    block_size: 9,
                    thresholds: Thresholds::Explicit(thresholds.to_vec()),
                    precision: None,
                    thin: Default::default(),
                },
            )
            .unwrap();
            assert_same(ed.model(), &fresh);
            let (a, b) = (ed.model().raster(), fresh.raster());
            for r in 0..h as u64 {
                for c in 0..w as u64 {
                    assert_eq!(a.value(c, r).to_bits(), b.value(c, r).to_bits());
                    assert_eq!(a.is_valid(c, r), b.is_valid(c, r));
                }
            }
        }
    }

    #[test]
    fn patch_outside_is_refused() {
        let mut ed = ModelEditor::new(wavy(20, 20, 0.0), 9, &[0.0, 1.0], None, None).unwrap();
        let before = ed.model().tree().nodes().to_vec();
        let err = ed.replace(15, 0, &wavy(6, 2, 0.0)).unwrap_err();
        assert!(matches!(err, Error::InvalidArgument(_)), "{err}");
        assert_eq!(ed.model().tree().nodes(), &before[..]);
    }
}
