//! Which order to keep a global dataset's tiles in: the QTM curve (seed 003) against the
//! orders of the longitude-latitude tiling itself.
//!
//! The tiles are the Earth cut into 1° × 1° cells (the SRTM tiling: 64,800 tiles). A view
//! sees the tiles whose shell (heights −11 km to 9 km) meets its frustum and is not wholly
//! below the horizon. A store that keeps its tiles sorted by some key reads a view as one
//! range scan per *run*: a maximal stretch of consecutive tiles in that order that are all
//! seen. Fewer runs, fewer scans (and, remotely, fewer requests). A dataset's manifest keeps
//! its tile records 32 to a page (`fmrh::format::manifest::TILES_PER_PAGE`), and opening a
//! view reads every page holding a seen tile: the second figure, `pages`, is that count,
//! what a view really reads. The orders:
//!
//! * `qtm`: the QTM curve index of the tile's centre at level 12 (cells of about 0.02°),
//!   ties (tiles near the poles, where the ZOT plane shrinks) by latitude and longitude;
//! * `hilbert`: the Hilbert curve over the 360 × 180 tile grid (what a dataset's manifest
//!   uses for its tiles, `format-spec/dataset.md`);
//! * `morton`: the Z-order of the tile grid (seed 001's code, `MortonKey`);
//! * `rows`: row after row, west to east.
//!
//! `cargo bench --bench qtm_order`. Counts, not timings: the same on any machine.

use fmrh::curve::{hilbert_encode, MortonKey, QtmCell};
use fmrh::format::manifest::TILES_PER_PAGE;
use fmrh::globe;
use fmrh::scene::{Aabb, Camera};

/// A tile: its south-west corner in whole degrees.
#[derive(Clone, Copy)]
struct Tile {
    lon: i32,
    lat: i32,
}

fn tiles() -> Vec<Tile> {
    let mut out = Vec::with_capacity(360 * 180);
    for lat in -90..90 {
        for lon in -180..180 {
            out.push(Tile { lon, lat });
        }
    }
    out
}

/// The tile's grid position: column from -180°, row from the north.
fn grid(t: &Tile) -> (u32, u32) {
    ((t.lon + 180) as u32, (89 - t.lat) as u32)
}

fn key(order: &str, t: &Tile) -> (u64, i32, i32) {
    let (c, r) = grid(t);
    let k = match order {
        "qtm" => QtmCell::locate(f64::from(t.lon) + 0.5, f64::from(t.lat) + 0.5, 12)
            .map(|q| q.curve_index())
            .unwrap_or(u64::MAX),
        "hilbert" => hilbert_encode(9, c, r),
        "morton" => MortonKey::from_node(9, c, r).code(),
        _ => u64::from(r) * 360 + u64::from(c),
    };
    (k, t.lat, t.lon)
}

/// Whether the view sees some of tile `t`.
fn seen(camera: &Camera, t: &Tile) -> bool {
    let view = camera.view().expect("a camera");
    let (lon0, lat0) = (f64::from(t.lon), f64::from(t.lat));
    let (min, max) = globe::shell_box(lon0, lon0 + 1.0, lat0, lat0 + 1.0, -11_000.0, 9_000.0);
    view.intersects(&Aabb { min, max })
        && !globe::shell_hidden(camera.eye, lon0, lon0 + 1.0, lat0, lat0 + 1.0, 9_000.0)
}

fn main() {
    let all = tiles();
    let cameras: [(&str, f64, f64, f64, f64, f64); 7] = [
        (
            "orbit 20,000 km over 43.5N 6.5E",
            43.5,
            6.5,
            2.0e7,
            0.0,
            -90.0,
        ),
        (
            "over the north pole, 1,000 km",
            89.99,
            0.0,
            1.0e6,
            0.0,
            -90.0,
        ),
        (
            "north pole, 3,000 km, oblique",
            80.0,
            30.0,
            3.0e6,
            0.0,
            -45.0,
        ),
        (
            "across the antimeridian, 500 km",
            0.0,
            180.0,
            5.0e5,
            0.0,
            -90.0,
        ),
        (
            "antimeridian 60S, 300 km, east",
            -60.0,
            179.0,
            3.0e5,
            90.0,
            -20.0,
        ),
        ("south pole, 2,000 km", -89.99, 0.0, 2.0e6, 0.0, -90.0),
        (
            "3 km over N43E006, looking north",
            43.2,
            6.5,
            3.0e3,
            0.0,
            -10.0,
        ),
    ];
    let orders = ["qtm", "hilbert", "morton", "rows"];
    let sorted: Vec<Vec<Tile>> = orders
        .iter()
        .map(|o| {
            let mut v = all.clone();
            v.sort_by_key(|t| key(o, t));
            v
        })
        .collect();
    println!(
        "{:<34} {:>6} | {:>13} {:>13} {:>13} {:>13}",
        "view: runs / manifest pages", "tiles", orders[0], orders[1], orders[2], orders[3]
    );
    let mut totals = [(0usize, 0usize); 4];
    for (name, lat, lon, h, heading, pitch) in cameras {
        let camera = Camera::on_globe(lat, lon, h, heading, pitch);
        let mut row = Vec::new();
        let mut count = 0;
        for (o, order) in sorted.iter().enumerate() {
            let flags: Vec<bool> = order.iter().map(|t| seen(&camera, t)).collect();
            count = flags.iter().filter(|&&f| f).count();
            let runs = flags
                .iter()
                .enumerate()
                .filter(|&(i, &f)| f && (i == 0 || !flags[i - 1]))
                .count();
            let pages = flags
                .chunks(TILES_PER_PAGE)
                .filter(|c| c.iter().any(|&f| f))
                .count();
            totals[o].0 += runs;
            totals[o].1 += pages;
            row.push(format!("{runs} / {pages}"));
        }
        println!(
            "{:<34} {:>6} | {:>13} {:>13} {:>13} {:>13}",
            name, count, row[0], row[1], row[2], row[3]
        );
    }
    let t: Vec<String> = totals.iter().map(|(r, p)| format!("{r} / {p}")).collect();
    println!(
        "{:<34} {:>6} | {:>13} {:>13} {:>13} {:>13}",
        "all views", "", t[0], t[1], t[2], t[3]
    );
}
