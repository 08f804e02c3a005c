//! Real servers for the remote-read tests and benchmark: nginx (Debian's `nginx-light` or
//! `nginx`) serving a directory with byte ranges and an access log, and moto (PyPI,
//! `moto[server]`) as an S3 server. Each is started on a free port of 127.0.0.1 by the test
//! that needs it and stopped when dropped. A missing program is a failure that says what to
//! install, never a skip: `.ci/run` installs both.

#![allow(dead_code)]

use std::net::{TcpListener, TcpStream};
use std::path::{Path, PathBuf};
use std::process::{Child, Command, Stdio};
use std::time::{Duration, Instant};

/// A free port on 127.0.0.1 (bound and released: the server binds it next).
pub fn free_port() -> u16 {
    TcpListener::bind("127.0.0.1:0")
        .and_then(|l| l.local_addr())
        .map(|a| a.port())
        .expect("a free port")
}

/// Waits until something listens on `port`.
fn wait_for(port: u16, what: &str, child: &mut Child) {
    let start = Instant::now();
    while TcpStream::connect(("127.0.0.1", port)).is_err() {
        if let Ok(Some(status)) = child.try_wait() {
            panic!("{what} exited at start ({status})");
        }
        assert!(
            start.elapsed() < Duration::from_secs(30),
            "{what} did not listen on port {port} within 30 s"
        );
        std::thread::sleep(Duration::from_millis(50));
    }
}

/// The path of `program`, or a panic saying how to install it.
fn program(name: &str, install: &str) -> PathBuf {
    let out = Command::new("sh")
        .args(["-c", &format!("command -v {name}")])
        .output()
        .expect("sh runs");
    let path = String::from_utf8_lossy(&out.stdout).trim().to_string();
    assert!(
        out.status.success() && !path.is_empty(),
        "{name} is not installed: {install} (.ci/run does this)"
    );
    PathBuf::from(path)
}

/// nginx serving a directory.
pub struct Nginx {
    child: Child,
    pub port: u16,
    conf_dir: tempfile::TempDir,
}

impl Nginx {
    /// Serves `root` (read-only, byte ranges, ETags) at `http://127.0.0.1:PORT/`.
    pub fn start(root: &Path) -> Nginx {
        let nginx = program("nginx", "apt-get install nginx-light");
        let conf_dir = tempfile::tempdir().expect("temp dir");
        let port = free_port();
        let d = conf_dir.path().display();
        // One process in the foreground as the calling user: no worker that would switch
        // to another user and lose access to the test's files.
        let conf = format!(
            "daemon off;\nmaster_process off;\npid {d}/nginx.pid;\nerror_log {d}/error.log;\n\
             events {{ worker_connections 512; }}\n\
             http {{\n  log_format ranges '$request_method $uri $status $body_bytes_sent \"$http_range\"';\n  \
             access_log {d}/access.log ranges;\n  client_body_temp_path {d}/body;\n  \
             proxy_temp_path {d}/proxy;\n  fastcgi_temp_path {d}/fastcgi;\n  \
             uwsgi_temp_path {d}/uwsgi;\n  scgi_temp_path {d}/scgi;\n  \
             default_type application/octet-stream;\n  keepalive_requests 100000;\n  \
             server {{ listen 127.0.0.1:{port}; root {}; }}\n}}\n",
            root.display()
        );
        std::fs::write(conf_dir.path().join("nginx.conf"), conf).expect("conf");
        let mut child = Command::new(nginx)
            .arg("-p")
            .arg(conf_dir.path())
            .arg("-c")
            .arg(conf_dir.path().join("nginx.conf"))
            .stdout(Stdio::null())
            .stderr(Stdio::null())
            .spawn()
            .expect("nginx starts");
        wait_for(port, "nginx", &mut child);
        Nginx {
            child,
            port,
            conf_dir,
        }
    }

    /// The URL of `rel` under the root.
    pub fn url(&self, rel: &str) -> String {
        format!("http://127.0.0.1:{}/{rel}", self.port)
    }

    /// The access log's lines: `METHOD URI STATUS BYTES "RANGE"`.
    pub fn log(&self) -> Vec<String> {
        std::fs::read_to_string(self.conf_dir.path().join("access.log"))
            .unwrap_or_default()
            .lines()
            .map(str::to_string)
            .collect()
    }

    /// Requests and body bytes in the access log from line `from` on.
    pub fn requests_since(&self, from: usize) -> (u64, u64) {
        let log = self.log();
        let lines = log.get(from..).unwrap_or_default();
        let bytes = lines
            .iter()
            .filter_map(|l| l.split_whitespace().nth(3)?.parse::<u64>().ok())
            .sum();
        (lines.len() as u64, bytes)
    }
}

impl Drop for Nginx {
    fn drop(&mut self) {
        let _ = self.child.kill();
        let _ = self.child.wait();
    }
}

/// moto's S3 server.
pub struct Moto {
    child: Child,
    pub port: u16,
}

impl Moto {
    /// Starts `moto_server` on a free port.
    pub fn start() -> Moto {
        let moto = program("moto_server", "pip install 'moto[server]'");
        let port = free_port();
        let mut child = Command::new(moto)
            .args(["-H", "127.0.0.1", "-p", &port.to_string()])
            .stdout(Stdio::null())
            .stderr(Stdio::null())
            .spawn()
            .expect("moto_server starts");
        wait_for(port, "moto_server", &mut child);
        Moto { child, port }
    }

    /// Its endpoint, for `AWS_ENDPOINT_URL`.
    pub fn endpoint(&self) -> String {
        format!("http://127.0.0.1:{}", self.port)
    }

    /// The environment the fmrh CLI reads S3 settings from.
    pub fn env(&self) -> Vec<(&'static str, String)> {
        vec![
            ("AWS_ENDPOINT_URL", self.endpoint()),
            ("AWS_ACCESS_KEY_ID", "testing".into()),
            ("AWS_SECRET_ACCESS_KEY", "testing".into()),
            ("AWS_REGION", "us-east-1".into()),
        ]
    }

    /// Creates `bucket` (path style; requests signed with SigV4 by curl, as the client's
    /// are).
    pub fn create_bucket(&self, bucket: &str) {
        let url = format!("{}/{bucket}", self.endpoint());
        curl(&[SIGN[0], SIGN[1], SIGN[2], SIGN[3], "-X", "PUT", &url]);
    }

    /// Uploads `file` as `bucket/key`.
    pub fn put(&self, bucket: &str, key: &str, file: &Path) {
        let url = format!("{}/{bucket}/{key}", self.endpoint());
        // `-T`: a plain PUT of the file's bytes (a form content type would make moto parse
        // the body as a form).
        let file = file.to_str().expect("a UTF-8 path");
        curl(&[SIGN[0], SIGN[1], SIGN[2], SIGN[3], "-T", file, &url]);
    }
}

impl Drop for Moto {
    fn drop(&mut self) {
        let _ = self.child.kill();
        let _ = self.child.wait();
    }
}

/// curl's arguments that sign a request with the credentials of [`Moto::env`].
const SIGN: [&str; 4] = [
    "--aws-sigv4",
    "aws:amz:us-east-1:s3",
    "--user",
    "testing:testing",
];

/// Runs curl, failing on an HTTP error.
fn curl(args: &[&str]) {
    let curl = program("curl", "apt-get install curl");
    let out = Command::new(curl)
        .args(["-sS", "--fail", "--max-time", "60", "-o", "/dev/null"])
        .args(args)
        .output()
        .expect("curl runs");
    assert!(
        out.status.success(),
        "curl {args:?}: {}",
        String::from_utf8_lossy(&out.stderr)
    );
}
