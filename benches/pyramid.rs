//! What storing the tree as a *pyramid* would save: a measurement for the next format step
//! (issue 15), not a format. Today every coarse grid and every physical block is coded on
//! its own (a planar predictor within the payload, `fmrh::codec`), so the samples a node
//! shares with its parent are stored twice, and the grids add about a third more samples
//! than the data holds. In a pyramid each node would code only the samples its parent does
//! not hold, predicted from the parent's grid; a sample is then stored once, at the coarsest
//! node that holds it, and drawing a node needs its ancestors' grids.
//!
//! For every node of the real model (the grids of the nodes above the finest level, and
//! every physical block, whose parent is its nearest ancestor in the pruned tree) this
//! codes, with the same pco back end as the codec:
//!
//! * **today**: the payload the codec writes (`codec::encode`, grids and blocks);
//! * **bilinear**: the samples not on the parent's lattice, as residuals against the
//!   bilinear interpolation of the parent's samples around them;
//! * **cubic**: the same against a 4-point (−1, 9, 9, −1)/16 interpolation along rows, then
//!   columns, where the parent has the neighbours (bilinear otherwise);
//! * **within payloads**: no parent, each payload coded coarse to fine within itself with
//!   the same cubic interpolation (its corners, then every stride down to 1). This asks
//!   whether the gain is the predictor or the samples no longer stored twice.
//!
//! DEMs whose heights all lie on a lattice step (`codec::LATTICE_STEPS`: SRTM integers,
//! Puget Sound's 0.1 m) are coded as lattice indexes, the others in the order-preserving
//! `u32` map of their `f32` bits. Voids are left out of the residuals (a
//! bitmap bit each). Every residual stream is decoded back and checked before it counts.
//!
//!     cargo bench --bench pyramid          (needs ../shared/data; PYRAMID_SCENES=1 adds
//!                                           the per-scene estimate)

use std::path::PathBuf;

#[path = "common/dems.rs"]
mod dems;

use fmrh::codec;
use fmrh::ingest::{load, IngestOptions};
use fmrh::model::{BuildOptions, Model, NO_PARENT};
use pco::standalone::{simple_compress, simple_decompress};
use pco::{ChunkConfig, DeltaSpec};

fn data(rel: &str) -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR"))
        .join("../shared/data")
        .join(rel)
}

/// A node's samples: the columns and rows it holds (clamped to the data, as format §7's
/// coarse grids), and whether it is a physical block (voids as NaN) or a grid (mended).
struct Samples {
    cols: Vec<u64>,
    rows: Vec<u64>,
}

fn grid_samples(model: &Model, level: u8, x: u32, y: u32) -> Samples {
    let d = model.domain();
    let fp = d.footprint(level, x, y);
    let s = d.stride(level);
    let (gw, gh) = d.grid_dims(level, x, y);
    let data = d.data_rect();
    Samples {
        cols: (0..u64::from(gw))
            .map(|i| (fp.col0 + i * s).min(data.col1))
            .collect(),
        rows: (0..u64::from(gh))
            .map(|j| (fp.row0 + j * s).min(data.row1))
            .collect(),
    }
}

fn block_samples(model: &Model, x: u32, y: u32) -> Samples {
    let d = model.domain();
    let r = d
        .footprint(d.finest_level(), x, y)
        .intersect(&d.data_rect())
        .unwrap_or_default();
    Samples {
        cols: (r.col0..=r.col1).collect(),
        rows: (r.row0..=r.row1).collect(),
    }
}

/// How a height becomes the integer that is coded: its index on the lattice of step `q`,
/// or its order-preserving bits.
#[derive(Clone, Copy)]
enum Space {
    Lattice(f64),
    Float,
}

impl Space {
    fn of(v: f32, space: Space) -> i64 {
        match space {
            Space::Lattice(q) => (f64::from(v) / q).round() as i64,
            Space::Float => {
                let b = v.to_bits();
                i64::from(if b & 0x8000_0000 != 0 {
                    !b
                } else {
                    b | 0x8000_0000
                })
            }
        }
    }
}

/// The interpolation of `xs` (ascending parent coordinates) at `x`: the indexes of the
/// parent samples it uses and their weights.
fn weights(xs: &[u64], x: u64, cubic: bool) -> Vec<(usize, f64)> {
    let hi = xs.partition_point(|&p| p < x).min(xs.len() - 1);
    if xs[hi] == x {
        return vec![(hi, 1.0)];
    }
    let lo = hi - 1;
    let t = (x - xs[lo]) as f64 / (xs[hi] - xs[lo]) as f64;
    let evenly = |a: usize, b: usize| xs[b] - xs[a] == xs[hi] - xs[lo];
    if cubic
        && (t - 0.5).abs() < 1e-12
        && lo >= 1
        && hi + 1 < xs.len()
        && evenly(lo - 1, lo)
        && evenly(hi, hi + 1)
    {
        return vec![
            (lo - 1, -1.0 / 16.0),
            (lo, 9.0 / 16.0),
            (hi, 9.0 / 16.0),
            (hi + 1, -1.0 / 16.0),
        ];
    }
    vec![(lo, 1.0 - t), (hi, t)]
}

/// Residuals of the samples of `child` not held by `parent`, predicted from the parent's
/// values (`pv`, row-major over its columns and rows, mended). Voids of a block are skipped.
fn residuals(
    child: &Samples,
    cv: &[f32],
    parent: &Samples,
    pv: &[f32],
    space: Space,
    cubic: bool,
) -> (Vec<i64>, usize) {
    let pw = parent.cols.len();
    let mut out = Vec::new();
    let mut voids = 0;
    for (j, &row) in child.rows.iter().enumerate() {
        let wy = weights(&parent.rows, row, cubic);
        for (i, &col) in child.cols.iter().enumerate() {
            let v = cv[j * child.cols.len() + i];
            if v.is_nan() {
                voids += 1;
                continue;
            }
            let wx = weights(&parent.cols, col, cubic);
            if wx.len() == 1 && wy.len() == 1 {
                continue; // the parent holds it
            }
            let mut p = 0.0f64;
            for &(yi, a) in &wy {
                for &(xi, b) in &wx {
                    p += a * b * f64::from(pv[yi * pw + xi]);
                }
            }
            let pred = match space {
                Space::Lattice(q) => (p / q).round() as i64,
                Space::Float => Space::of(p as f32, space),
            };
            out.push(Space::of(v, space).wrapping_sub(pred));
        }
    }
    (out, voids)
}

/// Bytes of a pco stream of `r` (plus a void bitmap when there are voids), checked by
/// decoding it.
fn coded_len(r: &[i64], n_samples: usize, voids: usize) -> usize {
    let bitmap = if voids > 0 { n_samples.div_ceil(8) } else { 0 };
    if r.is_empty() {
        return 1 + bitmap;
    }
    if r.iter().all(|&x| x == r[0]) {
        return 9 + bitmap;
    }
    let config = ChunkConfig::default().with_delta_spec(DeltaSpec::NoOp);
    let c = simple_compress(r, &config).expect("pco compresses");
    let back: Vec<i64> = simple_decompress(&c).expect("pco decompresses");
    assert_eq!(back, r, "a residual stream did not round-trip");
    // The payload's own header: an encoding byte and a length, as today's.
    c.len() + 5 + bitmap
}

/// Residuals of one payload on its own, coded coarse to fine *within* it: the corners
/// first, then at each stride `s` (a power of two, halving down to 1) the new columns of
/// the rows already known, each predicted by interpolating its row, then the new rows,
/// each predicted by interpolating its column (an interpolating wavelet, separable).
/// The last row and column belong to every stride. Voids are predicted through.
fn hierarchical(v: &[f32], w: usize, h: usize, space: Space, cubic: bool) -> (Vec<i64>, usize) {
    let mut k: Vec<i64> = v
        .iter()
        .map(|&x| if x.is_nan() { 0 } else { Space::of(x, space) })
        .collect();
    let void: Vec<bool> = v.iter().map(|x| x.is_nan()).collect();
    let voids = void.iter().filter(|&&x| x).count();
    let mut known = vec![false; w * h];
    let mut out = Vec::with_capacity(w * h);
    let top = (w.max(h) - 1).max(1).next_power_of_two();
    let on = |i: usize, n: usize, s: usize| i.is_multiple_of(s) || i == n - 1;
    // Corners: planar from nothing (their own values, as residuals from 0 then deltas).
    let mut prev = 0i64;
    for &(x, y) in &[(0, 0), (w - 1, 0), (0, h - 1), (w - 1, h - 1)] {
        let i = y * w + x;
        if known[i] {
            continue;
        }
        known[i] = true;
        if void[i] {
            k[i] = prev;
        } else {
            out.push(k[i].wrapping_sub(prev));
        }
        prev = k[i];
    }
    let mut s = top;
    while s >= 1 {
        // Rows known at stride 2s (and the last): fill the columns new at stride s.
        let axis = |idx: &[usize], at: usize| -> Vec<(usize, f64)> {
            // idx: known coordinates along the axis (ascending); interpolate at `at`.
            let xs: Vec<u64> = idx.iter().map(|&i| i as u64).collect();
            weights(&xs, at as u64, cubic)
                .into_iter()
                .map(|(j, wgt)| (idx[j], wgt))
                .collect()
        };
        let cols_known: Vec<usize> = (0..w).filter(|&x| on(x, w, 2 * s)).collect();
        let rows_known: Vec<usize> = (0..h).filter(|&y| on(y, h, 2 * s)).collect();
        let predict_at = |i: usize, p: f64, k: &mut Vec<i64>, out: &mut Vec<i64>| {
            // In both spaces the interpolation is of the coded integers.
            let pred = p.round() as i64;
            if void[i] {
                k[i] = pred;
            } else {
                out.push(k[i].wrapping_sub(pred));
            }
        };
        for &y in &rows_known {
            for x in (0..w).filter(|&x| on(x, w, s) && !on(x, w, 2 * s)) {
                let i = y * w + x;
                let p: f64 = axis(&cols_known, x)
                    .iter()
                    .map(|&(c, wg)| wg * k[y * w + c] as f64)
                    .sum();
                predict_at(i, p, &mut k, &mut out);
                known[i] = true;
            }
        }
        let cols_now: Vec<usize> = (0..w).filter(|&x| on(x, w, s)).collect();
        for y in (0..h).filter(|&y| on(y, h, s) && !on(y, h, 2 * s)) {
            for &x in &cols_now {
                let i = y * w + x;
                let p: f64 = axis(&rows_known, y)
                    .iter()
                    .map(|&(r, wg)| wg * k[r * w + x] as f64)
                    .sum();
                predict_at(i, p, &mut k, &mut out);
                known[i] = true;
            }
        }
        s /= 2;
    }
    debug_assert!(known.iter().all(|&x| x));
    (out, voids)
}

fn values(model: &Model, s: &Samples, mended: bool) -> Vec<f32> {
    let raster = model.raster();
    let mut v = Vec::with_capacity(s.cols.len() * s.rows.len());
    for &r in &s.rows {
        for &c in &s.cols {
            let valid = raster.is_valid(c, r);
            v.push(if valid || mended {
                raster.value(c, r)
            } else {
                f32::NAN
            });
        }
    }
    v
}

/// Bytes of one model's payloads, today and as a pyramid, in total and per tree node (a
/// node at the finest level counts its physical block).
struct Measured {
    /// The same cubic coding through `codec::parent` (the format's encoder to be).
    codec: usize,
    today_grids: usize,
    today_blocks: usize,
    bilinear: usize,
    cubic: usize,
    within: usize,
    today_of: Vec<usize>,
    cubic_of: Vec<usize>,
    /// Per finest node: its block's non-held samples coded with the planar predictor.
    planar_held_of: Vec<usize>,
}

impl Measured {
    /// Whether a tree node's payload would be coded against its parent: only where that is
    /// smaller than coding it alone.
    fn against_parent(&self, i: usize) -> bool {
        self.cubic_of[i] < self.today_of[i]
    }

    /// File bytes when only finest-level nodes may be coded against their parent, taking
    /// the smallest of alone, the parent's interpolation and (`planar`) the planar predictor
    /// over the block's own samples with the held ones free.
    fn finest_hybrid(&self, levels: &[u8], finest: u8, planar: bool) -> usize {
        let in_tree_today: usize = self.today_of.iter().sum();
        let chosen: usize = (0..self.today_of.len())
            .map(|i| {
                if levels[i] != finest {
                    return self.today_of[i];
                }
                let best = self.today_of[i].min(self.cubic_of[i]);
                if planar {
                    best.min(self.planar_held_of[i])
                } else {
                    best
                }
            })
            .sum();
        self.today_grids + self.today_blocks - in_tree_today + chosen
    }

    /// File bytes when each payload takes the smaller of the two codings (physical blocks
    /// outside the tree stay as today).
    fn hybrid(&self) -> usize {
        let in_tree_today: usize = self.today_of.iter().sum();
        let chosen: usize = (0..self.today_of.len())
            .map(|i| self.today_of[i].min(self.cubic_of[i]))
            .sum();
        self.today_grids + self.today_blocks - in_tree_today + chosen
    }
}

/// Bytes of `v` (at `s`) coded by `codec::parent` against the parent `pv` (at `ps`), with a
/// payload's 4-byte length, decoded back and checked.
fn against(s: &Samples, v: &[f32], ps: &Samples, pv: &[f32]) -> usize {
    use fmrh::codec::parent::{decode_against, encode_against, Axes, Parent};
    let at = Axes {
        cols: &s.cols,
        rows: &s.rows,
    };
    let parent = Parent {
        at: Axes {
            cols: &ps.cols,
            rows: &ps.rows,
        },
        heights: pv,
    };
    let bytes = encode_against(v, at, parent, None, fmrh::codec::Coder::default())
        .expect("a child of its parent encodes");
    let mut out = vec![0.0f32; v.len()];
    decode_against(&bytes, at, parent, &mut out).expect("decodes");
    assert!(
        v.iter().zip(&out).all(|(a, b)| a.to_bits() == b.to_bits()),
        "codec::parent did not round-trip"
    );
    bytes.len() + 4
}

fn measure(model: &Model, space: Space) -> Measured {
    let d = *model.domain();
    let finest = d.finest_level();
    let nodes = model.tree().nodes();
    let mut m = Measured {
        codec: 0,
        today_grids: 0,
        today_blocks: 0,
        bilinear: 0,
        cubic: 0,
        within: 0,
        today_of: vec![0; nodes.len()],
        cubic_of: vec![0; nodes.len()],
        planar_held_of: vec![usize::MAX; nodes.len()],
    };
    let hier = |v: &[f32], w: usize| {
        let (r, voids) = hierarchical(v, w, v.len() / w, space, true);
        coded_len(&r, v.len(), voids) + 4
    };
    // Grids above the finest level: each against its parent's grid.
    let mut grid_of: Vec<Option<(Samples, Vec<f32>)>> = (0..nodes.len()).map(|_| None).collect();
    for (i, n) in nodes.iter().enumerate() {
        if n.level == finest {
            continue;
        }
        let s = grid_samples(model, n.level, n.x, n.y);
        let v = values(model, &s, true);
        let today = codec::encode(&v, s.cols.len()).len() + 4;
        m.today_grids += today;
        m.today_of[i] = today;
        m.within += hier(&v, s.cols.len());
        if n.parent == NO_PARENT {
            m.bilinear += today;
            m.cubic += today;
            m.codec += today;
            m.cubic_of[i] = today;
        } else {
            let (ps, pv) = grid_of[n.parent as usize]
                .as_ref()
                .expect("parents come first");
            let (r, voids) = residuals(&s, &v, ps, pv, space, false);
            m.bilinear += coded_len(&r, v.len(), voids);
            let (r, voids) = residuals(&s, &v, ps, pv, space, true);
            let c = coded_len(&r, v.len(), voids);
            m.cubic += c;
            m.cubic_of[i] = c;
            m.codec += against(&s, &v, ps, pv);
        }
        grid_of[i] = Some((s, v));
    }
    // Physical blocks: each against its nearest ancestor in the tree.
    let (cols, rows) = d.nodes_across(finest);
    let node_at: std::collections::HashMap<(u8, u32, u32), usize> = nodes
        .iter()
        .enumerate()
        .map(|(i, n)| ((n.level, n.x, n.y), i))
        .collect();
    for y in 0..rows {
        for x in 0..cols {
            let s = block_samples(model, x, y);
            let v = values(model, &s, false);
            let today = codec::encode(&v, s.cols.len()).len() + 4;
            m.today_blocks += today;
            m.within += hier(&v, s.cols.len());
            let mut up = (finest - 1, x / 2, y / 2);
            let parent = loop {
                if let Some(&i) = node_at.get(&up) {
                    break i;
                }
                up = (up.0 - 1, up.1 / 2, up.2 / 2);
            };
            let (ps, pv) = grid_of[parent].as_ref().expect("an ancestor grid");
            let (r, voids) = residuals(&s, &v, ps, pv, space, false);
            m.bilinear += coded_len(&r, v.len(), voids);
            let (r, voids) = residuals(&s, &v, ps, pv, space, true);
            let c = coded_len(&r, v.len(), voids);
            m.cubic += c;
            m.codec += against(&s, &v, ps, pv);
            if let Some(&i) = node_at.get(&(finest, x, y)) {
                m.today_of[i] = today;
                m.cubic_of[i] = c;
                let (r, voids) = planar_held(&s, &v, ps, space);
                m.planar_held_of[i] = coded_len(&r, v.len(), voids);
            }
        }
    }
    m
}

/// Residuals of the samples of block `child` that `parent` does not hold, predicted with the
/// planar predictor of the codec (`left + up − up_left` over the coded integers, in raster
/// order) from the block's own samples: the held ones are known before any is decoded, so
/// they cost nothing and still serve as neighbours. Voids take their prediction.
fn planar_held(child: &Samples, cv: &[f32], parent: &Samples, space: Space) -> (Vec<i64>, usize) {
    let w = child.cols.len();
    let held_col: Vec<bool> = child
        .cols
        .iter()
        .map(|c| parent.cols.binary_search(c).is_ok())
        .collect();
    let held_row: Vec<bool> = child
        .rows
        .iter()
        .map(|r| parent.rows.binary_search(r).is_ok())
        .collect();
    let mut k: Vec<i64> = cv
        .iter()
        .map(|&x| if x.is_nan() { 0 } else { Space::of(x, space) })
        .collect();
    let mut out = Vec::new();
    let mut voids = 0;
    for (j, &hr) in held_row.iter().enumerate() {
        for (i, &hc) in held_col.iter().enumerate() {
            let idx = j * w + i;
            let p = match (i, j) {
                (0, 0) => 0,
                (_, 0) => k[idx - 1],
                (0, _) => k[idx - w],
                _ => k[idx - 1]
                    .wrapping_add(k[idx - w])
                    .wrapping_sub(k[idx - w - 1]),
            };
            if cv[idx].is_nan() {
                voids += 1;
                k[idx] = p;
                continue;
            }
            if hr && hc {
                continue; // known from the parent
            }
            out.push(k[idx].wrapping_sub(p));
        }
    }
    (out, voids)
}

/// The space a DEM's heights are coded in: the coarsest lattice every height lies on, else
/// the float bits.
fn space_of(hf: &fmrh::Heightfield) -> (Space, String) {
    let step = codec::LATTICE_STEPS.iter().copied().find(|&q| {
        hf.samples()
            .iter()
            .all(|&v| v.is_nan() || codec::is_lattice_value(v, q))
    });
    (
        step.map_or(Space::Float, Space::Lattice),
        step.map_or("float".to_string(), |q| format!("lattice {q}")),
    )
}

fn main() {
    let files = [
        ("dem-hills (float)", "gdal-rs-dem-hills/dem_hills.json"),
        ("St Helens", "mount-st-helens-usgs/SainteHelens.json"),
        ("pysheds", "pysheds-dem/pysheds_dem.json"),
        ("Puget east 512", "puget-sound-east-512/ps-e_lg.json"),
        ("Puget 1k", "puget-sound-1k/ps_height_1k.json"),
        ("Puget 4k", "puget-sound-4k-jpg/ps_height_4k_jpg.json"),
        ("SRTM3 N22W160", "srtm3-srtmpy/N22W160.json"),
        ("Fuji", "fuji-terrain-rgb/fuji.json"),
    ];
    println!(
        "| DEM | space | today grids | today blocks | today total | bilinear total | cubic total | cubic / today | within payloads | / today | hybrid | / today | codec::parent total |"
    );
    println!("|---|---|---|---|---|---|---|---|---|---|---|---|---|");
    let mut finest_rows = Vec::new();
    for (name, rel) in files {
        let hf = load(&data(rel), &IngestOptions::default())
            .unwrap_or_else(|e| panic!("{rel}: {e} (this benchmark needs ../shared/data)"));
        let (space, label) = space_of(&hf);
        let model = Model::build(hf, &BuildOptions::default()).expect("builds");
        let m = measure(&model, space);
        let today = m.today_grids + m.today_blocks;
        let hybrid = m.hybrid();
        let levels: Vec<u8> = model.tree().nodes().iter().map(|n| n.level).collect();
        let f = model.domain().finest_level();
        let (f2, f3) = (
            m.finest_hybrid(&levels, f, false),
            m.finest_hybrid(&levels, f, true),
        );
        finest_rows.push(format!(
            "| {name} | {today} | {f2} | {:.2} | {f3} | {:.2} |",
            f2 as f64 / today as f64,
            f3 as f64 / today as f64
        ));
        println!(
            "| {name} | {label} | {} | {} | {today} | {} | {} | {:.2} | {} | {:.2} | {hybrid} | {:.2} | {} |",
            m.today_grids,
            m.today_blocks,
            m.bilinear,
            m.cubic,
            m.cubic as f64 / today as f64,
            m.within,
            m.within as f64 / today as f64,
            hybrid as f64 / today as f64,
            m.codec
        );
    }
    println!(
        "\nFormat 4 codes only physical blocks against their parent: payload bytes with the \
         smaller of alone and the parent's interpolation (format 4.0), and with a third \
         choice, the planar predictor over the block's own samples with the held ones free.\n"
    );
    println!("| DEM | today (alone) | 4.0: alone or interpolation | / today | + planar with held | / today |");
    println!("|---|---|---|---|---|---|");
    for r in finest_rows {
        println!("{r}");
    }
    if std::env::var_os("PYRAMID_SCENES").is_some() {
        scenes();
    }
}

/// What a scene would read: its blocks' payloads today, against the cubic pyramid's
/// payloads of its blocks *and every ancestor of them* (drawing a node needs its
/// ancestors' grids), on the scene benchmarks' DEMs and cameras.
fn scenes() {
    println!(
        "\n| dataset | camera | tau | blocks | today B | ancestors added | pyramid B | pyramid / today | hybrid B | hybrid / today |"
    );
    println!("|---|---|---|---|---|---|---|---|---|---|");
    for dem in dems::dems() {
        let (space, _) = space_of(&dem.source);
        let model = Model::build(dem.source.clone(), &BuildOptions::default()).expect("builds");
        let m = measure(&model, space);
        let mut bytes = std::io::Cursor::new(Vec::new());
        fmrh::store::write_to(
            &model,
            &dem.source.metadata,
            &fmrh::store::WriteOptions::default(),
            &mut bytes,
        )
        .expect("writes");
        let store = fmrh::store::Store::from_bytes(bytes.into_inner()).expect("opens");
        let terrain = fmrh::scene::Terrain::new(&store).expect("terrain");
        let nodes = model.tree().nodes();
        for (cam_name, cam) in dem.cameras() {
            for tau in [0.5, 1.0, 2.0, 4.0] {
                let scene = terrain
                    .scene(&cam, &fmrh::scene::SceneOptions::new(tau))
                    .expect("scene");
                let mut today = 0usize;
                let mut needed = std::collections::BTreeSet::new();
                for b in &scene.blocks {
                    match b.node {
                        Some(i) => {
                            today += m.today_of[i as usize];
                            let mut at = i;
                            while needed.insert(at) && nodes[at as usize].parent != NO_PARENT {
                                at = nodes[at as usize].parent;
                            }
                        }
                        // A physical block below a pruned leaf stays self-contained.
                        None => today += b.payload.len as usize,
                    }
                }
                let pyramid: usize = needed
                    .iter()
                    .map(|&i| m.cubic_of[i as usize])
                    .sum::<usize>()
                    + scene
                        .blocks
                        .iter()
                        .filter(|b| b.node.is_none())
                        .map(|b| b.payload.len as usize)
                        .sum::<usize>();
                let ancestors =
                    needed.len() - scene.blocks.iter().filter(|b| b.node.is_some()).count();
                // Hybrid: a node needs its parent only when coded against it.
                let mut hybrid_needed = std::collections::BTreeSet::new();
                for i in scene.blocks.iter().filter_map(|b| b.node) {
                    let mut at = i as usize;
                    while hybrid_needed.insert(at)
                        && m.against_parent(at)
                        && nodes[at].parent != NO_PARENT
                    {
                        at = nodes[at].parent as usize;
                    }
                }
                let hybrid: usize = hybrid_needed
                    .iter()
                    .map(|&i| m.today_of[i].min(m.cubic_of[i]))
                    .sum::<usize>()
                    + scene
                        .blocks
                        .iter()
                        .filter(|b| b.node.is_none())
                        .map(|b| b.payload.len as usize)
                        .sum::<usize>();
                println!(
                    "| {} | {cam_name} | {tau} | {} | {today} | {ancestors} | {pyramid} | {:.2} | {hybrid} | {:.2} |",
                    dem.name,
                    scene.blocks.len(),
                    pyramid as f64 / today.max(1) as f64,
                    hybrid as f64 / today.max(1) as f64
                );
            }
        }
    }
}
