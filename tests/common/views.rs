//! Scene fixtures and the brute-force oracle of the ideal view-dependent cut.
//!
//! The oracle looks at every node of the model's tree, with no traversal, no cluster and no
//! index: a node belongs to the ideal cut when it meets the tolerance where it is seen, its
//! parent does not, and its box meets the frustum (exact separating-axis test). It shares only
//! the camera geometry (`View`) with the code under test.

use std::io::Cursor;

use fmrh::heightfield::Heightfield;
use fmrh::model::{BuildOptions, Model, SampleRect};
use fmrh::scene::{Aabb, View, WorldFrame};
use fmrh::store::Store;
use fmrh::store::{write_to, Bytes, WriteOptions};

use super::fields::Rng;

/// A model, its container in memory, and the source it came from.
pub struct Fixture {
    pub source: Heightfield,
    pub model: Model,
    pub store: Store<Bytes<Vec<u8>>>,
}

/// Builds `source` with `options` into an in-memory container.
pub fn fixture(source: Heightfield, options: &BuildOptions) -> Fixture {
    fixture_written(source, options, &WriteOptions::default())
}

/// [`fixture`], written with `write` (for example with every table in pages of its own).
#[allow(dead_code)]
pub fn fixture_written(
    source: Heightfield,
    options: &BuildOptions,
    write: &WriteOptions,
) -> Fixture {
    let model = Model::build(source.clone(), options).expect("model builds");
    let mut bytes = Cursor::new(Vec::new());
    write_to(&model, &source.metadata, write, &mut bytes).expect("writes");
    let store = Store::from_bytes(bytes.into_inner()).expect("opens");
    Fixture {
        source,
        model,
        store,
    }
}

/// Puget Sound 1k from the shared data, at its documented 160 m spacing.
pub fn puget_1k() -> Heightfield {
    // The bundled 16-bit PNG at 0.1 m: bit for bit the shared `.f32` (the large-data suite's
    // ingest tests check that).
    let path = super::data("puget-sound-1k/ps_height_1k.png");
    let options = fmrh::ingest::IngestOptions {
        z_scale: 0.1,
        ..Default::default()
    };
    let mut hf = fmrh::ingest::load(&path, &options).expect("Puget 1k loads");
    hf.metadata.spacing_m = Some([160.0, 160.0]);
    hf
}

/// The box of a node: footprint clipped to the data, by its height range.
pub fn node_box(
    model: &Model,
    frame: WorldFrame,
    level: u8,
    x: u32,
    y: u32,
    zmin: f32,
    zmax: f32,
) -> Aabb {
    let d = model.domain();
    let fp = d.footprint(level, x, y);
    let data = d.data_rect();
    Aabb {
        min: frame.point(fp.col0 as f64, fp.row0 as f64, f64::from(zmin)),
        max: frame.point(
            fp.col1.min(data.col1) as f64,
            fp.row1.min(data.row1) as f64,
            f64::from(zmax),
        ),
    }
}

/// The ideal view-dependent cut by brute force: node indexes, ascending.
pub fn ideal_cut(model: &Model, frame: WorldFrame, view: &View, tau: f64) -> Vec<u32> {
    let tree = model.tree();
    let rho = |i: u32| {
        let n = tree.node(i);
        let b = node_box(model, frame, n.level, n.x, n.y, n.min_height, n.max_height);
        view.screen_error(n.monotone_error, b.distance(view.eye))
    };
    (0..tree.nodes().len() as u32)
        .filter(|&i| {
            let n = tree.node(i);
            let parent_fails = n.parent == fmrh::model::NO_PARENT || rho(n.parent) > tau;
            let b = node_box(model, frame, n.level, n.x, n.y, n.min_height, n.max_height);
            rho(i) <= tau && parent_fails && view.intersects(&b)
        })
        .collect()
}

/// A random camera over the terrain: the eye anywhere from below the lowest point to high
/// above, up to a fifth of the extent beyond the edges; the target a random point of the
/// terrain's box.
pub fn random_camera(model: &Model, frame: WorldFrame, rng: &mut Rng) -> fmrh::scene::Camera {
    let d = model.domain();
    let root = &model.tree().nodes()[0];
    let (zmin, zmax) = (f64::from(root.min_height), f64::from(root.max_height));
    let (w, h) = (
        f64::from(d.width() - 1) * frame.dx,
        f64::from(d.height() - 1) * frame.dy,
    );
    let extent = w.max(h).max(1.0);
    let mut pick = |lo: f64, hi: f64| lo + (hi - lo) * rng.unit();
    let eye = glam::DVec3::new(
        pick(-0.2 * w, 1.2 * w),
        pick(-0.2 * h, 1.2 * h),
        pick(zmin - 0.05 * extent, zmax + extent),
    );
    let target = glam::DVec3::new(pick(0.0, w), pick(0.0, h), pick(zmin, zmax));
    let mut cam = fmrh::scene::Camera::looking_at(eye, target);
    cam.fov_y_deg = pick(10.0, 120.0);
    cam
}

/// Node indexes of a scene's blocks (all must be tree nodes).
pub fn node_indexes(blocks: &[fmrh::scene::SceneBlock]) -> Vec<u32> {
    let mut v: Vec<u32> = blocks
        .iter()
        .map(|b| b.node.expect("a tree node"))
        .collect();
    v.sort_unstable();
    v
}

/// Checks that `blocks` (sorted by key) are disjoint and that their key ranges hold every
/// finest block of `window` and no block outside it.
pub fn assert_window_cover(model: &Model, blocks: &[fmrh::scene::SceneBlock], window: &SampleRect) {
    let d = model.domain();
    let [x0, y0, x1, y1] = fmrh::scene::ranges::window_blocks(d, window);
    let keys: Vec<_> = blocks.iter().map(|b| b.keys(d)).collect();
    for pair in keys.windows(2) {
        assert!(pair[0].hi < pair[1].lo, "blocks overlap: {pair:?}");
    }
    let finest = d.finest_level();
    for y in y0..=y1 {
        for x in x0..=x1 {
            let k = fmrh::curve::hilbert_encode(u32::from(finest), x, y);
            let i = keys.partition_point(|r| r.lo <= k);
            assert!(
                i > 0 && keys[i - 1].hi >= k,
                "finest block ({x}, {y}) of the window is not covered"
            );
        }
    }
    for b in blocks {
        let shift = finest - b.level;
        let (bx0, by0) = (b.x << shift, b.y << shift);
        let (bx1, by1) = (((b.x + 1) << shift) - 1, ((b.y + 1) << shift) - 1);
        assert!(
            bx0 <= x1 && bx1 >= x0 && by0 <= y1 && by1 >= y0,
            "block {b:?} lies outside the window"
        );
    }
}
