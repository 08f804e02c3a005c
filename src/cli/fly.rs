//! `fmrh fly`: replays a camera path through the frame scheduler and reports, per frame,
//! what was loaded, evicted and kept resident (seed 000 Table 2).

use std::path::PathBuf;
use std::process::ExitCode;
use std::sync::Arc;

use serde::Serialize;

use crate::scene::{path, Camera, FrameStats, ScheduleOptions, Scheduler};
use crate::store::ReadStats;
use crate::store::Store;
use crate::Error;

use super::args::ViewArgs;

#[derive(clap::Args)]
pub struct FlyArgs {
    /// The container, or a dataset's directory (the path in the dataset's world frame).
    file: PathBuf,
    /// The camera path: CSV, one camera a line, eye_x,eye_y,eye_z,target_x,target_y,target_z
    /// (with --geo: latitude,longitude,height,heading,pitch).
    #[arg(long)]
    path: PathBuf,
    /// The path's cameras are on the globe (latitude and longitude in degrees, height above
    /// the WGS 84 ellipsoid in metres, heading clockwise from north, pitch above the
    /// horizontal), and so are the samples (a geographic container or dataset).
    #[arg(long)]
    geo: bool,
    #[command(flatten)]
    view: ViewArgs,
    /// Metres: blocks that leave the view but stay this close remain resident.
    #[arg(long, default_value_t = 0.0)]
    memory_radius: f64,
    /// Metres: the prefetcher warms predicted blocks this close.
    #[arg(long, default_value_t = 0.0)]
    cache_radius: f64,
    /// Resident bytes beyond which out-of-view blocks are evicted, least recently seen first.
    #[arg(long, default_value_t = 256 << 20)]
    budget: u64,
    /// Run the prefetch thread (with --cache-radius).
    #[arg(long)]
    prefetch: bool,
    /// Print every frame as JSON.
    #[arg(long)]
    pub json: bool,
}

#[derive(Serialize)]
struct FrameReport {
    frame: u64,
    #[serde(flatten)]
    stats: FrameStats,
}

#[derive(Serialize)]
struct Report {
    frames: Vec<FrameReport>,
    /// Over every frame after the first: mean loaded blocks / the first frame's.
    later_load_fraction: Option<f64>,
    /// What opening read, and what the whole path read after it (index and node pages once
    /// each through the page cache, payloads in coalesced runs; prefetch included).
    reads: Reads,
    /// A remote container: what the whole path asked its server for, opening included.
    #[serde(skip_serializing_if = "Option::is_none")]
    requests: Option<crate::store::RequestStats>,
}

#[derive(Serialize)]
struct Reads {
    open: ReadStats,
    path: ReadStats,
}

/// Runs `fmrh fly`.
pub fn run(args: &FlyArgs) -> Result<ExitCode, Error> {
    let text = std::fs::read_to_string(&args.path).map_err(|e| Error::io(&args.path, e))?;
    let template = Camera {
        fov_y_deg: args.view.fov,
        viewport: args.view.viewport()?,
        ..Camera::looking_at(glam::DVec3::ZERO, glam::DVec3::X)
    };
    args.view.flat_spacing_only(args.geo)?;
    let cameras = if args.geo {
        path::parse_geo(&text, &template)?
    } else {
        path::parse(&text, &template)?
    };
    if super::is_dataset(&args.file)? {
        return replay_dataset(args, &cameras);
    }
    if let Some(url) = super::url_of(&args.file) {
        #[cfg(feature = "remote")]
        return replay(args, Arc::new(Store::open_url(url)?), &cameras);
        #[cfg(not(feature = "remote"))]
        return Err(super::no_remote(url));
    }
    if args.view.mmap && crate::store::lock::SUPPORTED {
        // SAFETY: the --mmap contract, stated in its help: the state is registered, so fmrh
        // writers leave its pages alone, and no other tool modifies the file meanwhile.
        let store = unsafe { Store::open_mapped(&args.file) }?;
        replay(args, Arc::new(store), &cameras)
    } else {
        replay(args, Arc::new(Store::open(&args.file)?), &cameras)
    }
}

fn replay<S: crate::store::Source + 'static>(
    args: &FlyArgs,
    store: Arc<Store<S>>,
    cameras: &[Camera],
) -> Result<ExitCode, Error> {
    let options = ScheduleOptions {
        scene: args.view.options(),
        memory_radius: args.memory_radius,
        cache_radius: args.cache_radius,
        memory_budget: args.budget,
        prefetch: args.prefetch,
        spacing_m: if args.geo {
            None
        } else {
            args.view.spacing(&store, &args.file)?
        },
        globe: args.geo,
        globe_frame: None,
    };
    let open = store.open_reads();
    let counted = Arc::clone(&store);
    let mut scheduler = Scheduler::new(store, options)?;
    let mut frames = Vec::with_capacity(cameras.len());
    for cam in cameras {
        let f = scheduler.frame(cam)?;
        frames.push(FrameReport {
            frame: f.index,
            stats: f.stats,
        });
    }
    let later_load_fraction = (frames.len() > 1 && frames[0].stats.loaded > 0).then(|| {
        let later: u64 = frames[1..].iter().map(|f| f.stats.loaded).sum();
        later as f64 / (frames.len() - 1) as f64 / frames[0].stats.loaded as f64
    });
    scheduler.wait_prefetch();
    let report = Report {
        frames,
        later_load_fraction,
        reads: Reads {
            open,
            path: counted.read_stats(),
        },
        requests: counted.source().request_stats(),
    };
    if args.json {
        super::print_json(&report)?;
    } else {
        print_text(&report);
    }
    Ok(ExitCode::SUCCESS)
}

/// `fmrh fly DIR`: the frames across tiles.
fn replay_dataset(args: &FlyArgs, cameras: &[Camera]) -> Result<ExitCode, Error> {
    let ds = crate::dataset::Dataset::open(&args.file)?;
    let options = ScheduleOptions {
        scene: args.view.options(),
        memory_radius: args.memory_radius,
        cache_radius: args.cache_radius,
        memory_budget: args.budget,
        prefetch: args.prefetch,
        spacing_m: args
            .view
            .spacing
            .as_deref()
            .map(super::args::parse_spacing)
            .transpose()?,
        globe: args.geo,
        globe_frame: None,
    };
    let mut scheduler = crate::dataset::DatasetScheduler::new(&ds, options)?;
    let mut frames = Vec::with_capacity(cameras.len());
    for cam in cameras {
        let f = scheduler.frame(cam)?;
        frames.push(FrameReport {
            frame: f.index,
            stats: f.stats,
        });
    }
    scheduler.wait_prefetch();
    let later_load_fraction = (frames.len() > 1 && frames[0].stats.loaded > 0).then(|| {
        let later: u64 = frames[1..].iter().map(|f| f.stats.loaded).sum();
        later as f64 / (frames.len() - 1) as f64 / frames[0].stats.loaded as f64
    });
    let report = Report {
        frames,
        later_load_fraction,
        reads: Reads {
            open: ds.open_reads(),
            path: scheduler.read_stats().plus(&ds.manifest_reads()),
        },
        requests: ds.request_stats(),
    };
    if args.json {
        super::print_json(&report)?;
    } else {
        print_text(&report);
        println!("tiles opened: {} of {}", ds.tiles_opened(), ds.tile_count());
    }
    Ok(ExitCode::SUCCESS)
}

fn print_text(r: &Report) {
    println!(
        "{:>6} {:>7} {:>7} {:>10} {:>11} {:>7} {:>8} {:>12} {:>9} {:>9} {:>8}",
        "frame",
        "visible",
        "loaded",
        "triangles",
        "bytes",
        "evicted",
        "resident",
        "res. bytes",
        "sched us",
        "load us",
        "prefetch"
    );
    for f in &r.frames {
        let s = &f.stats;
        println!(
            "{:>6} {:>7} {:>7} {:>10} {:>11} {:>7} {:>8} {:>12} {:>9.1} {:>9.1} {:>8}",
            f.frame,
            s.visible,
            s.loaded,
            s.loaded_triangles,
            s.loaded_bytes,
            s.evicted,
            s.resident,
            s.resident_bytes,
            s.schedule_ns as f64 / 1e3,
            s.load_ns as f64 / 1e3,
            s.prefetch_hits
        );
    }
    // The frames the table above numbers 0, 9, 99 and the last (seed 000's frames 1, 10, 100).
    println!("\nseed 000 Table 2 form: loaded triangles and schedule time");
    for i in [0usize, 9, 99, r.frames.len().saturating_sub(1)] {
        if let Some(f) = r.frames.get(i) {
            println!(
                "  frame {:>5}: {:>9} triangles, {:>8.1} us",
                f.frame,
                f.stats.loaded_triangles,
                (f.stats.schedule_ns + f.stats.load_ns) as f64 / 1e3
            );
        }
    }
    if let Some(x) = r.later_load_fraction {
        println!(
            "  frames after the first load on average {:.1}% of the first frame's blocks",
            100.0 * x
        );
    }
    let (o, p) = (&r.reads.open, &r.reads.path);
    println!(
        "
read: open {} calls, {} bytes; the path {} calls, {} metadata bytes, {} payload bytes",
        o.reads(),
        o.bytes(),
        p.reads(),
        p.metadata_bytes,
        p.payload_bytes
    );
    if let Some(q) = &r.requests {
        println!(
            "requests: {} requests, {} bytes, {} rounds ({} retries), opening included",
            q.requests, q.bytes, q.rounds, q.retries
        );
    }
}
