//! Cold scenes over a network (issues 17 and 44, step 7): fmrh against a COG read by GDAL's
//! `/vsicurl/`. The same nginx serves both, behind a proxy on 127.0.0.1 that adds a round
//! trip time to every request (RTT 0, 20, 50 and 100 ms) and, in half the runs, caps the
//! link at 50 Mbit/s (shared by every connection, as one link is); the same cameras at
//! tau = 1 and 4 px are answered by each.
//!
//! **fmrh** opens the container by URL (one round: the commit slots and the file's last
//! 36 KiB, which hold the header, the directory, the top of the tree and the tables' roots in
//! a fresh file, 6.2 and later), schedules the view-dependent scene and loads its blocks, cold (a fresh
//! open each run). Its request plan (requests, bytes, rounds) comes from the source's
//! counters; nginx's access log confirms the requests and bytes.
//!
//! **The COG** (DEFLATE, predictor, overviews, 512² tiles: `benches/common/cog.rs`) is read
//! by GDAL itself (`benches/remote/cog_read.py`, Python bindings): open the URL, then
//! `ReadBlock` each tile that the COG reader of `scenes_vs_cog` chooses for the camera, a
//! tile being chosen when its *measured* error (against the source) covers at most tau
//! pixels, as fmrh's nodes are. So both answers meet tau; each one's largest screen-space
//! error is printed beside it. Requests and bytes of the COG are nginx's access log lines
//! and `$body_bytes_sent`.
//!
//! **Before** (optional): with `FMRH_REMOTE_BEFORE=DIR`, each DEM's container as an older
//! fmrh built it (`DIR/<dem>.fmrh`, e.g. a 6.2 file, whose residuals pco codes) is read the
//! same way in the same run, in rows marked `before` (today's build: `now`).
//!
//! Times are wall-clock, cold, the median of three runs, open included.
//!
//! `cargo bench --bench remote` (needs nginx, gdal-bin and python3-gdal; the large DEMs
//! need `../shared/data`). With `/tmp/fmrh-scale/mosaic` (made by `bash
//! benches/dataset/run.sh`), the 64-tile mosaic dataset is read by URL as well; `cargo bench
//! --bench remote -- mosaic` reads it alone, `-- quick` only RTT 0 and 100 ms without the
//! cap.

#[path = "../common/cog.rs"]
mod cog;
#[path = "../common/dems.rs"]
mod dems;
#[path = "../../tests/common/servers.rs"]
mod servers;

use std::io::{Read, Write};
use std::net::{TcpListener, TcpStream};
use std::path::Path;
use std::process::Command;
use std::sync::atomic::{AtomicU64, Ordering};
use std::sync::{Arc, Mutex};
use std::time::{Duration, Instant};

use cog::{cog_scene, make_cog};
use fmrh::scene::{load_blocks, Camera, SceneOptions, Terrain, TerrainFrame, WorldFrame};
use fmrh::store::RequestStats;
use fmrh::store::Store;

/// A TCP proxy in front of `upstream` that waits `latency` before passing on each chunk a
/// client sends (a request), as a round trip to a distant server would, and, when a rate
/// is set, sends the answers no faster than that many bytes a second over all connections
/// together (one shared link).
struct DelayProxy {
    port: u16,
    latency_ms: Arc<AtomicU64>,
    rate: Arc<AtomicU64>,
}

/// When the shared link is next free to send.
type Link = Arc<Mutex<Instant>>;

/// Copies `from` to `to` in chunks of at most `chunk` bytes, calling `before` with each
/// chunk's length before writing it, until either side closes; then closes `to`'s writing.
fn pump(mut from: TcpStream, mut to: TcpStream, chunk: usize, mut before: impl FnMut(usize)) {
    let mut buf = vec![0u8; chunk];
    loop {
        match from.read(&mut buf) {
            Ok(0) | Err(_) => break,
            Ok(n) => {
                before(n);
                if to.write_all(&buf[..n]).is_err() {
                    break;
                }
            }
        }
    }
    let _ = to.shutdown(std::net::Shutdown::Write);
}

impl DelayProxy {
    fn start(upstream: u16) -> DelayProxy {
        let listener = TcpListener::bind("127.0.0.1:0").expect("bind");
        let port = listener.local_addr().expect("addr").port();
        let latency_ms = Arc::new(AtomicU64::new(0));
        let rate = Arc::new(AtomicU64::new(0));
        let link: Link = Arc::new(Mutex::new(Instant::now()));
        let (latency, cap) = (Arc::clone(&latency_ms), Arc::clone(&rate));
        std::thread::spawn(move || {
            for client in listener.incoming() {
                let Ok(client) = client else { continue };
                let Ok(server) = TcpStream::connect(("127.0.0.1", upstream)) else {
                    continue;
                };
                let _ = client.set_nodelay(true);
                let _ = server.set_nodelay(true);
                let latency = Arc::clone(&latency);
                let (c_read, s_write) = (client.try_clone().unwrap(), server.try_clone().unwrap());
                // Requests: each chunk a client sends waits the latency.
                std::thread::spawn(move || {
                    pump(c_read, s_write, 64 << 10, |_| {
                        let ms = latency.load(Ordering::Relaxed);
                        if ms > 0 {
                            std::thread::sleep(Duration::from_millis(ms));
                        }
                    })
                });
                // Answers: each chunk waits for its share of the shared link.
                let (cap, link) = (Arc::clone(&cap), Arc::clone(&link));
                std::thread::spawn(move || {
                    pump(server, client, 16 << 10, |n| {
                        let rate = cap.load(Ordering::Relaxed);
                        if rate > 0 {
                            // Reserve the link for n bytes after whatever is queued.
                            let done = {
                                let mut free = link.lock().unwrap();
                                let start = (*free).max(Instant::now());
                                *free = start + Duration::from_secs_f64(n as f64 / rate as f64);
                                *free
                            };
                            std::thread::sleep(done.saturating_duration_since(Instant::now()));
                        }
                    })
                });
            }
        });
        DelayProxy {
            port,
            latency_ms,
            rate,
        }
    }

    fn set_latency(&self, ms: u64) {
        self.latency_ms.store(ms, Ordering::Relaxed);
    }

    /// Caps the link at `bytes_per_second` (0: no cap).
    fn set_rate(&self, bytes_per_second: u64) {
        self.rate.store(bytes_per_second, Ordering::Relaxed);
    }

    fn url(&self, rel: &str) -> String {
        format!("http://127.0.0.1:{}/{rel}", self.port)
    }
}

fn median(mut v: Vec<f64>) -> f64 {
    v.sort_by(f64::total_cmp);
    v[v.len() / 2]
}

/// One cold fmrh scene by URL: the open's and the scene's request plans, the blocks'
/// largest screen-space error, and the seconds it took.
fn fmrh_scene(
    url: &str,
    cam: &Camera,
    spacing: [f64; 2],
    tau: f64,
) -> (RequestStats, RequestStats, f64, f64) {
    let t = Instant::now();
    let store = Store::open_url(url).expect("opens by URL");
    let open = store.source().request_stats();
    let terrain = Terrain::with_spacing(&store, Some(spacing)).expect("terrain");
    let scene = terrain.scene(cam, &SceneOptions::new(tau)).expect("scene");
    load_blocks(&store, &scene.blocks, 0).expect("loads");
    let secs = t.elapsed().as_secs_f64();
    let scene_plan = store.source().request_stats().since(&open);
    (open, scene_plan, scene.stats.max_screen_error, secs)
}

/// One cold COG read by GDAL: seconds (from the script).
fn cog_read(url: &str, tiles: &[(usize, usize, usize)]) -> f64 {
    let script = Path::new(env!("CARGO_MANIFEST_DIR")).join("benches/remote/cog_read.py");
    let list: Vec<[usize; 3]> = tiles.iter().map(|&(l, x, y)| [l, x, y]).collect();
    let out = Command::new("/usr/bin/python3")
        .arg(script)
        .arg(url)
        .arg(serde_json::to_string(&list).expect("json"))
        .output()
        .expect("python3 runs (python3-gdal)");
    assert!(
        out.status.success(),
        "cog_read.py: {}",
        String::from_utf8_lossy(&out.stderr)
    );
    let v: serde_json::Value = serde_json::from_slice(&out.stdout).expect("JSON");
    v["seconds"].as_f64().expect("seconds")
}

/// The 64-tile mosaic (issue 16) by URL, when it was made: a cold tau = 1 scene from the
/// low and the high camera of `dataset_scale`, its request plan and time, beside the same
/// scene from the local directory (bytes read).
fn mosaic(served: &Path, proxy: &DelayProxy) {
    let dir = std::env::var_os("FMRH_SCALE_DATASET")
        .map(std::path::PathBuf::from)
        .unwrap_or_else(|| "/tmp/fmrh-scale/ds".into());
    if !dir.join("MANIFEST").is_file() {
        println!(
            "\n(no mosaic at {}: `bash benches/dataset/run.sh` makes it)",
            dir.display()
        );
        return;
    }
    std::os::unix::fs::symlink(&dir, served.join("mosaic")).expect("symlink");
    let local = fmrh::dataset::Dataset::open(&dir).expect("opens");
    let grid = local.grid();
    let [dx, dy] = local.spacing_m().unwrap_or([1.0, 1.0]);
    let (w, h) = ((grid.col1 as f64) * dx, (grid.row1 as f64) * dy);
    let cams = [
        (
            "low",
            Camera::looking_at(
                glam::DVec3::new(0.5 * w, 0.5 * h, 1500.0),
                glam::DVec3::new(0.5 * w + 30000.0, 0.5 * h + 10000.0, 0.0),
            ),
        ),
        (
            "high",
            Camera::looking_at(
                glam::DVec3::new(0.5 * w, 1.25 * h, 0.45 * w),
                glam::DVec3::new(0.5 * w, 0.5 * h, 0.0),
            ),
        ),
    ];
    println!("\n| mosaic camera | latency | tiles met | open req / KB / rounds | scene req / KB / rounds | local read KB | px | ms |");
    println!("|---|---|---|---|---|---|---|---|");
    for (name, cam) in cams {
        let ds = fmrh::dataset::Dataset::open(&dir).expect("opens");
        let scene = ds
            .scene(&cam, &SceneOptions::new(1.0), None)
            .expect("scene");
        let local_bytes = scene
            .tiles
            .iter()
            .fold(ds.open_reads(), |a, t| a.plus(&t.reads))
            .plus(&ds.load(&scene).expect("loads"))
            .bytes();
        for latency in [0u64, 20] {
            proxy.set_latency(latency);
            let mut times = Vec::new();
            let mut last = None;
            for _ in 0..3 {
                let t = Instant::now();
                let remote = fmrh::dataset::Dataset::open(Path::new(&proxy.url("mosaic/")))
                    .expect("opens by URL");
                let open = remote.request_stats().expect("remote");
                let s = remote
                    .scene(&cam, &SceneOptions::new(1.0), None)
                    .expect("scene");
                remote.load(&s).expect("loads");
                times.push(t.elapsed().as_secs_f64());
                let plan = remote.request_stats().expect("remote").since(&open);
                assert_eq!(s.blocks.len(), scene.blocks.len());
                last = Some((open, plan, s.tiles.len(), s.stats.max_screen_error));
            }
            let (open, plan, tiles, px) = last.expect("ran");
            println!(
                "| {name} | {latency} ms | {tiles} | {} / {:.1} / {} | {} / {:.1} / {} | {:.1} | {px:.2} | {:.1} |",
                open.requests,
                open.bytes as f64 / 1e3,
                open.rounds,
                plan.requests,
                plan.bytes as f64 / 1e3,
                plan.rounds,
                local_bytes as f64 / 1e3,
                median(times) * 1e3
            );
        }
    }
}

/// 50 Mbit/s, in bytes a second.
const CAP_50_MBIT: u64 = 50_000_000 / 8;

fn main() {
    // `cargo bench --bench remote -- mosaic` runs the mosaic section alone; `-- quick` the
    // single files at RTT 0 and 100 ms without the cap.
    let args: Vec<String> = std::env::args().skip(1).collect();
    let only_mosaic = args.iter().any(|a| a == "mosaic");
    let quick = args.iter().any(|a| a == "quick");
    let served = tempfile::tempdir().expect("temp dir");
    let before = std::env::var_os("FMRH_REMOTE_BEFORE").map(std::path::PathBuf::from);
    let mut cases = Vec::new();
    for dem in dems::dems().into_iter().filter(|_| !only_mosaic) {
        let Some(cog) = make_cog(served.path(), dem.name, &dem.source) else {
            continue;
        };
        let path = dem.build(served.path());
        let mut files = vec![("now", path)];
        if let Some(dir) = &before {
            let old = dir.join(format!("{}.fmrh", dem.name));
            if old.is_file() {
                let name = format!("{}-before.fmrh", dem.name);
                std::fs::copy(&old, served.path().join(&name)).expect("copies");
                files.push(("before", served.path().join(name)));
            } else {
                eprintln!("(no {}: no before row for {})", old.display(), dem.name);
            }
        }
        cases.push((dem, cog, files));
    }
    let nginx = servers::Nginx::start(served.path());
    let proxy = DelayProxy::start(nginx.port);
    if only_mosaic {
        mosaic(served.path(), &proxy);
        return;
    }
    let links: Vec<(u64, u64)> = if quick {
        vec![(0, 0), (100, 0)]
    } else {
        [0u64, 20, 50, 100]
            .into_iter()
            .flat_map(|rtt| [(rtt, 0), (rtt, CAP_50_MBIT)])
            .collect()
    };
    println!("| DEM | camera | tau | RTT | cap | file | fmrh open req / KB / rounds | fmrh scene req / KB / rounds | fmrh px | fmrh ms | COG req | COG KB | COG px | COG ms | fmrh/COG time | fmrh/COG bytes |");
    println!("|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|");
    let mut ratios: Vec<(String, f64)> = Vec::new();
    for (dem, cog, files) in &cases {
        let cog_name = cog.path.file_name().and_then(|n| n.to_str()).expect("name");
        let frame = WorldFrame::new(Some(dem.spacing));
        for (cam_name, cam) in dem.cameras() {
            let view = cam.view().expect("camera");
            for tau in [1.0, 4.0] {
                let (tiles, cog_px) = cog_scene(cog, TerrainFrame::Flat(frame), &view, tau);
                let tiles: Vec<(usize, usize, usize)> = tiles
                    .iter()
                    .map(|&(l, t)| {
                        let (tx_n, _) = cog.levels[l].tiles_across();
                        (l, t % tx_n, t / tx_n)
                    })
                    .collect();
                for &(rtt, rate) in &links {
                    proxy.set_latency(rtt);
                    proxy.set_rate(rate);
                    let mut cog_times = Vec::new();
                    let mut cog_log = (0, 0);
                    for _ in 0..3 {
                        let from = nginx.log().len();
                        cog_times.push(cog_read(&proxy.url(cog_name), &tiles));
                        cog_log = nginx.requests_since(from);
                    }
                    let cog_ms = median(cog_times) * 1e3;
                    for (version, path) in files {
                        let name = path.file_name().and_then(|n| n.to_str()).expect("name");
                        let mut fmrh_times = Vec::new();
                        let mut fmrh_last = None;
                        let mut fmrh_log = (0, 0);
                        for _ in 0..3 {
                            let from = nginx.log().len();
                            let r = fmrh_scene(&proxy.url(name), &cam, dem.spacing, tau);
                            fmrh_log = nginx.requests_since(from);
                            fmrh_times.push(r.3);
                            fmrh_last = Some(r);
                        }
                        let (open, scene, px, _) = fmrh_last.expect("ran");
                        assert_eq!(
                            fmrh_log.0,
                            open.requests + scene.requests,
                            "nginx saw what fmrh counted"
                        );
                        let fmrh_ms = median(fmrh_times) * 1e3;
                        let cap = if rate > 0 { "50 Mbit/s" } else { "none" };
                        println!(
                            "| {} | {cam_name} | {tau} | {rtt} ms | {cap} | {version} | {} / {:.1} / {} | {} / {:.1} / {} | {px:.2} | {fmrh_ms:.1} | {} | {:.1} | {cog_px:.2} | {cog_ms:.1} | {:.2} | {:.2} |",
                            dem.name,
                            open.requests,
                            open.bytes as f64 / 1e3,
                            open.rounds,
                            scene.requests,
                            scene.bytes as f64 / 1e3,
                            scene.rounds,
                            cog_log.0,
                            cog_log.1 as f64 / 1e3,
                            fmrh_ms / cog_ms,
                            fmrh_log.1 as f64 / cog_log.1.max(1) as f64,
                        );
                        ratios.push((format!("{version} {rtt} {cap}"), fmrh_ms / cog_ms));
                    }
                }
            }
        }
    }
    // Per file version, RTT and cap: the median and worst time ratio over every DEM,
    // camera and tau.
    println!("\n| file | RTT | cap | scenes | fmrh/COG time, median | worst | cells fmrh faster |");
    println!("|---|---|---|---|---|---|---|");
    let mut keys: Vec<String> = ratios.iter().map(|(k, _)| k.clone()).collect();
    keys.sort();
    keys.dedup();
    for key in keys {
        let mut v: Vec<f64> = ratios
            .iter()
            .filter(|(k, _)| *k == key)
            .map(|&(_, r)| r)
            .collect();
        v.sort_by(f64::total_cmp);
        let faster = v.iter().filter(|&&r| r < 1.0).count();
        let mut parts = key.splitn(3, ' ');
        let (version, rtt, cap) = (
            parts.next().unwrap_or(""),
            parts.next().unwrap_or(""),
            parts.next().unwrap_or(""),
        );
        println!(
            "| {version} | {rtt} ms | {cap} | {} | {:.2} | {:.2} | {faster} of {} |",
            v.len(),
            v[v.len() / 2],
            v[v.len() - 1],
            v.len()
        );
    }
    if !quick {
        proxy.set_rate(0);
        mosaic(served.path(), &proxy);
    }
}
