//! The terrain model: a heightfield cut into blocks, organised as an FMRH with measured errors,
//! grouped into error clusters in multiresolution Hilbert order.
//!
//! Read the submodules in order: [`domain`] (blocks, levels, padding), [`raster`] (voids
//! mended), [`surface`] (what a grid draws), [`measure`] (the static error), [`thinning`]
//! (a geographic grid's nodes coarsened east-west by area, format 6), [`tree`] (monotone
//! errors, pruning, Hilbert pre-order), [`cluster`] (cuts). [`Model::build`] runs them all;
//! [`edit`] brings a built model up to date with new samples, as a rebuild would.

pub mod cluster;
pub mod domain;
pub mod edit;
pub mod measure;
pub mod precision;
pub mod raster;
pub mod surface;
pub mod thinning;
pub mod tree;

pub use cluster::{Cluster, MAX_CLUSTERS};
pub use domain::{Domain, SampleRect, DEFAULT_BLOCK_SIZE};
#[cfg(any(test, feature = "testing"))]
pub use domain::{MAX_BLOCK_SIZE, MIN_BLOCK_SIZE};
pub use edit::ModelEditor;
#[cfg(any(test, feature = "testing"))]
pub use measure::NodeStats;
pub use precision::Precision;
pub use raster::MendedRaster;
pub use thinning::{LatLonSpacing, ThinByArea};
pub use tree::{Fmrh, Measurements, NO_PARENT};
#[cfg(any(test, feature = "testing"))]
pub use tree::Node;

use crate::error::Result;
use crate::heightfield::Heightfield;

/// Which cluster thresholds to build.
#[derive(Clone, Debug, Default, PartialEq)]
pub enum Thresholds {
    /// The default √2 ladder from the root's error down, plus 0 (model §6).
    #[default]
    Ladder,
    /// Exactly these thresholds (any order; duplicates are dropped).
    Explicit(Vec<f64>),
}

/// How to build a model.
#[derive(Clone, Debug, PartialEq)]
pub struct BuildOptions {
    /// Samples along a block side: `2^k + 1`, 9 to 1025.
    pub block_size: u32,
    /// Cluster thresholds.
    pub thresholds: Thresholds,
    /// Store heights to this step, within half of it (see [`precision`]); `None` keeps them
    /// bit for bit.
    pub precision: Option<Precision>,
    /// Thin nodes by area (format 6, [`thinning`]): by default where the heightfield is a
    /// longitude-latitude grid.
    pub thin: ThinByArea,
}

impl Default for BuildOptions {
    fn default() -> Self {
        BuildOptions {
            block_size: DEFAULT_BLOCK_SIZE,
            thresholds: Thresholds::Ladder,
            precision: None,
            thin: ThinByArea::Auto,
        }
    }
}

/// A built terrain model: the mended data, the FMRH and its clusters.
#[derive(Clone, Debug)]
pub struct Model {
    raster: MendedRaster,
    tree: Fmrh,
    clusters: Vec<Cluster>,
    precision: Option<Precision>,
    storage_error_measured: Option<f64>,
    thinning: Option<LatLonSpacing>,
}

/// A node's grid: the `b × b` point-decimation of the mended raster over its footprint, with
/// which grid samples stand in for voids or padding.
#[derive(Clone, Debug, PartialEq)]
pub struct NodeGrid {
    /// Samples a side.
    pub size: u32,
    /// Row-major heights (north row first); voids and padding carry their mended stand-in.
    pub heights: Vec<f32>,
    /// Row-major: `true` where the grid sample is not a real height.
    pub void: Vec<bool>,
}

impl Model {
    /// Builds the model of `heightfield` (consumed: its buffer becomes the mended raster).
    pub fn build(heightfield: Heightfield, options: &BuildOptions) -> Result<Model> {
        Model::build_with_progress(heightfield, options, &crate::progress::Silent)
    }

    /// As [`Model::build`], telling `progress` how the measuring (most of the time) advances.
    pub fn build_with_progress(
        heightfield: Heightfield,
        options: &BuildOptions,
        progress: &dyn crate::progress::Progress,
    ) -> Result<Model> {
        let domain = Domain::new(
            heightfield.width(),
            heightfield.height(),
            options.block_size,
        )?;
        let explicit = match &options.thresholds {
            Thresholds::Explicit(t) => Some(precision::check_thresholds(
                cluster::validate_thresholds(t)?,
                options.precision,
            )?),
            Thresholds::Ladder => None,
        };
        let precision = options.precision;
        let thinning = options
            .thin
            .spacing(heightfield.metadata.georeference.as_ref());
        let (heightfield, storage_error_measured) = match precision {
            Some(p) => {
                let (hf, worst) = p.quantise_heightfield(heightfield);
                (hf, Some(worst.unwrap_or(0.0)))
            }
            None => (heightfield, Some(0.0)),
        };
        let floor = precision.map_or(0.0, Precision::bound);
        let raster = MendedRaster::new(heightfield).with_storage_error(floor);
        let mut measured = Measurements::measure_with_progress(&raster, &domain, progress);
        if let Some(spacing) = &thinning {
            measured.thin_by_area(&raster, &domain, spacing);
        }
        let thresholds = explicit.clone().unwrap_or_else(|| {
            let mut ladder =
                cluster::default_ladder(measured.root_error(), measured.min_positive_error());
            // No node beats the storage error: the ladder's lossless rung becomes its bound.
            ladder.retain(|&t| t > floor);
            ladder.insert(0, floor);
            ladder
        });
        let tree = Fmrh::prune(domain, &measured, thresholds[0]);
        drop(measured);
        let mut clusters = cluster::build_clusters(&tree, &thresholds);
        if explicit.is_none() {
            clusters = cluster::merge_identical_cuts(clusters);
        }
        Ok(Model {
            raster,
            tree,
            clusters,
            precision,
            storage_error_measured,
            thinning,
        })
    }

    /// The geometry.
    pub fn domain(&self) -> &Domain {
        self.tree.domain()
    }

    /// The mended data.
    pub fn raster(&self) -> &MendedRaster {
        &self.raster
    }

    /// The FMRH.
    pub fn tree(&self) -> &Fmrh {
        &self.tree
    }

    /// The clusters, ascending by threshold.
    pub fn clusters(&self) -> &[Cluster] {
        &self.clusters
    }

    /// The storage precision its heights were kept to, if any.
    pub fn precision(&self) -> Option<Precision> {
        self.precision
    }

    /// The largest `|stored - source|` over the real heights, measured when the model was
    /// built from its source (0 without a precision; at most its bound with one). `None`
    /// for a model edited from stored heights, whose source is gone.
    pub fn storage_error_measured(&self) -> Option<f64> {
        self.storage_error_measured
    }

    /// The spacing its nodes were thinned by area with ([`thinning`]), if they were.
    pub fn thinning(&self) -> Option<LatLonSpacing> {
        self.thinning
    }

    /// The largest static error anywhere: the root's `e*`.
    pub fn max_error(&self) -> f64 {
        self.tree.nodes()[0].monotone_error
    }

    /// The grid of node `index` (see [`NodeGrid`]).
    pub fn node_grid(&self, index: u32) -> NodeGrid {
        let fp = self.tree.footprint(index);
        let node = *self.tree.node(index);
        let level = node.level;
        let (b, s) = (self.domain().block_size(), self.domain().stride(level));
        let mut heights = Vec::with_capacity(b as usize * b as usize);
        let mut void = Vec::with_capacity(b as usize * b as usize);
        for j in 0..u64::from(b) {
            for i in 0..u64::from(b) {
                let (col, row) = (fp.col0 + i * s, fp.row0 + j * s);
                heights.push(self.raster.value(col, row));
                void.push(!self.raster.is_valid(col, row));
            }
        }
        if node.thin > 0 {
            // Stored thinned (format 6): the grid a reader expands, bit for bit.
            let (gw, _) = self.domain().grid_dims(level, node.x, node.y);
            thinning::thin_in_place(&mut heights, b as usize, gw, 1 << node.thin);
        }
        NodeGrid {
            size: b,
            heights,
            void,
        }
    }
}
