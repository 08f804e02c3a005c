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
use crate::store::Source;

impl<S: Source> Terrain<'_, S> {
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
        let d = *self.domain();
        let (quadrants, window) = self.region(&view, options.window)?;
        let mut search = Search {
            terrain: self,
            view: &view,
            tau: options.tau,
            out: Vec::new(),
            stats: SceneStats {
                quadrants: quadrants.len() as u64,
                ..SceneStats::default()
            },
        };
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
                search.uniform(&quadrants, p_min, options.gap)?;
            }
            Mode::View => search.view_dependent(&quadrants, options.gap)?,
        }
        let Search {
            mut out, mut stats, ..
        } = search;
        self.finish(&view, options.window, &mut out);
        let side = u64::from(d.block_size());
        for block in &out {
            stats.add_block(block, side);
        }
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
