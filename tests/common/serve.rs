//! `fmrh serve` for the tests: started on a free port (it prints its address first), asked
//! with plain HTTP/1.0 over a socket (so nothing between the test and the server rewrites
//! a path or a header), and killed when dropped.

#![allow(dead_code)]

use std::io::{BufRead, BufReader, Read, Write};
use std::net::TcpStream;
use std::path::Path;
use std::process::{Child, Command, Stdio};

/// Puget Sound 1k (bundled) as a container `dir/ps1k.fmrh`, built as the README builds it.
pub fn puget(dir: &Path) -> std::path::PathBuf {
    let file = dir.join("ps1k.fmrh");
    let png = super::bundled_dir().join("puget-sound-1k/ps_height_1k.png");
    let out = super::fmrh(&[
        "build",
        png.to_str().unwrap(),
        "--z-scale",
        "0.1",
        "--spacing",
        "160",
        "-o",
        file.to_str().unwrap(),
    ]);
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    file
}

/// A running `fmrh serve`.
pub struct Served {
    child: Child,
    /// `host:port`.
    pub address: String,
    /// What it printed after its address, a line at a time.
    lines: std::sync::Mutex<std::sync::mpsc::Receiver<String>>,
}

impl Served {
    /// Serves `paths` on a free port of 127.0.0.1.
    pub fn start(paths: &[&Path]) -> Served {
        Served::start_with(paths, &[])
    }

    /// Serves `paths` on a free port of 127.0.0.1, with more arguments.
    pub fn start_with(paths: &[&Path], args: &[&str]) -> Served {
        let mut child = Command::new(env!("CARGO_BIN_EXE_fmrh"))
            .arg("serve")
            .args(paths)
            .args(["--port", "0"])
            .args(args)
            .stdout(Stdio::piped())
            .stderr(Stdio::inherit())
            .spawn()
            .expect("fmrh serve starts");
        let mut line = String::new();
        let stdout = child.stdout.take().expect("piped stdout");
        let mut reader = BufReader::new(stdout);
        reader
            .read_line(&mut line)
            .expect("fmrh serve prints its address");
        let address = line
            .trim()
            .strip_prefix("fmrh: serving on http://")
            .and_then(|a| a.strip_suffix('/'))
            .unwrap_or_else(|| panic!("unexpected first line from fmrh serve: {line:?}"))
            .to_string();
        // Keep reading its stdout, so it never blocks on a full pipe.
        let (send, lines) = std::sync::mpsc::channel();
        std::thread::spawn(move || {
            for line in reader.lines().map_while(Result::ok) {
                // Nobody listening: keep draining.
                let _ = send.send(line);
            }
        });
        Served {
            child,
            address,
            lines: std::sync::Mutex::new(lines),
        }
    }

    /// The next line the server prints that starts with `prefix` (the lines before it are
    /// passed over); panics after two minutes without one.
    pub fn wait_line(&self, prefix: &str) -> String {
        let lines = self.lines.lock().unwrap();
        let until = std::time::Instant::now() + std::time::Duration::from_secs(120);
        loop {
            let left = until
                .checked_duration_since(std::time::Instant::now())
                .unwrap_or_default();
            match lines.recv_timeout(left) {
                Ok(line) if line.starts_with(prefix) => return line,
                Ok(_) => {}
                Err(e) => panic!("fmrh serve printed no line starting {prefix:?}: {e}"),
            }
        }
    }

    /// `http://host:port`.
    pub fn base(&self) -> String {
        format!("http://{}", self.address)
    }

    /// `GET path` (or another method) with `headers`: the status, the headers (names in
    /// lower case) and the body.
    pub fn ask(&self, method: &str, path: &str, headers: &[(&str, &str)]) -> Answer {
        let mut stream = TcpStream::connect(&self.address).expect("connect to fmrh serve");
        let mut request = format!("{method} {path} HTTP/1.0\r\nHost: {}\r\n", self.address);
        for (k, v) in headers {
            request.push_str(&format!("{k}: {v}\r\n"));
        }
        request.push_str("\r\n");
        stream
            .write_all(request.as_bytes())
            .expect("send the request");
        let mut raw = Vec::new();
        stream.read_to_end(&mut raw).expect("read the answer");
        let split = raw
            .windows(4)
            .position(|w| w == b"\r\n\r\n")
            .expect("an answer with a head");
        let head = String::from_utf8(raw[..split].to_vec()).expect("an ASCII head");
        let mut lines = head.split("\r\n");
        let status: u16 = lines
            .next()
            .and_then(|l| l.split(' ').nth(1))
            .and_then(|s| s.parse().ok())
            .expect("a status line");
        let headers = lines
            .filter_map(|l| l.split_once(':'))
            .map(|(k, v)| (k.trim().to_ascii_lowercase(), v.trim().to_string()))
            .collect();
        Answer {
            status,
            headers,
            body: raw[split + 4..].to_vec(),
        }
    }

    pub fn get(&self, path: &str) -> Answer {
        self.ask("GET", path, &[])
    }
}

impl Drop for Served {
    fn drop(&mut self) {
        let _ = self.child.kill();
        let _ = self.child.wait();
    }
}

/// One HTTP answer.
pub struct Answer {
    pub status: u16,
    pub headers: Vec<(String, String)>,
    pub body: Vec<u8>,
}

impl Answer {
    /// The value of header `name` (lower case).
    pub fn header(&self, name: &str) -> Option<&str> {
        self.headers
            .iter()
            .find(|(k, _)| k == name)
            .map(|(_, v)| v.as_str())
    }

    /// The body as JSON.
    pub fn json(&self) -> serde_json::Value {
        serde_json::from_slice(&self.body).unwrap_or_else(|e| {
            panic!(
                "HTTP {}: not JSON ({e}): {}",
                self.status,
                String::from_utf8_lossy(&self.body)
            )
        })
    }
}
