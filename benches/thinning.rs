//! Thinning by area (issue 19, `fmrh::model::thinning`): what coarsening a geographic
//! grid's nodes east-west by their true area would save, at equal measured error.
//!
//! For each grid: the model is built as `fmrh build` builds it (block 65, the default
//! ladder), every node is thinned by its area factor and its error measured on the thinned
//! grid, and then, side by side:
//!
//! * **grids**: the coarse nodes' grid samples and coded bytes (fmrh's grid codec, each grid
//!   coded on its own, both ways), and how many nodes have a factor above 1;
//! * **cuts at equal error**: for each threshold δ of the model's cluster ladder, the cut of
//!   the tree with every node's monotone error at most δ (what a uniform scene of the whole
//!   grid at that error loads): blocks and coded bytes with square grids and their errors,
//!   against thinned grids and their (larger) thinned errors, physical blocks where a leaf
//!   is not within δ.
//!
//! The grids: the bundled ETOPO1 whole-Earth grid (0.5°, every latitude), the bundled SRTM3
//! tile N43E006 where it is (43°–44° N, factor 1 everywhere: the control), and the same
//! tile placed at 60°, 70° and 80° N two ways (there is no SRTM north of 60°, and polar DEMs
//! of that size are not bundled): its samples as they are (the relief squeezed east-west by
//! the narrower columns), and its relief regridded to keep its shape on the ground (each row
//! resampled linearly: a longitude-latitude product made from isotropic ground data, which
//! polar grids are, samples the ground that much more densely east-west).
//!
//! **Stored (format 6).** Then the same grid built twice as `fmrh build` writes it (payloads
//! coded against their parents where smaller, 4 KiB pages): square (`--no-thin`) and thinned
//! by area (the default for longitude-latitude grids, with the √2 error guard), both with
//! the square build's thresholds. Side by side: file and grid bytes, and for each threshold
//! δ the bytes a uniform scene at δ reads: the payloads of the cluster's cut plus every
//! ancestor grid they are coded against (what a reader must decode first).
//!
//! `cargo bench --bench thinning` (bundled data only). One timing: the model build, square
//! against thinned (thinning measures each candidate node a second time), best of three.

use std::collections::HashMap;
use std::path::PathBuf;

#[path = "common/thinning_study.rs"]
mod study;

use fmrh::model::thinning::LatLonSpacing;
use fmrh::model::{BuildOptions, Model, ThinByArea, Thresholds};
use fmrh::store::Store;
use fmrh::store::{write_to, WriteOptions};
use fmrh::Heightfield;
use study::{cut, thinned_grid, AreaThinning};

fn bundled(rel: &str) -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR"))
        .join("data")
        .join(rel)
}

/// Coded bytes of node `(level, x, y)`'s grid thinned `k` times.
fn coded(model: &Model, level: u8, x: u32, y: u32, k: u32) -> (u64, u64) {
    let (cols, grid) = thinned_grid(model.raster(), model.domain(), level, x, y, k);
    (
        grid.len() as u64,
        fmrh::codec::encode(&grid, cols as usize).len() as u64,
    )
}

fn report(name: &str, field: Heightfield) {
    let g = field
        .metadata
        .georeference
        .clone()
        .expect("a georeferenced grid");
    let spacing = LatLonSpacing {
        lat0: g.origin[1],
        dlat: g.step[1],
        dlon: g.step[0],
    };
    let model = Model::build(
        field.clone(),
        &BuildOptions {
            thin: ThinByArea::Off,
            ..BuildOptions::default()
        },
    )
    .expect("model");
    let tree = model.tree();
    let d = model.domain();
    let by_area = AreaThinning::measure(model.raster(), tree, &spacing);
    let within = AreaThinning::measure_within(model.raster(), tree, &spacing, 2f64.sqrt());
    let finest = d.finest_level();
    let coarse = tree.nodes().iter().filter(|n| n.level < finest).count();
    println!(
        "\n### {name}: {} x {} samples, latitudes {:.2}..{:.2}, {} levels, {} nodes ({} coarse)\n",
        d.width(),
        d.height(),
        spacing.lat0 + f64::from(d.height() - 1) * spacing.dlat,
        spacing.lat0,
        d.levels(),
        tree.nodes().len(),
        coarse
    );
    // Per node: coded bytes with each policy's factor; the coarse nodes' totals.
    let per_node = |t: &AreaThinning, label: &str| -> Vec<u64> {
        let (mut samples, mut bytes, mut square_samples, mut square_bytes, mut thinned) =
            (0, 0, 0, 0, 0);
        let out = tree
            .nodes()
            .iter()
            .enumerate()
            .map(|(i, n)| {
                let k = t.factor[i];
                let c = coded(&model, n.level, n.x, n.y, k);
                if n.level < finest {
                    let sq = if k > 1 {
                        coded(&model, n.level, n.x, n.y, 1)
                    } else {
                        c
                    };
                    samples += c.0;
                    bytes += c.1;
                    square_samples += sq.0;
                    square_bytes += sq.1;
                    thinned += usize::from(k > 1);
                }
                c.1
            })
            .collect();
        println!(
            "{label}: {thinned} of {coarse} coarse grids thinned; their samples {square_samples} -> {samples} ({:+.1} %), coded bytes {square_bytes} -> {bytes} ({:+.1} %)",
            (samples as f64 / square_samples.max(1) as f64 - 1.0) * 100.0,
            (bytes as f64 / square_bytes.max(1) as f64 - 1.0) * 100.0
        );
        out
    };
    let square = per_node(
        &AreaThinning {
            factor: vec![1; tree.nodes().len()],
            static_error: Vec::new(),
            monotone_error: Vec::new(),
        },
        "square",
    );
    let area_bytes = per_node(&by_area, "by area");
    let within_bytes = per_node(&within, "by area within √2 of the error");
    let mut physical: HashMap<(u32, u32), u64> = HashMap::new();
    let mut cost = |cutset: &[(Option<u32>, u8, u32, u32)], per_node: &[u64]| -> (usize, u64) {
        let bytes = cutset
            .iter()
            .map(|&(i, level, x, y)| match i {
                Some(i) => per_node[i as usize],
                None => *physical
                    .entry((x, y))
                    .or_insert_with(|| coded(&model, level, x, y, 1).1),
            })
            .sum();
        (cutset.len(), bytes)
    };
    println!("\n| δ (m) | square: blocks | KB | by area: blocks | KB | saved | within √2: blocks | KB | saved |");
    println!("|---|---|---|---|---|---|---|---|---|");
    let square_monotone: Vec<f64> = tree.nodes().iter().map(|n| n.monotone_error).collect();
    let saved = |a: u64, b: u64| (1.0 - b as f64 / a.max(1) as f64) * 100.0;
    for c in model.clusters() {
        let delta = c.threshold;
        let a = cost(&cut(tree, &square_monotone, delta), &square);
        let b = cost(&cut(tree, &by_area.monotone_error, delta), &area_bytes);
        let w = cost(&cut(tree, &within.monotone_error, delta), &within_bytes);
        println!(
            "| {delta:.1} | {} | {:.1} | {} | {:.1} | {:+.1} % | {} | {:.1} | {:+.1} % |",
            a.0,
            a.1 as f64 / 1024.0,
            b.0,
            b.1 as f64 / 1024.0,
            saved(a.1, b.1),
            w.0,
            w.1 as f64 / 1024.0,
            saved(a.1, w.1),
        );
    }
    stored(&field);
}

/// The least of three builds' wall times of `field` with `options`, in milliseconds.
fn build_ms(field: &Heightfield, options: &BuildOptions) -> f64 {
    (0..3)
        .map(|_| {
            let t = std::time::Instant::now();
            let m = Model::build(field.clone(), options).expect("model");
            let ms = t.elapsed().as_secs_f64() * 1e3;
            drop(m);
            ms
        })
        .fold(f64::INFINITY, f64::min)
}

/// `field` built and written square and thinned, in memory.
fn stored(field: &Heightfield) {
    let square = Model::build(
        field.clone(),
        &BuildOptions {
            thin: ThinByArea::Off,
            ..BuildOptions::default()
        },
    )
    .expect("model");
    let thresholds: Vec<f64> = square.clusters().iter().map(|c| c.threshold).collect();
    let thinned = Model::build(
        field.clone(),
        &BuildOptions {
            thresholds: Thresholds::Explicit(thresholds.clone()),
            thin: ThinByArea::Auto,
            ..BuildOptions::default()
        },
    )
    .expect("model");
    let bytes = |m: &Model| {
        let mut out = std::io::Cursor::new(Vec::new());
        write_to(m, &field.metadata, &WriteOptions::default(), &mut out).expect("written");
        Store::from_bytes(out.into_inner()).expect("opens")
    };
    let (a, b) = (bytes(&square), bytes(&thinned));
    let thin_count = thinned.tree().nodes().iter().filter(|n| n.thin > 0).count();
    let (la, lb) = (a.layout().expect("layout"), b.layout().expect("layout"));
    let saved = |a: u64, b: u64| (1.0 - b as f64 / a.max(1) as f64) * 100.0;
    println!(
        "\nstored (format 6): {thin_count} coarse grids thinned; file {} -> {} bytes ({:+.1} % saved), grid payloads {} -> {} ({:+.1} % saved), block payloads {} -> {} ({:+.1} % saved: fewer of a block's samples are held by a thinned parent)",
        la.file_length,
        lb.file_length,
        saved(la.file_length, lb.file_length),
        la.grid_bytes,
        lb.grid_bytes,
        saved(la.grid_bytes, lb.grid_bytes),
        la.block_bytes,
        lb.block_bytes,
        saved(la.block_bytes, lb.block_bytes)
    );
    let off = BuildOptions {
        thin: ThinByArea::Off,
        ..BuildOptions::default()
    };
    println!(
        "build time (best of 3, this machine): square {:.0} ms, thinned {:.0} ms",
        build_ms(field, &off),
        build_ms(field, &BuildOptions::default())
    );
    println!("\n| δ (m) | square: nodes | KB read | thinned: nodes | KB read | saved |");
    println!("|---|---|---|---|---|---|");
    for (c, delta) in thresholds.iter().enumerate() {
        let (na, ka) = read_at(&a, &square, c);
        let (nb, kb) = read_at(&b, &thinned, c);
        println!(
            "| {delta:.1} | {na} | {:.1} | {nb} | {:.1} | {:+.1} % |",
            ka as f64 / 1024.0,
            kb as f64 / 1024.0,
            saved(ka, kb)
        );
    }
}

/// The nodes of cluster `c`'s cut and the payload bytes a reader reads to draw them: their
/// own and every grid they are coded against, transitively, each once.
fn read_at<S: fmrh::store::Source>(store: &Store<S>, model: &Model, c: usize) -> (usize, u64) {
    let nodes = store.nodes().expect("nodes");
    let finest = store.domain().finest_level();
    let mut seen = std::collections::HashSet::new();
    let mut bytes = 0u64;
    let cut = &model.clusters()[c].nodes;
    for &i in cut {
        let mut todo = vec![i];
        while let Some(i) = todo.pop() {
            if !seen.insert(i) {
                continue;
            }
            let n = &nodes[i as usize];
            bytes += u64::from(n.payload.len);
            if n.level == finest {
                let b = store.stored_block(n.x, n.y).expect("block");
                todo.extend(b.against);
            } else if n.grid_against_parent {
                todo.extend(n.parent);
            }
        }
    }
    (cut.len(), bytes)
}

fn main() {
    let options = fmrh::ingest::IngestOptions::default();
    let etopo = fmrh::ingest::load(
        &bundled("etopo1-pybacktrack/etopo1-bed-0.5deg.tif"),
        &options,
    )
    .expect("ETOPO1");
    report("ETOPO1 0.5°, the whole Earth", etopo);
    let srtm =
        fmrh::ingest::load(&bundled("srtm3-pyhgtmap/N43E006.hgt.gz"), &options).expect("N43E006");
    report("N43E006 where it is (control)", srtm.clone());
    for lat in [61.0, 71.0, 81.0] {
        let mut moved = srtm.clone();
        if let Some(g) = moved.metadata.georeference.as_mut() {
            g.origin[1] = lat;
        }
        report(
            &format!("N43E006's samples placed at {}°–{lat}° N", lat - 1.0),
            moved,
        );
        report(
            &format!(
                "N43E006's relief at {}°–{lat}° N, regridded to keep its ground shape",
                lat - 1.0
            ),
            regridded(&srtm, lat - 0.5),
        );
    }
}

/// `field` (an SRTM tile at 43.5° N) moved to be centred on latitude `lat`, its relief kept
/// the same shape on the ground: each row resampled east-west (linearly between the source
/// samples) at the source's ground spacing times `cos lat / cos 43.5°`, as a longitude-
/// latitude product gridded from isotropic ground data is there. Same sample count.
fn regridded(field: &Heightfield, lat: f64) -> Heightfield {
    let (w, h) = (field.width(), field.height());
    let ratio = lat.to_radians().cos() / 43.5f64.to_radians().cos();
    let src = field.samples();
    let mut out = Heightfield::from_fn(w, h, |x, y| {
        let c = f64::from(x) * ratio;
        let (c0, t) = (c.floor() as usize, c - c.floor());
        let row = &src[y as usize * w as usize..(y as usize + 1) * w as usize];
        let a = f64::from(row[c0]);
        let b = f64::from(row[(c0 + 1).min(w as usize - 1)]);
        // Whole metres, as the source (and every SRTM-like product) stores them.
        (a + (b - a) * t).round() as f32
    })
    .expect("a valid field");
    out.metadata = field.metadata.clone();
    if let Some(g) = out.metadata.georeference.as_mut() {
        g.origin[1] = lat + 0.5;
    }
    out
}
