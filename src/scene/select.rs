//! One selection, start to finish: the tolerance checked, the region found, the mode's cut
//! searched ([`Mode`]: `uniform` or `view_dependent`, each an `impl` block on the shared
//! `Search` state), then the blocks finished (sorted, culled, neighbour levels) and counted.
//! A new mode is a new file with an `impl` block on `Search`, a [`Mode`] variant, and one arm
//! here.

use std::time::Instant;

use super::camera::{Camera, TerrainFrame};
use super::result::{Mode, Scene, SceneOptions, SceneStats};
use super::search::Search;
use super::terrain::{Region, Terrain};
use crate::error::{Error, Result};
use crate::model::SampleRect;
use crate::store::Source;

/// Levels above the finest that [`Terrain::scene_blocks`] splits the frustum's region to:
/// quadrants of 8 × 8 finest blocks at the least. Measured over the 1.07 G-sample mosaic's
/// fly-through (64 tiles of 64 × 64 blocks): 3 to 6 levels all schedule a frame in about
/// 0.45× the exact region's time, 2 in 0.55×, 1 in 0.8×; 3 keeps the region's pieces small
/// on larger stores, where a coarse piece the frustum barely meets would scan many nodes.
pub const SCHEDULE_REGION_LEVELS: u8 = 3;

impl<S: Source> Terrain<'_, S> {
    /// The *cut* of the terrain within a static bound: the blocks over `window` (inclusive
    /// samples, inside the data) of the coarsest error level whose every node is within
    /// `max_error` metres of the source (`format-spec/model.md`'s cluster of the largest
    /// threshold at most `max_error`; physical blocks, `e* = 0`, below the finest). No
    /// camera: the blocks' distances and screen errors are left at 0. A level is a cut of
    /// the whole tree, so two windows get the same block wherever they overlap: tiles cut
    /// from neighbouring windows agree on their shared edges.
    pub fn cut(&self, window: SampleRect, max_error: f64, gap: u64) -> Result<Scene> {
        let started = Instant::now();
        if max_error.is_nan() || max_error < 0.0 {
            return Err(Error::InvalidArgument(format!(
                "error bound {max_error} m: must be a number >= 0"
            )));
        }
        // A camera the search can hold; a window decides the region, so it is not looked
        // through, and no block is culled by it.
        let b = self.rect_box(&window, self.root().min_height, self.root().max_height);
        let centre = (b.min + b.max) * 0.5;
        let reach = (b.max - b.min).length().max(1.0);
        let nominal = Camera {
            eye: centre + glam::DVec3::splat(reach),
            target: centre,
            ..Camera::looking_at(glam::DVec3::ONE, glam::DVec3::ZERO)
        };
        let view = nominal.view()?;
        let region = self.region(&view, Some(window))?;
        let (mut blocks, mut stats) = self.search(&view, 0.0, &region, |search| {
            search.uniform_within(&region, max_error, gap)
        })?;
        for block in &mut blocks {
            block.distance = 0.0;
            block.screen_error = 0.0;
        }
        // Screen errors were counted from the nominal camera: there are none.
        stats.max_screen_error = 0.0;
        stats.schedule_ns = started.elapsed().as_nanos() as u64;
        Ok(Scene {
            mode: Mode::Uniform,
            tau: 0.0,
            window: region.span,
            blocks,
            stats,
        })
    }

    /// Runs one mode's search (`run`) over `region` seen from `view`, then finishes the
    /// blocks (sorted, culled unless a window decides the region, neighbour levels) and
    /// counts them.
    fn search(
        &self,
        view: &super::camera::View,
        tau: f64,
        region: &Region,
        run: impl FnOnce(&mut Search<'_, '_, S>) -> Result<()>,
    ) -> Result<(Vec<super::result::SceneBlock>, SceneStats)> {
        let mut search = Search {
            terrain: self,
            view,
            tau,
            cull: region.coarse,
            out: Vec::new(),
            stats: SceneStats {
                quadrants: region.quadrants.len() as u64,
                ..SceneStats::default()
            },
        };
        run(&mut search)?;
        let Search {
            mut out, mut stats, ..
        } = search;
        self.finish(view, region.window, &mut out);
        let side = u64::from(self.domain().block_size());
        for block in &out {
            stats.add_block(block, side);
        }
        Ok((out, stats))
    }

    /// Selects the blocks `camera` needs at tolerance `options.tau`.
    pub fn scene(&self, camera: &Camera, options: &SceneOptions) -> Result<Scene> {
        self.scene_with(camera, options, None)
    }

    /// As [`Terrain::scene`]; in uniform mode, with `p_min` (when given) as the nearest
    /// distance instead of the region's own. A dataset gives every tile the nearest distance
    /// over all of them, so that one static bound holds over the whole view.
    pub fn scene_with(
        &self,
        camera: &Camera,
        options: &SceneOptions,
        p_min: Option<f64>,
    ) -> Result<Scene> {
        self.select(camera, options, p_min, self.domain().finest_level())
    }

    /// The blocks of [`Terrain::scene`], the same to the bit, found sooner for a scheduler
    /// that needs only them. In view-dependent mode without a window the frustum's region
    /// is split no deeper than [`SCHEDULE_REGION_LEVELS`] levels above the finest: on a far
    /// tile that the frustum's edge crosses, the exact region is hundreds of one-block
    /// quadrants, each a range scan, for a cut of a few coarse nodes. The coarser region
    /// holds all the terrain the exact one does; its farthest point only seeds the search
    /// from a coarser cluster (still at or above the cut, see `view_dependent`); nodes whose
    /// box misses the frustum are dropped as the search meets them, and `finish` culls the
    /// rest as always. What differs is the scene's `window` (the coarser region's span) and
    /// its work counts (quadrants, ranges, pages, node reads). On the globe, and in uniform
    /// mode, this is [`Terrain::scene`].
    pub fn scene_blocks(&self, camera: &Camera, options: &SceneOptions) -> Result<Scene> {
        let flat = matches!(self.world(), TerrainFrame::Flat(_));
        let deepest = match (options.mode, options.window) {
            (Mode::View, None) if flat => self
                .domain()
                .finest_level()
                .saturating_sub(SCHEDULE_REGION_LEVELS),
            // Uniform mode's bound comes from the region's nearest point, so its region must
            // be exact. On the globe so must the frustum's: a quadrant below the horizon is
            // left out of it by a test of that quadrant, which a larger piece holding it may
            // not pass, and `finish` tests each block as a whole.
            _ => self.domain().finest_level(),
        };
        self.select(camera, options, None, deepest)
    }

    fn select(
        &self,
        camera: &Camera,
        options: &SceneOptions,
        p_min: Option<f64>,
        deepest: u8,
    ) -> Result<Scene> {
        let started = Instant::now();
        let view = camera.view()?;
        if !options.tau.is_finite() || options.tau < 0.0 {
            return Err(Error::InvalidArgument(format!(
                "tolerance {} px: must be finite and >= 0",
                options.tau
            )));
        }
        let region = self.region_to(&view, options.window, deepest)?;
        let (out, mut stats) = self.search(&view, options.tau, &region, |search| {
            match options.mode {
                Mode::Uniform => {
                    let p_min = match (p_min, options.window) {
                        (Some(p), _) => p,
                        (None, Some(w)) => self
                            .rect_box(&w, self.root().min_height, self.root().max_height)
                            .distance(view.eye),
                        (None, None) => region.near,
                    };
                    search.uniform(&region, p_min, options.gap)
                }
                Mode::View => search.view_dependent(&region, options.gap),
            }
        })?;
        stats.schedule_ns = started.elapsed().as_nanos() as u64;
        Ok(Scene {
            mode: options.mode,
            tau: options.tau,
            window: region.span,
            blocks: out,
            stats,
        })
    }
}
