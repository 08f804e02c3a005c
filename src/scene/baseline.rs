//! Two naive ways to answer a view, kept as yardsticks for the benchmarks and as
//! independent cross-checks for the tests.
//!
//! * [`all_finest`]: every physical block of the region, as a tiled store without levels of
//!   detail would load them (seed 000's "physical model directly").
//! * [`traversal`]: the view-dependent cut found top-down from the root through the node
//!   table, without clusters or index pages (seed 000's "logic structure FMRH"). Its answer
//!   is the view mode's; only the nodes it reads differ.

use crate::error::Result;
use crate::model::SampleRect;
use crate::store::Source;

use super::camera::Camera;
use super::ranges::{self, KeyRange};
use super::{SceneBlock, Terrain};

/// Every physical block of the region (the window, or the frustum's footprint), sorted by
/// key.
pub fn all_finest<S: Source>(
    terrain: &Terrain<'_, S>,
    camera: &Camera,
    window: Option<SampleRect>,
) -> Result<Vec<SceneBlock>> {
    let view = camera.view()?;
    let region = terrain.region(&view, window)?;
    let (zmin, zmax) = terrain.height_range();
    let mut out = Vec::new();
    for q in &region.quadrants {
        let (xs, ys) = q.blocks(terrain.domain());
        for y in ys {
            for x in xs.clone() {
                out.push(terrain.physical_block(&view, x, y, zmin, zmax)?);
            }
        }
    }
    terrain.finish(&view, window, &mut out);
    Ok(out)
}

/// The view-dependent cut by a top-down walk of the node table: at each node, keep it when
/// it meets `tau` where it is seen, else visit its children that meet the region.
pub fn traversal<S: Source>(
    terrain: &Terrain<'_, S>,
    camera: &Camera,
    tau: f64,
    window: Option<SampleRect>,
) -> Result<Vec<SceneBlock>> {
    let view = camera.view()?;
    let d = *terrain.domain();
    let region = ranges::merge(&terrain.region(&view, window)?.keys, u64::MAX);
    let Some(region) = region.first() else {
        return Ok(Vec::new());
    };
    let store = terrain.store();
    let finest = d.finest_level();
    let mut out = Vec::new();
    let mut stack = vec![(0u32, store.node(0)?)];
    while let Some((i, n)) = stack.pop() {
        let distance = terrain.node_box(&n).distance(view.eye);
        if view.screen_error(n.monotone_error, distance) <= tau || n.level >= finest {
            out.push(terrain.node_block(&view, i, &n));
            continue;
        }
        if n.subtree_len <= 1 {
            let q = ranges::Quadrant {
                level: n.level,
                x: n.x,
                y: n.y,
            };
            let (xs, ys) = q.blocks(&d);
            for y in ys {
                for x in xs.clone() {
                    let key = ranges::block_key(&d, x, y);
                    if region.meets(&KeyRange::single(key)) {
                        out.push(terrain.physical_block(
                            &view,
                            x,
                            y,
                            n.min_height,
                            n.max_height,
                        )?);
                    }
                }
            }
            continue;
        }
        for child in store.children(i, &n) {
            let (c, child) = child?;
            if region.meets(&KeyRange::of_node(child.key, child.level, finest)) {
                stack.push((c, child));
            }
        }
    }
    terrain.finish(&view, window, &mut out);
    Ok(out)
}
