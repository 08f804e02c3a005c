//! `fmrh serve`'s Cesium terrain under load: N concurrent clients (keep-alive HTTP/1.1,
//! Cesium's `Accept` and gzip) fetching the tiles a fly-over asks for, on the bundled SRTM
//! tile N43E006. Prints, for 1, 4, 16 and 64 clients: tiles a second, p50 and p99
//! latency, the server's CPU seconds and its peak memory, first for cold tiles (asked as
//! soon as a fresh server listens: every tile cut on the fly but those its warming, which
//! starts with it, has cut already), then for repeated tiles (the same fly-over again,
//! from the cache), then cold again on another fresh server once it says it has cut its
//! coarse tiles ahead (`fmrh: warmed ...`; a build that does not warm has no such row).
//!
//! The fly-over: a camera path across the tile from south-west to north-east, at each of 40
//! stops asking the tiles a Cesium globe asks near the ground: the deepest level's 3 × 3
//! around the camera, and the coarser levels' tiles above them (as Cesium walks from the
//! roots). Run: `cargo bench --bench terrain_load`. To compare two builds side by side in
//! one run, name the other's binary in `FMRH_BASELINE` (for example a worktree of an older
//! commit built into its own target directory): each row is then measured for both, the
//! baseline first, each on a fresh server.

use std::collections::BTreeSet;
use std::io::{BufRead, BufReader, Read, Write};
use std::net::TcpStream;
use std::path::Path;
use std::process::{Child, Command, Stdio};
use std::sync::atomic::{AtomicUsize, Ordering};
use std::sync::Arc;
use std::time::{Duration, Instant};

const ACCEPT: &str = "application/vnd.quantized-mesh;extensions=octvertexnormals-watermask-metadata,application/octet-stream;q=0.9,*/*;q=0.01";

struct Server {
    child: Child,
    address: String,
    /// The server's standard output after its first line, a line at a time (read on a
    /// thread of its own, so the server never blocks on a full pipe).
    lines: std::sync::mpsc::Receiver<String>,
}

impl Server {
    fn start(binary: &str, path: &Path) -> Server {
        let mut child = Command::new(binary)
            .args(["serve", path.to_str().unwrap(), "--port", "0"])
            .stdout(Stdio::piped())
            .stderr(Stdio::null())
            .spawn()
            .expect("fmrh serve starts");
        let stdout = BufReader::new(child.stdout.take().unwrap());
        let (send, lines) = std::sync::mpsc::channel();
        std::thread::spawn(move || {
            for line in stdout.lines().map_while(Result::ok) {
                if send.send(line).is_err() {
                    break;
                }
            }
        });
        let line = lines.recv().expect("fmrh serve prints its address");
        let address = line
            .trim()
            .trim_start_matches("fmrh: serving on http://")
            .trim_end_matches('/')
            .to_string();
        Server {
            child,
            address,
            lines,
        }
    }

    /// Waits (at most a minute) for the server to say it has cut its coarse tiles ahead:
    /// the line, or `None` (a build that does not warm says nothing).
    fn warmed(&self) -> Option<String> {
        let until = Instant::now() + Duration::from_secs(60);
        while let Some(left) = until.checked_duration_since(Instant::now()) {
            match self.lines.recv_timeout(left) {
                Ok(line) if line.starts_with("fmrh: warmed") => return Some(line),
                Ok(_) => continue,
                Err(_) => return None,
            }
        }
        None
    }

    /// CPU seconds (user + system) and peak resident memory (MiB) so far.
    fn usage(&self) -> (f64, f64) {
        let pid = self.child.id();
        let stat = std::fs::read_to_string(format!("/proc/{pid}/stat")).unwrap_or_default();
        let fields: Vec<&str> = stat
            .rsplit_once(')')
            .map_or(Vec::new(), |(_, r)| r.split_whitespace().collect());
        let ticks = |i: usize| {
            fields
                .get(i)
                .and_then(|v| v.parse::<f64>().ok())
                .unwrap_or(0.0)
        };
        // utime and stime are fields 14 and 15 (1-based); after the `)` they are 12 and 13.
        let cpu = (ticks(11) + ticks(12)) / 100.0;
        let status = std::fs::read_to_string(format!("/proc/{pid}/status")).unwrap_or_default();
        let hwm = status
            .lines()
            .find(|l| l.starts_with("VmHWM:"))
            .and_then(|l| l.split_whitespace().nth(1))
            .and_then(|v| v.parse::<f64>().ok())
            .unwrap_or(0.0)
            / 1024.0;
        (cpu, hwm)
    }
}

impl Drop for Server {
    fn drop(&mut self) {
        let _ = self.child.kill();
        let _ = self.child.wait();
    }
}

/// One keep-alive connection.
struct Client {
    reader: BufReader<TcpStream>,
    address: String,
}

impl Client {
    fn new(address: &str) -> Client {
        let stream = TcpStream::connect(address).expect("connect to fmrh serve");
        stream.set_nodelay(true).unwrap();
        stream
            .set_read_timeout(Some(Duration::from_secs(60)))
            .unwrap();
        Client {
            reader: BufReader::new(stream),
            address: address.to_string(),
        }
    }

    /// `GET path`: the status and the body's length; status 0 when the connection failed
    /// (a server past its connection limits answers 503 and closes: the next request opens
    /// a new connection).
    fn get(&mut self, path: &str) -> (u16, usize) {
        match self.try_get(path) {
            Ok(r) => r,
            Err(_) => {
                if let Ok(stream) = TcpStream::connect(&self.address) {
                    let _ = stream.set_nodelay(true);
                    let _ = stream.set_read_timeout(Some(Duration::from_secs(60)));
                    self.reader = BufReader::new(stream);
                }
                (0, 0)
            }
        }
    }

    fn try_get(&mut self, path: &str) -> std::io::Result<(u16, usize)> {
        let request = format!(
            "GET {path} HTTP/1.1\r\nHost: {}\r\nAccept: {ACCEPT}\r\nAccept-Encoding: gzip\r\n\r\n",
            self.address
        );
        self.reader.get_mut().write_all(request.as_bytes())?;
        let mut status = 0u16;
        let mut length = 0usize;
        let mut line = String::new();
        loop {
            line.clear();
            if self.reader.read_line(&mut line)? == 0 {
                return Err(std::io::ErrorKind::UnexpectedEof.into());
            }
            let l = line.trim_end();
            if l.is_empty() {
                break;
            }
            if let Some(s) = l.strip_prefix("HTTP/1.1 ") {
                status = s[..3].parse().unwrap_or(0);
            }
            if let Some((k, v)) = l.split_once(':') {
                if k.eq_ignore_ascii_case("content-length") {
                    length = v.trim().parse().unwrap_or(0);
                }
            }
        }
        let mut body = vec![0u8; length];
        self.reader.read_exact(&mut body)?;
        Ok((status, length))
    }
}

/// The tiles of the fly-over, in the order asked.
fn fly_over(layer: &serde_json::Value) -> Vec<(u32, u32, u32)> {
    let maxzoom = layer["maxzoom"].as_u64().unwrap() as u32;
    let b: Vec<f64> = layer["bounds"]
        .as_array()
        .unwrap()
        .iter()
        .map(|v| v.as_f64().unwrap())
        .collect();
    let mut seen = BTreeSet::new();
    let mut out = Vec::new();
    for stop in 0..40 {
        let t = (f64::from(stop) + 0.5) / 40.0;
        let (lon, lat) = (b[0] + (b[2] - b[0]) * t, b[1] + (b[3] - b[1]) * t);
        for z in 0..=maxzoom {
            let d = 180.0 / f64::from(1u32 << z);
            let (x, y) = (((lon + 180.0) / d) as i64, ((lat + 90.0) / d) as i64);
            let reach = if z == maxzoom { 1 } else { 0 };
            for dy in -reach..=reach {
                for dx in -reach..=reach {
                    let tile = (z, (x + dx) as u32, (y + dy) as u32);
                    if seen.insert(tile) {
                        out.push(tile);
                    }
                }
            }
        }
    }
    out
}

/// Runs `clients` clients over `tiles` (each takes the next tile in turn): per-request
/// latencies (ms), the wall time, and how many answers were not 200 or 404.
fn run(
    address: &str,
    tiles: &[(u32, u32, u32)],
    name: &str,
    clients: usize,
) -> (Vec<f64>, f64, usize) {
    let next = Arc::new(AtomicUsize::new(0));
    let tiles = Arc::new(tiles.to_vec());
    let started = Instant::now();
    let handles: Vec<_> = (0..clients)
        .map(|_| {
            let (next, tiles, address, name) = (
                next.clone(),
                tiles.clone(),
                address.to_string(),
                name.to_string(),
            );
            std::thread::spawn(move || {
                let mut client = Client::new(&address);
                let mut latencies = Vec::new();
                let mut bad = 0;
                loop {
                    let i = next.fetch_add(1, Ordering::Relaxed);
                    let Some(&(z, x, y)) = tiles.get(i) else {
                        break;
                    };
                    let t = Instant::now();
                    let (status, _) = client.get(&format!("/{name}/{z}/{x}/{y}.terrain"));
                    latencies.push(t.elapsed().as_secs_f64() * 1e3);
                    if status != 200 && status != 404 {
                        bad += 1;
                    }
                }
                (latencies, bad)
            })
        })
        .collect();
    let mut all = Vec::new();
    let mut bad = 0;
    for h in handles {
        let (l, b) = h.join().unwrap();
        all.extend(l);
        bad += b;
    }
    (all, started.elapsed().as_secs_f64(), bad)
}

fn percentile(sorted: &[f64], p: f64) -> f64 {
    sorted[((sorted.len() - 1) as f64 * p).round() as usize]
}

fn main() {
    let dir = tempfile::tempdir().unwrap();
    let dem = Path::new(env!("CARGO_MANIFEST_DIR")).join("data/srtm3-pyhgtmap/N43E006.hgt.gz");
    let container = dir.path().join("n43.fmrh");
    let built = Command::new(env!("CARGO_BIN_EXE_fmrh"))
        .args([
            "build",
            "-q",
            dem.to_str().unwrap(),
            "-o",
            container.to_str().unwrap(),
        ])
        .status()
        .unwrap();
    assert!(built.success());
    let name = "n43.fmrh";
    println!("fmrh serve, Cesium terrain, SRTM3 N43E006 (bundled); 2-core machine");
    let mut servers = Vec::new();
    if let Ok(baseline) = std::env::var("FMRH_BASELINE") {
        servers.push(("baseline", baseline));
    }
    servers.push(("this build", env!("CARGO_BIN_EXE_fmrh").to_string()));
    println!("| server | tiles | clients | tiles/s | p50 ms | p99 ms | server CPU s | peak RSS MiB | refused or failed |");
    println!("|---|---|---|---|---|---|---|---|---|");
    for clients in [1usize, 4, 16, 64] {
        for (who, binary) in &servers {
            load(who, binary, &container, name, clients);
        }
    }
}

/// The rows of `clients` clients on a fresh server (`binary`): cold tiles asked at once
/// (the server's warming, if it warms, racing them) then repeated; and, on another fresh
/// server that says it warmed its coarse tiles, cold tiles asked after that.
fn load(who: &str, binary: &str, container: &Path, name: &str, clients: usize) {
    fly(who, binary, container, name, clients, false);
    fly(who, binary, container, name, clients, true);
}

fn fly(who: &str, binary: &str, container: &Path, name: &str, clients: usize, warmed: bool) {
    let server = Server::start(binary, container);
    if warmed && server.warmed().is_none() {
        return;
    }
    let mut c = Client::new(&server.address);
    let layer = {
        let request = format!(
            "GET /{name}/layer.json HTTP/1.1\r\nHost: {}\r\n\r\n",
            server.address
        );
        c.reader.get_mut().write_all(request.as_bytes()).unwrap();
        let mut head = String::new();
        let mut length = 0;
        loop {
            head.clear();
            c.reader.read_line(&mut head).unwrap();
            if head.trim().is_empty() {
                break;
            }
            if let Some(v) = head.to_ascii_lowercase().strip_prefix("content-length:") {
                length = v.trim().parse().unwrap();
            }
        }
        let mut body = vec![0u8; length];
        c.reader.read_exact(&mut body).unwrap();
        serde_json::from_slice::<serde_json::Value>(&body).unwrap()
    };
    drop(c);
    let tiles = fly_over(&layer);
    let phases: &[(&str, usize)] = if warmed {
        &[("cold after warming", 1)]
    } else {
        &[("cold", 1), ("repeated", 20)]
    };
    for &(kind, rounds) in phases {
        let (cpu0, _) = server.usage();
        let mut latencies = Vec::new();
        let mut wall = 0.0;
        let mut bad = 0;
        for _ in 0..rounds {
            let (l, w, b) = run(&server.address, &tiles, name, clients);
            latencies.extend(l);
            wall += w;
            bad += b;
        }
        let (cpu1, rss) = server.usage();
        latencies.sort_by(f64::total_cmp);
        println!(
                "| {who} | {kind} ({} tiles) | {clients} | {:.0} | {:.2} | {:.2} | {:.2} | {:.0} | {bad} |",
                tiles.len(),
                latencies.len() as f64 / wall,
                percentile(&latencies, 0.5),
                percentile(&latencies, 0.99),
                cpu1 - cpu0,
                rss
            );
    }
}
