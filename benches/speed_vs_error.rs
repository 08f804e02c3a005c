//! Speed and bytes against error, as a picture: for each DEM, five ways to answer the same
//! cameras at tau 0.5 to 8 px, each placed by its *measured* largest screen error (its
//! surface compared with the source at every valid sample the frustum may see, in pixels
//! at that sample's distance: not the method's own report) against its time and against
//! the bytes it read.
//!
//! Methods: **fmrh view** (view-dependent scene), **fmrh uniform** (one cluster from the
//! nearest distance), **traversal** (the view-dependent cut walked from the root, no
//! clusters: `scene::baseline::traversal`), **all-finest** (every physical block of the view),
//! each opened lean from a file read with `pread`, selected, and its blocks loaded and
//! decoded; and **COG** (a Cloud-Optimized GeoTIFF read by a reader that knows every tile's
//! true error, `benches/common/cog.rs`). Times are warm, best of 3, open included; per tau
//! the plot shows the mean time and bytes over the cameras and the worst measured error.
//!
//! Writes `docs/speed-vs-error.csv` and one `docs/speed-vs-error-<dem>.svg` per DEM (plotters,
//! SVG backend, no font files). `cargo bench --bench speed_vs_error` (gdal-bin for the COG;
//! the large DEMs need `../shared/data`).

#[path = "common/cog.rs"]
mod cog;
#[path = "common/dems.rs"]
mod dems;

use std::collections::BTreeMap;
use std::fmt::Write as _;
use std::path::{Path, PathBuf};
use std::time::Instant;

use plotters::prelude::*;

use fmrh::scene::{
    baseline, load_blocks, reconstruct, Camera, Mode, Scene, SceneBlock, SceneOptions, Terrain,
    TerrainFrame, View, WorldFrame,
};
use fmrh::store::FileSource;
use fmrh::{store::Store, Heightfield};

const METHODS: [&str; 5] = [
    "fmrh view",
    "fmrh uniform",
    "traversal",
    "all-finest",
    "COG",
];
const TAUS: [f64; 5] = [0.5, 1.0, 2.0, 4.0, 8.0];

/// One measurement: time (us), bytes read, measured max screen error (px).
#[derive(Clone, Copy, Debug)]
struct Point {
    us: f64,
    bytes: f64,
    px: f64,
}

/// The blocks of `method` for `cam` at `tau`, from `store`.
fn select(
    store: &Store<FileSource>,
    method: &str,
    cam: &Camera,
    tau: f64,
) -> (Vec<SceneBlock>, Scene) {
    let terrain = Terrain::new(store).expect("terrain");
    let mode = if method == "fmrh uniform" {
        Mode::Uniform
    } else {
        Mode::View
    };
    let scene = terrain
        .scene(
            cam,
            &SceneOptions {
                mode,
                ..SceneOptions::new(tau)
            },
        )
        .expect("scene");
    let blocks = match method {
        "traversal" => baseline::traversal(&terrain, cam, tau, None).expect("traversal"),
        "all-finest" => baseline::all_finest(&terrain, cam, None).expect("all finest"),
        _ => scene.blocks.clone(),
    };
    (blocks, scene)
}

/// Open, select, load and decode: (time us, bytes read).
fn timed(path: &Path, method: &str, cam: &Camera, tau: f64) -> (f64, f64) {
    let mut best = f64::INFINITY;
    let mut bytes = 0.0;
    for _ in 0..3 {
        let t = Instant::now();
        let store = Store::open(path).expect("opens");
        let (blocks, _) = select(&store, method, cam, tau);
        load_blocks(&store, &blocks, 0).expect("loads");
        best = best.min(t.elapsed().as_secs_f64() * 1e6);
        bytes = (store.open_reads().bytes() + store.read_stats().bytes()) as f64;
    }
    (best, bytes)
}

/// The measured largest screen error of `blocks` over the view's window.
fn measured(
    store: &Store<FileSource>,
    source: &Heightfield,
    frame: WorldFrame,
    view: &View,
    blocks: Vec<SceneBlock>,
    scene: &Scene,
) -> f64 {
    let Some(window) = scene.window else {
        return 0.0;
    };
    let as_scene = Scene {
        blocks,
        ..scene.clone()
    };
    let rec = reconstruct(store, &as_scene, window).expect("reconstructs");
    let w = (window.col1 - window.col0 + 1) as usize;
    let sw = source.width() as usize;
    let mut worst = 0.0f64;
    for (i, v) in rec.values.iter().enumerate() {
        let (col, row) = (window.col0 + (i % w) as u64, window.row0 + (i / w) as u64);
        let h = source.samples()[row as usize * sw + col as usize];
        if h.is_nan() || v.is_nan() {
            continue;
        }
        worst = worst.max(cog::sample_px(view, frame, col, row, h, *v));
    }
    worst
}

fn chart(path: &Path, title: &str, series: &BTreeMap<&str, Vec<Point>>) {
    let colours = [
        RGBColor(31, 119, 180),
        RGBColor(44, 160, 44),
        RGBColor(148, 103, 189),
        RGBColor(127, 127, 127),
        RGBColor(214, 39, 40),
    ];
    let root = SVGBackend::new(path, (1100, 440)).into_drawing_area();
    root.fill(&WHITE).expect("draws");
    let (left, right) = root.split_horizontally(550);
    let ymax = series
        .values()
        .flatten()
        .map(|p| p.px)
        .fold(0.0f64, f64::max)
        .max(1.0)
        * 1.1;
    for (area, by_bytes) in [(left, false), (right, true)] {
        let x = |p: &Point| if by_bytes { p.bytes } else { p.us };
        let all: Vec<f64> = series.values().flatten().map(x).collect();
        let (lo, hi) = (
            all.iter().copied().fold(f64::INFINITY, f64::min) * 0.7,
            all.iter().copied().fold(0.0f64, f64::max) * 1.4,
        );
        let caption = if by_bytes {
            format!("{title}: error against bytes read")
        } else {
            format!("{title}: error against time (warm)")
        };
        let mut c = ChartBuilder::on(&area)
            .caption(caption, ("sans-serif", 16))
            .margin(12)
            .x_label_area_size(40)
            .y_label_area_size(50)
            .build_cartesian_2d((lo..hi).log_scale(), 0.0..ymax)
            .expect("chart");
        c.configure_mesh()
            .x_desc(if by_bytes {
                "bytes read"
            } else {
                "microseconds"
            })
            .y_desc("measured max screen error (px)")
            .draw()
            .expect("mesh");
        for (i, name) in METHODS.iter().enumerate() {
            let Some(points) = series.get(name) else {
                continue;
            };
            let colour = colours[i];
            let xy: Vec<(f64, f64)> = points.iter().map(|p| (x(p), p.px)).collect();
            c.draw_series(LineSeries::new(xy.clone(), colour.stroke_width(2)))
                .expect("line")
                .label(*name)
                .legend(move |(x, y)| PathElement::new(vec![(x, y), (x + 16, y)], colour));
            c.draw_series(xy.into_iter().map(|p| Circle::new(p, 3, colour.filled())))
                .expect("points");
        }
        c.configure_series_labels()
            .border_style(BLACK)
            .background_style(WHITE)
            .draw()
            .expect("legend");
    }
    root.present().expect("writes the SVG");
}

fn main() {
    let dir = tempfile::tempdir().expect("temp dir");
    let root = PathBuf::from(env!("CARGO_MANIFEST_DIR"));
    let docs = root.join("docs");
    std::fs::create_dir_all(&docs).expect("docs/");
    let mut csv = String::from("dem,camera,method,tau,time_us,bytes,measured_px\n");
    for dem in dems::dems() {
        let name = dem.name;
        let frame = WorldFrame::new(Some(dem.spacing));
        let cog = cog::make_cog(dir.path(), name, &dem.source);
        let path = dem.build(dir.path());
        let source = &dem.source;
        let store = Store::open(&path).expect("opens");
        // Per method and tau: (sum us, sum bytes, max px, cameras).
        let mut acc: BTreeMap<(&str, u64), (f64, f64, f64, f64)> = BTreeMap::new();
        let cams: Vec<_> = dem
            .cameras()
            .into_iter()
            .filter(|(c, _)| *c != "overview")
            .collect();
        for (cam_name, cam) in &cams {
            let view = cam.view().expect("camera");
            for tau in TAUS {
                for method in METHODS {
                    let p = if method == "COG" {
                        let Some(cog) = &cog else { continue };
                        let (tiles, _) = cog::cog_scene(cog, TerrainFrame::Flat(frame), &view, tau);
                        let (bytes, _) = cog::cog_reads(cog, &tiles);
                        let us = (0..3)
                            .map(|_| {
                                let t = Instant::now();
                                let chosen =
                                    cog::cog_scene(cog, TerrainFrame::Flat(frame), &view, tau).0;
                                cog::cog_decode(cog, &chosen);
                                t.elapsed().as_secs_f64() * 1e6
                            })
                            .fold(f64::INFINITY, f64::min);
                        let px = cog::measured_px(cog, source, frame, &view, &tiles);
                        Point {
                            us,
                            bytes: bytes as f64,
                            px,
                        }
                    } else {
                        let (us, bytes) = timed(&path, method, cam, tau);
                        let (blocks, scene) = select(&store, method, cam, tau);
                        let px = measured(&store, source, frame, &view, blocks, &scene);
                        Point { us, bytes, px }
                    };
                    let _ = writeln!(
                        csv,
                        "{name},{cam_name},{method},{tau},{:.1},{},{:.4}",
                        p.us, p.bytes, p.px
                    );
                    let e = acc
                        .entry((method, tau.to_bits()))
                        .or_insert((0.0, 0.0, 0.0, 0.0));
                    e.0 += p.us;
                    e.1 += p.bytes;
                    e.2 = e.2.max(p.px);
                    e.3 += 1.0;
                }
            }
        }
        let mut series: BTreeMap<&str, Vec<Point>> = BTreeMap::new();
        for ((method, _), (us, bytes, px, n)) in acc {
            series.entry(method).or_default().push(Point {
                us: us / n,
                bytes: bytes / n,
                px,
            });
        }
        let svg = docs.join(format!("speed-vs-error-{name}.svg"));
        chart(&svg, name, &series);
        println!("{name}: wrote {}", svg.display());
        for (method, points) in &series {
            let line: Vec<String> = points
                .iter()
                .map(|p| format!("{:.0} us / {:.0} B / {:.2} px", p.us, p.bytes, p.px))
                .collect();
            println!("  {method:>12}: {}", line.join(" | "));
        }
    }
    std::fs::write(docs.join("speed-vs-error.csv"), csv).expect("writes the CSV");
}
