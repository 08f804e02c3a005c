//! Meshes of scenes (`fmrh::mesh`, `fmrh mesh`) are crack-free and honest. Stitched meshes are
//! *conforming*: every triangle edge inside the meshed area is shared by exactly two
//! triangles (so no crack and no T-junction), a sample that is a vertex of several blocks has
//! one height in all of them, every block's triangles tile its footprint exactly once,
//! counter-clockwise from above, and every vertex is within the error of the coarsest block
//! holding it of the source. That holds on random terrain under random cameras, on Puget
//! Sound 1k, where a block meets one more than `log2(b-1)` levels coarser (its corners then
//! fall between the coarse block's vertices), and where blocks' grids are offset (tiles of a
//! dataset). Skirts hang at least as deep as the gap to the neighbour's surface along every
//! shared edge. The `.glb` that `fmrh mesh` writes holds those meshes: one node per scene
//! block with its level, key and error, positions in the documented axes. TIN meshes
//! (`build_tin_in`, `--max-error`) tile each block's footprint with triangles whose corners
//! are its grid points, are within their measured error (no more than the budget) of every
//! grid point, and hang skirts below the neighbouring TINs along every shared edge.

mod common;

use std::collections::{BTreeSet, HashMap};

use fmrh::mesh::{build, build_tin_in, BlockMesh, Cracks};
use fmrh::model::surface::surface;
use fmrh::model::{BuildOptions, SampleRect};
use fmrh::scene::surface::GridBlock;
use fmrh::scene::{
    load_blocks, LoadedBlock, Scene, SceneOptions, Terrain, TerrainFrame, WorldFrame, PAYLOAD_GAP,
};
use fmrh::store::Source;
use fmrh::store::Store;
use proptest::prelude::*;

use common::fields::{self, Rng};
use common::views;

/// A block's grid, owned.
struct Grid {
    rect: SampleRect,
    stride: u64,
    width: u32,
    height: u32,
    heights: Vec<f32>,
    error: f64,
}

impl Grid {
    fn block(&self) -> GridBlock<'_> {
        GridBlock {
            rect: self.rect,
            stride: self.stride,
            grid_width: self.width,
            grid_height: self.height,
            heights: &self.heights,
            error: self.error,
        }
    }

    /// The surface of `format-spec/model.md` §4 at a sample of the footprint.
    fn surface(&self, col: u64, row: u64) -> f64 {
        let (u, v, s) = (col - self.rect.col0, row - self.rect.row0, self.stride);
        let w = u64::from(self.width);
        let at = |i: u64, j: u64| self.heights[(j * w + i) as usize];
        if s == 1 {
            return f64::from(at(u, v));
        }
        let i = (u / s).min(w - 2);
        let j = (v / s).min(u64::from(self.height) - 2);
        surface(
            at(i, j),
            at(i + 1, j),
            at(i, j + 1),
            at(i + 1, j + 1),
            s,
            u - i * s,
            v - j * s,
        )
    }

    fn holds(&self, col: u64, row: u64) -> bool {
        self.rect.col0 <= col
            && col <= self.rect.col1
            && self.rect.row0 <= row
            && row <= self.rect.row1
    }
}

/// The grids of a scene's blocks, read from `store`.
fn grids_of<S: Source>(store: &Store<S>, scene: &Scene) -> Vec<Grid> {
    let loaded: Vec<LoadedBlock> = load_blocks(store, &scene.blocks, PAYLOAD_GAP).unwrap();
    let d = store.domain();
    scene
        .blocks
        .iter()
        .zip(loaded)
        .map(|(b, l)| Grid {
            rect: b.rect(),
            stride: d.stride(b.level),
            width: l.width,
            height: l.height,
            heights: l.heights.to_vec(),
            error: b.error,
        })
        .collect()
}

fn mesh(grids: &[Grid], cracks: Cracks) -> Vec<BlockMesh> {
    let blocks: Vec<GridBlock<'_>> = grids.iter().map(Grid::block).collect();
    build(&blocks, &WorldFrame::new(Some([10.0, 10.0])), cracks).unwrap()
}

/// Twice the signed area of a triangle in samples; negative when counter-clockwise seen
/// from above (rows grow southwards).
fn turn(a: (u64, u64), b: (u64, u64), c: (u64, u64)) -> i128 {
    let p = |q: (u64, u64)| (i128::from(q.0), i128::from(q.1));
    let (a, b, c) = (p(a), p(b), p(c));
    (b.0 - a.0) * (c.1 - a.1) - (b.1 - a.1) * (c.0 - a.0)
}

/// A sample, `(col, row)`.
type Sample = (u64, u64);

/// Checks that stitched `meshes` of `grids` are conforming and within their errors of
/// `source` (valid samples only). Returns how many blocks had an edge stitched.
fn check_stitched(
    grids: &[Grid],
    meshes: &[BlockMesh],
    source: &dyn Fn(u64, u64) -> Option<f64>,
) -> usize {
    let mut heights: HashMap<(u64, u64), u64> = HashMap::new();
    let mut edges: HashMap<(Sample, Sample), u32> = HashMap::new();
    for m in meshes {
        let g = &grids[m.block];
        let r = g.rect;
        let mut area: i128 = 0;
        for v in &m.vertices {
            assert!(!v.skirt, "a stitched mesh has no skirts");
            assert!(g.holds(v.col, v.row), "vertex {v:?} outside block {r:?}");
            let bits = v.height.to_bits();
            let seen = *heights.entry((v.col, v.row)).or_insert(bits);
            assert_eq!(
                seen,
                bits,
                "({}, {}) drawn at {} and at {}: a crack",
                v.col,
                v.row,
                f64::from_bits(seen),
                v.height
            );
            // Within the error of the coarsest blocks holding it.
            if let Some(h) = source(v.col, v.row) {
                let holders: Vec<&Grid> = grids.iter().filter(|o| o.holds(v.col, v.row)).collect();
                let coarsest = holders.iter().map(|o| o.stride).max().unwrap();
                let bound = holders
                    .iter()
                    .filter(|o| o.stride == coarsest)
                    .map(|o| o.error)
                    .fold(0.0, f64::max);
                assert!(
                    (v.height - h).abs() <= bound,
                    "({}, {}) at {} is {} from the source, past {bound}",
                    v.col,
                    v.row,
                    v.height,
                    (v.height - h).abs()
                );
            }
        }
        for t in &m.triangles {
            let p = t.map(|i| {
                let v = &m.vertices[i as usize];
                (v.col, v.row)
            });
            let a = turn(p[0], p[1], p[2]);
            assert!(
                a < 0,
                "triangle {p:?} of block {r:?} is not counter-clockwise from above"
            );
            area -= a;
            for k in 0..3 {
                let (x, y) = (p[k], p[(k + 1) % 3]);
                *edges.entry((x.min(y), x.max(y))).or_default() += 1;
            }
        }
        let want = 2 * i128::from((r.col1 - r.col0) as u32) * i128::from((r.row1 - r.row0) as u32);
        assert_eq!(area, want, "block {r:?}: its triangles do not tile it once");
    }
    for (&(a, b), &n) in &edges {
        assert!(n <= 2, "edge {a:?}-{b:?} has {n} triangles");
        if n == 1 {
            // A triangle edge with one side only must be on the outline of the meshed area:
            // no other block holds its midpoint.
            let mid = |g: &Grid| {
                let r = g.rect;
                2 * r.col0 <= a.0 + b.0
                    && a.0 + b.0 <= 2 * r.col1
                    && 2 * r.row0 <= a.1 + b.1
                    && a.1 + b.1 <= 2 * r.row1
            };
            let holders = grids
                .iter()
                .filter(|g| g.rect.col0 < g.rect.col1 && mid(g))
                .count();
            assert_eq!(
                holders, 1,
                "edge {a:?}-{b:?} is open inside the mesh: a crack or a T-junction"
            );
        }
    }
    meshes.iter().filter(|m| m.stitched.contains(&true)).count()
}

/// Checks that every skirt reaches below the neighbour's surface along the edge it hangs
/// from, at every sample (both surfaces and the skirt's foot are linear between samples).
fn check_skirts(grids: &[Grid], meshes: &[BlockMesh]) -> usize {
    let mut hung = 0;
    for m in meshes {
        let g = &grids[m.block];
        let mut top: HashMap<(u64, u64), f64> = HashMap::new();
        for v in m.vertices.iter().filter(|v| !v.skirt) {
            assert_eq!(
                v.height,
                g.surface(v.col, v.row),
                "skirts keep the block's surface"
            );
            top.insert((v.col, v.row), v.height);
        }
        let r = g.rect;
        for v in m.vertices.iter().filter(|v| v.skirt) {
            // A skirt vertex hangs below its edge by that edge's depth.
            let edges = [
                v.row == r.row0,
                v.col == r.col1,
                v.row == r.row1,
                v.col == r.col0,
            ];
            let d = top[&(v.col, v.row)] - v.height;
            assert!((0..4).any(|e| edges[e] && m.skirts[e] == d), "{v:?}");
        }
        hung += usize::from(m.skirts.iter().any(|&d| d > 0.0));
        for (o, other) in grids.iter().enumerate() {
            if o == m.block {
                continue;
            }
            let b = other.rect;
            // The shared piece of edge, if any (positive length), and which edge of `g`.
            let (c0, c1) = (r.col0.max(b.col0), r.col1.min(b.col1));
            let (r0, r1) = (r.row0.max(b.row0), r.row1.min(b.row1));
            let e = if c0 == c1 && r0 < r1 {
                if c0 == r.col1 {
                    1
                } else {
                    3
                }
            } else if r0 == r1 && c0 < c1 {
                if r0 == r.row0 {
                    0
                } else {
                    2
                }
            } else {
                continue;
            };
            let d = m.skirts[e];
            for col in c0..=c1 {
                for row in r0..=r1 {
                    let foot = g.surface(col, row) - d;
                    assert!(
                        foot <= other.surface(col, row),
                        "the skirt of {r:?} ends above {b:?} at ({col}, {row})"
                    );
                }
            }
        }
    }
    hung
}

fn tin(grids: &[Grid], budget: f64) -> Vec<BlockMesh> {
    let blocks: Vec<GridBlock<'_>> = grids.iter().map(Grid::block).collect();
    let frame = TerrainFrame::Flat(WorldFrame::new(Some([10.0, 10.0])));
    build_tin_in(&blocks, &frame, budget).unwrap()
}

/// The height a mesh's surface triangles draw at sample `(col, row)`, from the first
/// triangle holding it (closed); `None` where none does.
fn drawn(m: &BlockMesh, col: u64, row: u64) -> Option<f64> {
    let p = |i: u32| {
        let v = &m.vertices[i as usize];
        (i128::from(v.col), i128::from(v.row), v.height)
    };
    let (x, y) = (i128::from(col), i128::from(row));
    m.triangles
        .iter()
        .filter(|t| t.iter().all(|&i| !m.vertices[i as usize].skirt))
        .find_map(|t| {
            let [a, b, c] = t.map(p);
            let area = (b.0 - a.0) * (c.1 - a.1) - (b.1 - a.1) * (c.0 - a.0);
            let w = |o: (i128, i128, f64), q: (i128, i128, f64)| {
                (q.0 - o.0) * (y - o.1) - (q.1 - o.1) * (x - o.0)
            };
            let (wa, wb, wc) = (w(b, c), w(c, a), w(a, b));
            let inside = if area < 0 {
                wa <= 0 && wb <= 0 && wc <= 0
            } else {
                false
            };
            inside.then(|| (wa as f64 * a.2 + wb as f64 * b.2 + wc as f64 * c.2) / area as f64)
        })
}

/// Checks TIN `meshes` of `grids` cut within `budget`: corners on the grid at its heights,
/// triangles counter-clockwise from above tiling each footprint, every grid point within
/// the block's measured error (itself within the budget), and skirts reaching below the
/// neighbouring TIN at every sample of every shared edge. Returns the blocks with a skirt.
fn check_tins(grids: &[Grid], meshes: &[BlockMesh], budget: f64) -> usize {
    let mut hung = 0;
    for m in meshes {
        let g = &grids[m.block];
        let r = g.rect;
        assert!(m.tin_error <= budget, "{} > {budget}", m.tin_error);
        let mut area = 0i128;
        for t in m
            .triangles
            .iter()
            .filter(|t| t.iter().all(|&i| !m.vertices[i as usize].skirt))
        {
            let [a, b, c] = t.map(|i| (m.vertices[i as usize].col, m.vertices[i as usize].row));
            let turned = turn(a, b, c);
            assert!(
                turned < 0,
                "a triangle of {r:?} is not counter-clockwise from above"
            );
            area -= turned;
        }
        let footprint = i128::from(r.col1 - r.col0) * i128::from(r.row1 - r.row0) * 2;
        assert_eq!(area, footprint, "the triangles of {r:?} tile it");
        for v in m.vertices.iter().filter(|v| !v.skirt) {
            assert!(g.holds(v.col, v.row));
            assert_eq!(
                v.height,
                g.surface(v.col, v.row),
                "a corner off the grid's height"
            );
        }
        // Every grid point (and the footprint's far edges) against the TIN.
        let lattice = |lo: u64, hi: u64| {
            let mut out: Vec<u64> = (lo..=hi).step_by(g.stride as usize).collect();
            if out.last() != Some(&hi) {
                out.push(hi);
            }
            out
        };
        let mut worst = 0.0f64;
        for row in lattice(r.row0, r.row1) {
            for col in lattice(r.col0, r.col1) {
                let d = (drawn(m, col, row).expect("the TIN covers its grid")
                    - g.surface(col, row))
                .abs();
                worst = worst.max(d);
            }
        }
        assert!(
            worst <= m.tin_error + 1e-9 * (1.0 + worst),
            "{r:?}: {worst} past the measured {}",
            m.tin_error
        );
        hung += usize::from(m.skirts.iter().any(|&d| d > 0.0));
        for n in meshes.iter().filter(|n| n.block != m.block) {
            let b = grids[n.block].rect;
            let (c0, c1) = (r.col0.max(b.col0), r.col1.min(b.col1));
            let (r0, r1) = (r.row0.max(b.row0), r.row1.min(b.row1));
            let e = if c0 == c1 && r0 < r1 {
                if c0 == r.col1 {
                    1
                } else {
                    3
                }
            } else if r0 == r1 && c0 < c1 {
                if r0 == r.row0 {
                    0
                } else {
                    2
                }
            } else {
                continue;
            };
            for col in c0..=c1 {
                for row in r0..=r1 {
                    let (Some(top), Some(there)) = (drawn(m, col, row), drawn(n, col, row)) else {
                        panic!("({col}, {row}) on a shared edge is not drawn by both sides");
                    };
                    assert!(
                        top - m.skirts[e] <= there + 1e-9 * (1.0 + there.abs()),
                        "the skirt of {r:?} ends above the TIN of {b:?} at ({col}, {row})"
                    );
                }
            }
        }
    }
    hung
}

fn random_scene(
    side: u32,
    character: fields::Character,
    seed: u64,
    tau: f64,
) -> (views::Fixture, Scene) {
    let field = fields::make(side, side - side / 5, character, 0.02, seed);
    let f = views::fixture(
        field,
        &BuildOptions {
            block_size: 9,
            ..BuildOptions::default()
        },
    );
    let terrain = Terrain::with_spacing(&f.store, Some([10.0, 10.0])).unwrap();
    let camera = views::random_camera(&f.model, terrain.frame(), &mut Rng::new(seed));
    let scene = terrain.scene(&camera, &SceneOptions::new(tau)).unwrap();
    (f, scene)
}

fn source_of(hf: &fmrh::Heightfield) -> impl Fn(u64, u64) -> Option<f64> + '_ {
    move |col, row| {
        let v = hf.samples()[(row * u64::from(hf.width()) + col) as usize];
        v.is_finite().then_some(f64::from(v))
    }
}

proptest! {
    #![proptest_config(ProptestConfig { cases: 40, ..ProptestConfig::default() })]

    #[test]
    fn stitched_scene_meshes_are_conforming_and_within_their_errors(
        side in 20u32..220,
        character in fields::character(),
        seed in any::<u64>(),
        tau in 0.2f64..4.0,
    ) {
        let (f, scene) = random_scene(side, character, seed, tau);
        let grids = grids_of(&f.store, &scene);
        let meshes = mesh(&grids, Cracks::Stitch);
        check_stitched(&grids, &meshes, &source_of(&f.source));
    }

    #[test]
    fn skirts_reach_below_the_neighbours(
        side in 20u32..160,
        character in fields::character(),
        seed in any::<u64>(),
        tau in 0.2f64..4.0,
    ) {
        let (f, scene) = random_scene(side, character, seed, tau);
        let grids = grids_of(&f.store, &scene);
        let meshes = mesh(&grids, Cracks::Skirts);
        check_skirts(&grids, &meshes);
    }

    #[test]
    fn tins_are_within_their_budget_and_skirted_against_their_neighbours(
        side in 20u32..160,
        character in fields::character(),
        seed in any::<u64>(),
        tau in 0.2f64..4.0,
        budget in prop_oneof![Just(0.0), 0.0f64..50.0],
    ) {
        let (f, scene) = random_scene(side, character, seed, tau);
        let grids = grids_of(&f.store, &scene);
        let meshes = tin(&grids, budget);
        check_tins(&grids, &meshes, budget);
    }
}

/// Puget Sound 1k under the README's camera: levels 2 to 4 meet, and the stitched mesh is
/// conforming; without stitching (each block its own grid) it is not.
#[test]
fn puget_sound_meshes_stitch_where_levels_meet() {
    let f = views::fixture(views::puget_1k(), &BuildOptions::default());
    let terrain = Terrain::new(&f.store).unwrap();
    let camera = fmrh::scene::Camera {
        fov_y_deg: 55.0,
        viewport: [640, 360],
        ..fmrh::scene::Camera::looking_at(
            glam::DVec3::new(60000.0, 175000.0, 9000.0),
            glam::DVec3::new(80000.0, 90000.0, 0.0),
        )
    };
    let scene = terrain.scene(&camera, &SceneOptions::new(1.0)).unwrap();
    let levels: std::collections::BTreeSet<u8> = scene.blocks.iter().map(|b| b.level).collect();
    assert!(levels.len() >= 3, "levels {levels:?}");
    let grids = grids_of(&f.store, &scene);
    let meshes = mesh(&grids, Cracks::Stitch);
    let stitched = check_stitched(&grids, &meshes, &source_of(&f.source));
    assert!(stitched >= 10, "{stitched} blocks stitched");
    // The same blocks meshed on their own grids (the skirts' surfaces, skirts left out)
    // leave T-junctions where levels meet: the check above sees them.
    let mut plain = mesh(&grids, Cracks::Skirts);
    for m in &mut plain {
        let n = m.vertices.iter().filter(|v| !v.skirt).count() as u32;
        m.vertices.truncate(n as usize);
        m.triangles.retain(|t| t.iter().all(|&i| i < n));
    }
    let failed = std::panic::catch_unwind(|| check_stitched(&grids, &plain, &|_, _| None));
    assert!(failed.is_err(), "unstitched meshes passed the crack check");
    assert!(check_skirts(&grids, &mesh(&grids, Cracks::Skirts)) >= 10);
}

/// Puget Sound 1k under the same camera as TINs: fewer triangles the larger the budget,
/// each block within it, and skirts where the TINs of neighbours part.
#[test]
fn puget_sound_tins_shrink_with_their_budget() {
    let f = views::fixture(views::puget_1k(), &BuildOptions::default());
    let terrain = Terrain::new(&f.store).unwrap();
    let camera = fmrh::scene::Camera {
        fov_y_deg: 55.0,
        viewport: [640, 360],
        ..fmrh::scene::Camera::looking_at(
            glam::DVec3::new(60000.0, 175000.0, 9000.0),
            glam::DVec3::new(80000.0, 90000.0, 0.0),
        )
    };
    let scene = terrain.scene(&camera, &SceneOptions::new(1.0)).unwrap();
    let grids = grids_of(&f.store, &scene);
    let count = |m: &[BlockMesh]| -> usize {
        m.iter()
            .map(|b| {
                b.triangles
                    .iter()
                    .filter(|t| t.iter().all(|&i| !b.vertices[i as usize].skirt))
                    .count()
            })
            .sum()
    };
    let full = count(&mesh(&grids, Cracks::Skirts));
    let mut last = usize::MAX;
    for budget in [0.0, 1.0, 5.0, 20.0] {
        let meshes = tin(&grids, budget);
        let hung = check_tins(&grids, &meshes, budget);
        let n = count(&meshes);
        assert!(
            n <= full && n < last,
            "{budget} m: {n} triangles (grid {full}, before {last})"
        );
        if budget > 0.0 {
            assert!(hung >= 10, "{budget} m: {hung} blocks skirted");
        }
        last = n;
    }
    // Measured: 20 m keeps 54 % of this view's triangles (its blocks are already decimated
    // to about a pixel, and the Cascades are steep); a quarter saved is the floor.
    assert!(last * 4 < full * 3, "20 m keeps {last} of {full} triangles");
    assert!(build_tin_in(&[], &TerrainFrame::Flat(WorldFrame::new(None)), f64::NAN).is_err());
}

fn rect(col0: u64, row0: u64, col1: u64, row1: u64) -> SampleRect {
    SampleRect {
        col0,
        row0,
        col1,
        row1,
    }
}

/// A random grid of `w × h` points.
fn random_grid(rect: SampleRect, stride: u64, w: u32, h: u32, rng: &mut Rng) -> Grid {
    Grid {
        rect,
        stride,
        width: w,
        height: h,
        heights: (0..w * h).map(|_| (rng.unit() * 100.0) as f32).collect(),
        error: 0.0,
    }
}

/// A block of stride 16 meets sixteen blocks of stride 1 (four levels finer, past
/// `log2(b-1) = 3` for 9-sample grids) along its east edge: their corners fall between its
/// vertices, so it takes them as vertices of its own, and every shared point has one height.
#[test]
fn a_block_many_levels_coarser_takes_its_neighbours_corners() {
    let mut rng = Rng::new(7);
    let mut grids = vec![random_grid(rect(0, 0, 128, 128), 16, 9, 9, &mut rng)];
    grids[0].error = 100.0;
    for k in 0..16 {
        grids.push(random_grid(
            rect(128, 8 * k, 136, 8 * k + 8),
            1,
            9,
            9,
            &mut rng,
        ));
    }
    let meshes = mesh(&grids, Cracks::Stitch);
    check_stitched(&grids, &meshes, &|_, _| None);
    let coarse = &meshes[0];
    assert!(coarse.stitched[1] && !coarse.stitched[0]);
    let east: Vec<u64> = coarse
        .vertices
        .iter()
        .filter(|v| v.col == 128)
        .map(|v| v.row)
        .collect();
    assert_eq!(
        east.len(),
        17,
        "every fine corner is a vertex of the coarse edge: {east:?}"
    );
    // A fine corner between coarse vertices lies on the coarse edge's line.
    let v = coarse
        .vertices
        .iter()
        .find(|v| (v.col, v.row) == (128, 8))
        .unwrap();
    assert_eq!(v.height, grids[0].surface(128, 8));
    // Skirts close the same gaps.
    check_skirts(&grids, &mesh(&grids, Cracks::Skirts));
}

/// Tiles whose grids are offset (a dataset's tiles need not align): two blocks of the same
/// stride meet along a piece of edge where their grid points differ. The first given
/// gives the vertices; the other takes them.
#[test]
fn blocks_with_offset_grids_meet_without_cracks() {
    let mut rng = Rng::new(11);
    let grids = vec![
        random_grid(rect(0, 0, 32, 32), 4, 9, 9, &mut rng),
        random_grid(rect(32, 2, 64, 34), 4, 9, 9, &mut rng),
        // A physical block south of the first, a data edge clipping it at column 30.
        random_grid(rect(0, 32, 30, 40), 1, 31, 9, &mut rng),
    ];
    let meshes = mesh(&grids, Cracks::Stitch);
    check_stitched(&grids, &meshes, &|_, _| None);
    // The second takes the first one's grid points along the shared piece; the first takes
    // the second's corner at row 2.
    let rows = |m: &BlockMesh, col: u64| -> Vec<u64> {
        let mut r: Vec<u64> = m
            .vertices
            .iter()
            .filter(|v| v.col == col)
            .map(|v| v.row)
            .collect();
        r.sort_unstable();
        r
    };
    let mut want: Vec<u64> = vec![0, 2];
    want.extend((1..=8).map(|k| 4 * k));
    assert_eq!(rows(&meshes[0], 32), want);
    want.remove(0);
    want.push(34);
    assert_eq!(rows(&meshes[1], 32), want);
    assert!(meshes[0].stitched[1] && meshes[1].stitched[3]);
}

/// Regression (found by the property test above): a coarse block clipped by the data's
/// east edge to less than one cell is one cell thick, and its long west side takes the
/// corners of the finer blocks along it. Clipping ears must not leave a side along those
/// corners (it left them as T-junctions).
#[test]
fn a_thin_block_with_many_corners_on_its_side_is_cut_without_t_junctions() {
    let (f, scene) = random_scene(138, fields::Character::Cliff, 18305275996682265738, 0.2);
    let grids = grids_of(&f.store, &scene);
    let thin = grids
        .iter()
        .position(|g| g.rect.col0 == 128 && g.rect.col1 == 137 && g.stride == 16)
        .expect("the scene has the thin block");
    let meshes = mesh(&grids, Cracks::Stitch);
    check_stitched(&grids, &meshes, &source_of(&f.source));
    let m = meshes.iter().find(|m| m.block == thin).unwrap();
    assert!(m.stitched[3]);
    assert!(m.vertices.iter().filter(|v| v.col == 128).count() > 8);
}

/// A dataset's tiles are cut at arbitrary samples, so blocks on either side of a tile
/// border have grids offset from each other and levels on different scales: the stitched
/// mesh across the tiles is conforming all the same, and within its errors.
#[test]
fn dataset_meshes_are_conforming_across_tiles() {
    let dir = tempfile::tempdir().unwrap();
    let field = fields::make(150, 120, fields::Character::Hills, 0.01, 5);
    let rects = common::tiles::split(&field, &[37, 90], &[53], &[4]);
    let ds_dir = common::tiles::build(dir.path(), &field, &rects, &common::tiles::options(None));
    let ds = fmrh::dataset::Dataset::open(&ds_dir).unwrap();
    let camera = fmrh::scene::Camera::looking_at(
        glam::DVec3::new(-200.0, 1400.0, 300.0),
        glam::DVec3::new(800.0, 500.0, 0.0),
    );
    let scene = ds.scene(&camera, &SceneOptions::new(4.0), None).unwrap();
    let tiles: std::collections::BTreeSet<u64> = scene.blocks.iter().map(|b| b.tile).collect();
    assert!(tiles.len() >= 4, "the view meets tiles {tiles:?}");
    let grids: Vec<Grid> = ds
        .load_blocks(&scene)
        .unwrap()
        .into_iter()
        .zip(&scene.blocks)
        .map(|((l, stride), b)| Grid {
            rect: b.block.rect(),
            stride,
            width: l.width,
            height: l.height,
            heights: l.heights.to_vec(),
            error: b.block.error,
        })
        .collect();
    let meshes = mesh(&grids, Cracks::Stitch);
    let stitched = check_stitched(&grids, &meshes, &source_of(&field));
    let strides: std::collections::BTreeSet<u64> = grids.iter().map(|g| g.stride).collect();
    assert!(stitched > 0, "strides {strides:?}, {} blocks", grids.len());
    check_skirts(&grids, &mesh(&grids, Cracks::Skirts));
}

mod fractal {
    //! Detail past the data (`fmrh::mesh::fractal`): refinement is deterministic (the same
    //! key gives the same heights, another key others), keeps every stored sample exactly,
    //! stays within its declared errors (a depth's surface is within its error of every
    //! deeper one), halves the error with each depth, and meshes without cracks beside real
    //! blocks and between depths.

    use super::*;
    use fmrh::mesh::fractal::{self, Physical, Synthetic, MAX_DEPTH, SCALE};

    fn block(seed: u64, b: u32) -> (Vec<f32>, SampleRect) {
        let mut rng = Rng::new(seed);
        let heights = (0..b * b).map(|_| (rng.unit() * 50.0) as f32).collect();
        let side = u64::from(b - 1) * SCALE;
        (heights, rect(3 * side, 5 * side, 4 * side, 6 * side))
    }

    /// Every node `depth` below the block (all of them split down to it).
    fn at_depth(p: &Physical<'_>, a: f64, depth: u8) -> Vec<Synthetic> {
        fractal::refine(p, a, &mut |d, _, _, _, _| d < depth)
    }

    /// The surface of the synthetic nodes at scaled point `(x, y)`.
    fn surface_at(nodes: &[Synthetic], b: u32, x: u64, y: u64) -> f64 {
        let n = nodes
            .iter()
            .find(|n| n.rect.col0 <= x && x <= n.rect.col1 && n.rect.row0 <= y && y <= n.rect.row1)
            .unwrap();
        Grid {
            rect: n.rect,
            stride: n.stride,
            width: b,
            height: b,
            heights: n.heights.clone(),
            error: n.error,
        }
        .surface(x, y)
    }

    proptest! {
        #![proptest_config(ProptestConfig { cases: 24, ..ProptestConfig::default() })]

        #[test]
        fn refinement_is_deterministic_exact_on_the_data_and_within_its_errors(
            seed in any::<u64>(),
            key in any::<u64>(),
            k in 0u8..MAX_DEPTH,
            b in prop_oneof![Just(9u32), Just(17)],
        ) {
            let (heights, r) = block(seed, b);
            let p = Physical { key, rect: r, side: b, heights: &heights };
            let a = fractal::roughness(&heights, b as usize, b as usize);
            prop_assert!(a > 0.0);
            let deep = at_depth(&p, a, MAX_DEPTH);
            prop_assert_eq!(deep.len(), 1 << (2 * MAX_DEPTH));
            // Deterministic; another key, other heights.
            prop_assert_eq!(&deep, &at_depth(&p, a, MAX_DEPTH));
            let other = Physical { key: key ^ 1, ..p };
            prop_assert_ne!(&deep, &at_depth(&other, a, MAX_DEPTH));
            let peak = heights.iter().fold(0.0f64, |m, &h| m.max(f64::from(h).abs()));
            let slack = fractal::declared_error(0.0, 0, peak);
            let physical = Grid { rect: r, stride: SCALE, width: b, height: b, heights: heights.clone(), error: 0.0 };
            for n in &deep {
                prop_assert_eq!(n.error, fractal::declared_error(a, MAX_DEPTH, peak));
                for j in 0..b as u64 {
                    for i in 0..b as u64 {
                        let (x, y) = (n.rect.col0 + i * n.stride, n.rect.row0 + j * n.stride);
                        let h = n.heights[(j * u64::from(b) + i) as usize];
                        // A stored sample keeps its height exactly.
                        if (x - r.col0) % SCALE == 0 && (y - r.row0) % SCALE == 0 {
                            let (c, rw) = ((x - r.col0) / SCALE, (y - r.row0) / SCALE);
                            prop_assert_eq!(h, heights[(rw * u64::from(b) + c) as usize]);
                        }
                        // The physical block's edges stay straight between its samples, as
                        // its real neighbours draw them (up to the rounding of each depth).
                        if x == r.col0 || x == r.col1 || y == r.row0 || y == r.row1 {
                            let edge = physical.surface(x, y);
                            prop_assert!((f64::from(h) - edge).abs() <= slack, "edge point ({}, {})", x, y);
                        }
                    }
                }
            }
            // Depth k's surface is within its declared error of the deepest one.
            let coarse = if k == 0 {
                vec![Synthetic {
                    depth: 0, x: 0, y: 0, rect: r, stride: SCALE,
                    heights: heights.clone(),
                    error: fractal::declared_error(a, 0, peak),
                }]
            } else {
                at_depth(&p, a, k)
            };
            let e_k = coarse[0].error;
            for n in &deep {
                for j in 0..b as u64 {
                    for i in 0..b as u64 {
                        let (x, y) = (n.rect.col0 + i * n.stride, n.rect.row0 + j * n.stride);
                        let h = f64::from(n.heights[(j * u64::from(b) + i) as usize]);
                        let s = surface_at(&coarse, b, x, y);
                        prop_assert!((h - s).abs() <= e_k, "depth {}: {} from the deepest, past {}", k, (h - s).abs(), e_k);
                    }
                }
            }
        }
    }

    #[test]
    fn each_depth_declares_half_the_error_of_the_one_above() {
        let a = 3.0;
        for d in 0..MAX_DEPTH {
            let slack = fractal::declared_error(0.0, d, 100.0);
            let (e, child) = (
                fractal::declared_error(a, d, 100.0),
                fractal::declared_error(a, d + 1, 100.0),
            );
            assert_eq!(child - slack, (e - slack) / 2.0);
        }
        assert_eq!(
            fractal::roughness(&[7.0; 81], 9, 9),
            0.0,
            "flat ground has no detail to add"
        );
    }

    /// A scene of Puget Sound 1k seen from close above: its physical blocks near the eye are
    /// refined to several depths, and the stitched mesh of real and synthetic blocks is
    /// conforming, with every stored sample within its block's error.
    #[test]
    fn refined_scenes_mesh_without_cracks_beside_real_blocks() {
        let f = views::fixture(views::puget_1k(), &BuildOptions::default());
        let terrain = Terrain::new(&f.store).unwrap();
        let camera = fmrh::scene::Camera::looking_at(
            glam::DVec3::new(80000.0, 92000.0, 1500.0),
            glam::DVec3::new(80000.0, 88000.0, 0.0),
        );
        let view = camera.view().unwrap();
        let scene = terrain.scene(&camera, &SceneOptions::new(1.0)).unwrap();
        let frame = terrain.frame();
        let mut grids = Vec::new();
        let mut depths = BTreeSet::new();
        for mut g in grids_of(&f.store, &scene) {
            let s = |v: u64| v * SCALE;
            g.rect = rect(
                s(g.rect.col0),
                s(g.rect.row0),
                s(g.rect.col1),
                s(g.rect.row1),
            );
            g.stride *= SCALE;
            if g.stride == SCALE && g.width == 65 && g.height == 65 {
                let a = fractal::roughness(&g.heights, 65, 65);
                let key = (g.rect.col0 * 31) ^ g.rect.row0;
                let p = Physical {
                    key,
                    rect: g.rect,
                    side: 65,
                    heights: &g.heights,
                };
                let nodes = fractal::refine_for_view(&p, a, &view, &frame, 1.0);
                if !nodes.is_empty() {
                    for n in nodes {
                        depths.insert(n.depth);
                        grids.push(Grid {
                            rect: n.rect,
                            stride: n.stride,
                            width: 65,
                            height: 65,
                            heights: n.heights,
                            error: g.error,
                        });
                    }
                    continue;
                }
            }
            grids.push(g);
        }
        assert!(depths.len() >= 2, "depths {depths:?}");
        let blocks: Vec<GridBlock<'_>> = grids.iter().map(Grid::block).collect();
        let scaled = WorldFrame {
            dx: frame.dx / SCALE as f64,
            dy: frame.dy / SCALE as f64,
        };
        let meshes = build(&blocks, &scaled, Cracks::Stitch).unwrap();
        let source = source_of(&f.source);
        let stitched = check_stitched(&grids, &meshes, &|x, y| {
            (x % SCALE == 0 && y % SCALE == 0)
                .then(|| source(x / SCALE, y / SCALE))
                .flatten()
        });
        assert!(stitched > 0);
    }

    /// `refine_block` refines only a whole physical block with no void: the same samples
    /// with one void, at a stride of 2, cut by the data's edge (narrower than tall), or
    /// smaller than 9 × 9 are drawn as stored, and flat ground is never refined.
    #[test]
    fn only_whole_void_free_physical_blocks_are_refined() {
        let b = 17u32;
        let (heights, _) = block(7, b);
        let camera = fmrh::scene::Camera::looking_at(
            glam::DVec3::new(8.0, 30.0, 5.0),
            glam::DVec3::new(8.0, 8.0, 0.0),
        );
        let view = camera.view().unwrap();
        let frame = WorldFrame::new(Some([1.0, 1.0]));
        let whole = rect(0, 0, 16, 16);
        let refine = |rect: SampleRect, stride: u64, w: u32, h: u32, hs: &[f32]| {
            let g = GridBlock {
                rect,
                stride,
                grid_width: w,
                grid_height: h,
                heights: hs,
                error: 0.0,
            };
            fractal::refine_block(99, &g, &view, &frame, 1.0)
        };
        let nodes = refine(whole, 1, b, b, &heights);
        assert!(!nodes.is_empty(), "the whole block is refined");
        for n in &nodes {
            assert!(n.heights.iter().all(|h| h.is_finite()));
        }
        // At the north-west corner, which roughness does not read (no inner sample has it as
        // a neighbour): only the void rule keeps the block as stored.
        let mut void = heights.clone();
        void[0] = f32::NAN;
        assert!(refine(whole, 1, b, b, &void).is_empty(), "a void");
        assert!(
            refine(rect(0, 0, 32, 32), 2, b, b, &heights).is_empty(),
            "stride 2"
        );
        let cut = &heights[..(b * (b - 1)) as usize];
        assert!(
            refine(rect(0, 0, 16, 15), 1, b, b - 1, cut).is_empty(),
            "cut"
        );
        let small: Vec<f32> = heights[..64].to_vec();
        assert!(
            refine(rect(0, 0, 7, 7), 1, 8, 8, &small).is_empty(),
            "8 x 8"
        );
        let flat = vec![42.0f32; heights.len()];
        assert!(refine(whole, 1, b, b, &flat).is_empty(), "flat ground");
    }
}
