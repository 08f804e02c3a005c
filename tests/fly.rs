//! Frames are incremental and their bookkeeping is exact. The shipped camera paths
//! (`tests/paths/*.csv`) are what their generators produce over the real DEMs; replaying them
//! through the scheduler, every frame loads exactly the visible blocks that were not
//! resident, keeps the rest, evicts only blocks out of view, and frames after the first
//! load a small fraction of the first (seed 000 Table 2, printed). Prefetch changes where
//! bytes come from, never which blocks a frame loads; on a steady path whose next camera is
//! predicted exactly, every load is a prefetch hit. The memory area keeps blocks that left
//! the view, and the budget bounds what it keeps.

mod common;

use std::collections::HashSet;
use std::path::PathBuf;
use std::sync::Arc;

use common::views::{self, Fixture};
use fmrh::model::BuildOptions;
use fmrh::scene::path::{self, Ground};
use fmrh::scene::{BlockId, Camera, ScheduleOptions, Scheduler, Terrain};
use fmrh::store::Bytes;
use fmrh::store::Store;

struct Shipped {
    name: &'static str,
    make: fn(&Ground<'_>) -> Vec<Camera>,
    dataset: fn() -> fmrh::Heightfield,
}

fn n43e007() -> fmrh::Heightfield {
    fmrh::ingest::load(
        &common::data("srtm3-pyhgtmap/N43E007.f32"),
        &Default::default(),
    )
    .unwrap()
}

fn shipped() -> Vec<Shipped> {
    vec![
        Shipped {
            name: "puget-1k-straight",
            make: |g| path::straight(g, 1500.0, 600),
            dataset: views::puget_1k,
        },
        Shipped {
            name: "puget-1k-orbit",
            make: |g| path::orbit(g, 0.35, 4000.0, 720),
            dataset: views::puget_1k,
        },
        Shipped {
            name: "puget-1k-low-pass",
            make: |g| path::low_pass(g, 0.5, 150.0, 4000.0, 600),
            dataset: views::puget_1k,
        },
        Shipped {
            name: "n43e007-low-pass",
            make: |g| path::low_pass(g, 0.1, 100.0, 2000.0, 600),
            dataset: n43e007,
        },
    ]
}

fn path_file(name: &str) -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR")).join(format!("tests/paths/{name}.csv"))
}

/// The generator's view of a fixture: extent and highest mended ground near a point.
fn with_ground<T>(f: &Fixture, body: impl FnOnce(&Ground<'_>) -> T) -> T {
    let terrain = Terrain::new(&f.store).unwrap();
    let frame = terrain.frame();
    let d = f.model.domain();
    let (w, h) = (d.width() as f64, d.height() as f64);
    let highest = |x: f64, y: f64, r: f64| -> f64 {
        let c = |v: f64, step: f64, n: f64| (v / step).clamp(0.0, n - 1.0);
        let (c0, c1) = (c(x - r, frame.dx, w) as u64, c(x + r, frame.dx, w) as u64);
        let (r0, r1) = (c(y - r, frame.dy, h) as u64, c(y + r, frame.dy, h) as u64);
        let mut top = f64::NEG_INFINITY;
        for row in r0..=r1 {
            for col in c0..=c1 {
                top = top.max(f64::from(f.model.raster().value(col, row)));
            }
        }
        top
    };
    let g = Ground {
        width: (w - 1.0) * frame.dx,
        height: (h - 1.0) * frame.dy,
        highest: &highest,
    };
    body(&g)
}

fn cameras_of(s: &Shipped) -> Vec<Camera> {
    let text = std::fs::read_to_string(path_file(s.name)).expect("the shipped path exists");
    path::parse(
        &text,
        &Camera::looking_at(glam::DVec3::ZERO, glam::DVec3::X),
    )
    .unwrap()
}

#[test]
fn shipped_paths_match_their_generators() {
    for s in shipped() {
        let f = views::fixture((s.dataset)(), &BuildOptions::default());
        let text = with_ground(&f, |g| path::to_csv(&(s.make)(g)));
        let file = path_file(s.name);
        if std::env::var_os("FMRH_BLESS").is_some() {
            std::fs::write(&file, &text).unwrap();
        }
        let shipped = std::fs::read_to_string(&file).expect("run with FMRH_BLESS=1 to create");
        assert_eq!(shipped, text, "{} differs from its generator", s.name);
    }
}

fn arc_store(f: Fixture) -> Arc<Store<Bytes<Vec<u8>>>> {
    Arc::new(f.store)
}

#[test]
fn frames_load_only_what_is_missing() {
    let mut table = String::new();
    for s in shipped() {
        let store = arc_store(views::fixture((s.dataset)(), &BuildOptions::default()));
        let cams = cameras_of(&s);
        let mut sched = Scheduler::new(store, ScheduleOptions::new(1.0)).unwrap();
        let mut resident: HashSet<BlockId> = HashSet::new();
        let mut loads = Vec::new();
        for (i, cam) in cams.iter().enumerate() {
            let frame = sched.frame(cam).unwrap();
            let visible: HashSet<BlockId> = sched
                .last_scene()
                .unwrap()
                .blocks
                .iter()
                .map(BlockId::of)
                .collect();
            let load: HashSet<BlockId> = frame.load.iter().copied().collect();
            let keep: HashSet<BlockId> = frame.keep.iter().copied().collect();
            assert_eq!(&load | &keep, visible, "{} frame {i}", s.name);
            // The scheduler's selection (a coarser region) is the scene, block for block.
            let exact = Terrain::new(sched.store())
                .unwrap()
                .scene(cam, &ScheduleOptions::new(1.0).scene)
                .unwrap();
            assert_eq!(
                sched.last_scene().unwrap().blocks,
                exact.blocks,
                "{} frame {i}",
                s.name
            );
            assert!(load.is_disjoint(&resident), "{} frame {i} reloads", s.name);
            assert!(keep.is_subset(&resident));
            for e in &frame.evict {
                assert!(!visible.contains(e) && resident.contains(e));
            }
            resident = &(&resident | &load) - &frame.evict.iter().copied().collect();
            let now: HashSet<BlockId> = sched.resident().map(BlockId::of).collect();
            assert_eq!(now, resident);
            // No memory area: the resident set is the view.
            assert_eq!(resident, visible);
            loads.push(frame.stats);
        }
        let first = loads[0].loaded as f64;
        let later =
            loads[1..].iter().map(|l| l.loaded).sum::<u64>() as f64 / (loads.len() - 1) as f64;
        let pick = |i: usize| loads.get(i).map_or(0, |l| l.loaded_triangles);
        table.push_str(&format!(
            "{:<20} frame 1: {:>8} tri | 10: {:>7} | 100: {:>7} | {}: {:>7} | later mean {:.1}% of frame 1 blocks\n",
            s.name, pick(0), pick(9), pick(99), loads.len(), pick(loads.len() - 1), 100.0 * later / first
        ));
        assert!(
            later <= 0.25 * first,
            "{}: frames after the first load {later} blocks on average, the first {first}",
            s.name
        );
    }
    eprintln!("{table}");
}

/// A frame is a selection, then its application. A selection applied late (after another
/// frame made its blocks resident) loads none of them again: they are kept, and the resident
/// bytes are counted once.
#[test]
fn a_selection_applied_late_loads_nothing_twice() {
    let store = arc_store(views::fixture(views::puget_1k(), &BuildOptions::default()));
    let cams = cameras_of(&shipped()[0]);
    let mut sched = Scheduler::new(store, ScheduleOptions::new(1.0)).unwrap();
    let stale = sched.select(&cams[0]).unwrap();
    let first = sched.frame(&cams[0]).unwrap();
    assert!(first.stats.loaded > 0);
    let late = sched.apply(&cams[0], stale).unwrap();
    assert_eq!(late.stats.loaded, 0);
    assert!(late.load.is_empty());
    assert_eq!(late.keep, first.load, "every block of the view is kept");
    assert_eq!(late.stats.resident_bytes, first.stats.resident_bytes);
    assert_eq!(late.stats.resident, first.stats.resident);
}

#[test]
fn prefetch_changes_sources_not_answers() {
    let s = &shipped()[0];
    let store = arc_store(views::fixture((s.dataset)(), &BuildOptions::default()));
    let cams: Vec<Camera> = cameras_of(s).into_iter().take(120).collect();
    let plain = ScheduleOptions::new(1.0);
    let warm = ScheduleOptions {
        cache_radius: 1e9,
        prefetch: true,
        ..plain
    };
    let mut a = Scheduler::new(Arc::clone(&store), plain).unwrap();
    let mut b = Scheduler::new(store, warm).unwrap();
    let (mut hits, mut loaded) = (0, 0);
    for (i, cam) in cams.iter().enumerate() {
        let fa = a.frame(cam).unwrap();
        let fb = b.frame(cam).unwrap();
        assert_eq!(
            (&fa.load, &fa.keep, &fa.evict),
            (&fb.load, &fb.keep, &fb.evict)
        );
        for id in &fb.load {
            assert_eq!(a.payload(id), b.payload(id));
        }
        if i >= 2 {
            hits += fb.stats.prefetch_hits;
            loaded += fb.stats.loaded;
        }
        b.wait_prefetch();
    }
    // The path is straight at constant speed: the extrapolated camera is the next one.
    assert!(loaded > 0);
    assert_eq!(
        hits, loaded,
        "every load after the second frame was prefetched"
    );
}

#[test]
fn the_memory_area_keeps_what_left_the_view_within_the_budget() {
    let s = &shipped()[1]; // orbit
    let store = arc_store(views::fixture((s.dataset)(), &BuildOptions::default()));
    let mut cams: Vec<Camera> = cameras_of(s).into_iter().take(90).collect();
    let back: Vec<Camera> = cams.iter().rev().copied().collect();
    cams.extend(back);
    let keep_all = ScheduleOptions {
        memory_radius: 1e9,
        ..ScheduleOptions::new(1.0)
    };
    let mut sched = Scheduler::new(Arc::clone(&store), keep_all).unwrap();
    for (i, cam) in cams.iter().enumerate() {
        let frame = sched.frame(cam).unwrap();
        if i >= 90 {
            assert!(
                frame.load.is_empty(),
                "frame {i}: returning along the path reloads"
            );
            assert!(frame.evict.is_empty());
        }
    }
    let budget = 2 << 20;
    let tight = ScheduleOptions {
        memory_budget: budget,
        ..keep_all
    };
    let mut sched = Scheduler::new(store, tight).unwrap();
    for cam in &cams {
        let frame = sched.frame(cam).unwrap();
        let visible_bytes: u64 = sched
            .last_scene()
            .unwrap()
            .blocks
            .iter()
            .map(|b| u64::from(b.payload.len))
            .sum();
        assert!(frame.stats.resident_bytes <= budget.max(visible_bytes));
    }
}
