//! One selection, start to finish: the tolerance checked, the region found, the mode's cut
//! searched ([`Mode`]: `uniform` or `view_dependent`, each an `impl` block on the shared
//! `Search` state), then the blocks finished (sorted, culled, neighbour levels) and counted.
//! A new mode is a new file with an `impl` block on `Search`, a [`Mode`] variant, and one arm
//! here.

use std::time::Instant;

use super::camera::Camera;
use super::result::{Mode, Scene, SceneOptions, SceneStats};
use super::search::Search;
use super::terrain::Terrain;
use crate::error::{Error, Result};
use crate::model::SampleRect;
use crate::store::Source;

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
        let (quadrants, window) = self.region(&view, Some(window))?;
        let (mut blocks, mut stats) = self.search(&view, 0.0, &quadrants, window, |search| {
            search.uniform_within(&quadrants, max_error, gap)
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
            window,
            blocks,
            stats,
        })
    }

    /// Runs one mode's search (`run`) over `quadrants` seen from `view`, then finishes the
    /// blocks (sorted, culled unless `window` decides the region, neighbour levels) and
    /// counts them.
    fn search(
        &self,
        view: &super::camera::View,
        tau: f64,
        quadrants: &[super::ranges::Quadrant],
        window: Option<SampleRect>,
        run: impl FnOnce(&mut Search<'_, '_, S>) -> Result<()>,
    ) -> Result<(Vec<super::result::SceneBlock>, SceneStats)> {
        let mut search = Search {
            terrain: self,
            view,
            tau,
            out: Vec::new(),
            stats: SceneStats {
                quadrants: quadrants.len() as u64,
                ..SceneStats::default()
            },
        };
        run(&mut search)?;
        let Search {
            mut out, mut stats, ..
        } = search;
        self.finish(view, window, &mut out);
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
        let started = Instant::now();
        let view = camera.view()?;
        if !options.tau.is_finite() || options.tau < 0.0 {
            return Err(Error::InvalidArgument(format!(
                "tolerance {} px: must be finite and >= 0",
                options.tau
            )));
        }
        let (quadrants, window) = self.region(&view, options.window)?;
        let (out, mut stats) =
            self.search(&view, options.tau, &quadrants, options.window, |search| {
                match options.mode {
                    Mode::Uniform => {
                        let p_min = match (p_min, options.window) {
                            (Some(p), _) => p,
                            (None, Some(w)) => self
                                .rect_box(&w, self.root().min_height, self.root().max_height)
                                .distance(view.eye),
                            (None, None) => quadrants
                                .iter()
                                .map(|q| self.quadrant_box(q).distance(view.eye))
                                .fold(f64::INFINITY, f64::min),
                        };
                        search.uniform(&quadrants, p_min, options.gap)
                    }
                    Mode::View => search.view_dependent(&quadrants, options.gap),
                }
            })?;
        stats.schedule_ns = started.elapsed().as_nanos() as u64;
        Ok(Scene {
            mode: options.mode,
            tau: options.tau,
            window,
            blocks: out,
            stats,
        })
    }
}
