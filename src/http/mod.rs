//! A small HTTP/1.1 server for `fmrh serve`: a thread per connection, keep-alive, `GET` and
//! `HEAD` only, bodies of known length, and limits on everything a client controls.
//!
//! Why not a crate: tiny_http 0.12 was tried first and lost requests. Its connection pool
//! queues a new connection behind busy threads when two arrive at once, and a thread stays
//! busy for as long as its keep-alive connection is open, so a remote dataset's parallel
//! tile opens hung until a timeout (seen here: about one scene in three stalled for 60 s).
//! An async server would fix that at the cost of a runtime; a blocking server this small,
//! which only reads files, does not need one.
//!
//! **What a client controls, and its limit** ([`Limits`]; each has a test in
//! `tests/serve.rs`, and the head parser a fuzz target):
//!
//! * a request head: at most [`MAX_HEAD`] bytes and [`MAX_HEADERS`] header lines (`431`),
//!   and it must arrive whole within the timeout of the previous answer (a client that
//!   trickles it, slowloris, gets `408` and is closed);
//! * a connection: idle past the timeout, it is closed; at most
//!   [`Limits::max_connections`] are served at once and [`Limits::per_client`] from one
//!   address (more are answered `503` and closed), so one host cannot take every thread;
//! * reading the answer: a client must take it at [`Limits::min_rate`] bytes a second
//!   after a first timeout's grace, else the connection is closed (a slow reader holds a
//!   thread no longer than that);
//! * a body: refused (`400`), nothing here reads one; byte ranges: see [`ranges`] (capped,
//!   and answered from the file part by part, never gathered in memory).

pub mod ranges;

use std::collections::HashMap;
use std::io::{BufRead, BufReader, Read, Write};
use std::net::{IpAddr, TcpListener, TcpStream};
use std::sync::atomic::{AtomicUsize, Ordering};
use std::sync::{Arc, Mutex};
use std::time::{Duration, Instant};

/// The longest request head (request line and headers) read.
pub const MAX_HEAD: usize = 16 << 10;
/// The most header lines a request head may have.
pub const MAX_HEADERS: usize = 100;

/// What the server allows a client (see the module doc).
#[derive(Clone, Copy, Debug)]
pub struct Limits {
    /// How long a connection may idle, a request head may take to arrive, and a client may
    /// go without taking any of an answer.
    pub timeout: Duration,
    /// Connections served at once.
    pub max_connections: usize,
    /// Connections served at once from one address.
    pub per_client: usize,
    /// Bytes a second a client must take an answer at, past the first timeout.
    pub min_rate: u64,
}

impl Default for Limits {
    fn default() -> Self {
        Limits {
            timeout: Duration::from_secs(30),
            max_connections: 256,
            per_client: 64,
            min_rate: 16 << 10,
        }
    }
}

/// One request: its method, target (path and query, still percent-encoded) and headers.
#[derive(Debug)]
pub struct Request {
    pub method: String,
    pub target: String,
    headers: Vec<(String, String)>,
}

impl Request {
    /// The value of the header `name` (any case).
    pub fn header(&self, name: &str) -> Option<&str> {
        self.headers
            .iter()
            .find(|(k, _)| k.eq_ignore_ascii_case(name))
            .map(|(_, v)| v.as_str())
    }
}

/// A response body: bytes in memory, `len` bytes of a file from where it stands, or a
/// `multipart/byteranges` body read from a file part by part.
pub enum Body {
    Bytes(Vec<u8>),
    File(std::fs::File, u64),
    /// Each part's head and then its range of the file, and the closing delimiter.
    Parts(std::fs::File, Vec<ranges::Part>, Vec<u8>),
}

impl Body {
    /// Its length in bytes.
    pub fn content_length(&self) -> u64 {
        match self {
            Body::Bytes(b) => b.len() as u64,
            Body::File(_, n) => *n,
            Body::Parts(_, parts, end) => parts
                .iter()
                .map(|(head, r)| head.len() as u64 + (r.end - r.start))
                .sum::<u64>()
                .saturating_add(end.len() as u64),
        }
    }
}

/// One response.
pub struct Response {
    pub status: u16,
    pub headers: Vec<(String, String)>,
    pub body: Body,
}

impl Response {
    pub fn new(status: u16, content_type: &str, body: Body) -> Response {
        Response {
            status,
            headers: vec![("Content-Type".into(), content_type.into())],
            body,
        }
    }

    /// With one more header.
    pub fn with(mut self, name: &str, value: impl Into<String>) -> Response {
        self.headers.push((name.into(), value.into()));
        self
    }
}

fn reason(status: u16) -> &'static str {
    match status {
        200 => "OK",
        204 => "No Content",
        206 => "Partial Content",
        304 => "Not Modified",
        400 => "Bad Request",
        404 => "Not Found",
        405 => "Method Not Allowed",
        406 => "Not Acceptable",
        408 => "Request Timeout",
        412 => "Precondition Failed",
        416 => "Range Not Satisfiable",
        422 => "Unprocessable Content",
        431 => "Request Header Fields Too Large",
        503 => "Service Unavailable",
        505 => "HTTP Version Not Supported",
        _ => "Internal Server Error",
    }
}

/// The connections open from each address, for [`Limits::per_client`].
#[derive(Default)]
struct Clients(Mutex<HashMap<IpAddr, usize>>);

impl Clients {
    /// Counts one more connection from `ip`, unless it has `limit` already.
    fn admit(&self, ip: IpAddr, limit: usize) -> bool {
        let mut open = self.0.lock().unwrap_or_else(|p| p.into_inner());
        let n = open.entry(ip).or_insert(0);
        if *n >= limit {
            return false;
        }
        *n += 1;
        true
    }

    fn leave(&self, ip: IpAddr) {
        let mut open = self.0.lock().unwrap_or_else(|p| p.into_inner());
        if let Some(n) = open.get_mut(&ip) {
            *n -= 1;
            if *n == 0 {
                open.remove(&ip);
            }
        }
    }
}

/// Serves `listener` forever: each connection on its own thread, each request answered by
/// `handler`, within `limits`.
pub fn serve<H>(listener: TcpListener, limits: Limits, handler: H)
where
    H: Fn(&Request) -> Response + Send + Sync + 'static,
{
    let handler = Arc::new(handler);
    let open = Arc::new(AtomicUsize::new(0));
    let clients = Arc::new(Clients::default());
    for stream in listener.incoming() {
        let Ok(stream) = stream else {
            // Out of descriptors, or a connection reset before it was accepted: go on.
            std::thread::sleep(Duration::from_millis(10));
            continue;
        };
        let busy = |mut s: TcpStream| {
            let _ = s.set_write_timeout(Some(Duration::from_secs(1)));
            let _ = s.write_all(
                b"HTTP/1.1 503 Service Unavailable\r\nContent-Length: 0\r\nRetry-After: 1\r\nConnection: close\r\n\r\n",
            );
        };
        let Ok(ip) = stream.peer_addr().map(|a| a.ip()) else {
            continue;
        };
        if open.fetch_add(1, Ordering::AcqRel) >= limits.max_connections {
            open.fetch_sub(1, Ordering::AcqRel);
            busy(stream);
            continue;
        }
        if !clients.admit(ip, limits.per_client) {
            open.fetch_sub(1, Ordering::AcqRel);
            busy(stream);
            continue;
        }
        let (handler, done, who) = (Arc::clone(&handler), Arc::clone(&open), Arc::clone(&clients));
        let spawned = std::thread::Builder::new().spawn(move || {
            let _ = connection(stream, &limits, &*handler);
            who.leave(ip);
            done.fetch_sub(1, Ordering::AcqRel);
        });
        if spawned.is_err() {
            // No thread to be had: the stream was dropped with the closure (closed).
            clients.leave(ip);
            open.fetch_sub(1, Ordering::AcqRel);
        }
    }
}

/// A socket read against a deadline: each read may wait only for what is left of it, so a
/// client that trickles a request head byte by byte cannot stretch it past the deadline.
struct Deadline {
    stream: TcpStream,
    until: Instant,
    /// Whether a byte arrived since [`Deadline::reset`]: a head begun, not an idle line.
    got: bool,
}

impl Deadline {
    fn started(&self) -> bool {
        self.got
    }

    fn reset(&mut self) {
        self.got = false;
    }
}

impl Read for Deadline {
    fn read(&mut self, buf: &mut [u8]) -> std::io::Result<usize> {
        let left = self.until.saturating_duration_since(Instant::now());
        if left.is_zero() {
            return Err(std::io::Error::new(
                std::io::ErrorKind::TimedOut,
                "the request head took too long",
            ));
        }
        self.stream.set_read_timeout(Some(left))?;
        let n = self.stream.read(buf)?;
        self.got |= n > 0;
        Ok(n)
    }
}

/// Answers the requests of one connection until it closes, idles, or asks to close.
fn connection(
    stream: TcpStream,
    limits: &Limits,
    handler: &dyn Fn(&Request) -> Response,
) -> std::io::Result<()> {
    stream.set_nodelay(true)?;
    let mut reader = BufReader::new(Deadline {
        stream: stream.try_clone()?,
        until: Instant::now() + limits.timeout,
        got: false,
    });
    let mut writer = stream;
    loop {
        // The next head, whole, within the timeout.
        reader.get_mut().until = Instant::now() + limits.timeout;
        let head = match read_head(&mut reader) {
            Ok(h) => h,
            Err(e)
                if matches!(
                    e.kind(),
                    std::io::ErrorKind::TimedOut | std::io::ErrorKind::WouldBlock
                ) =>
            {
                // Silent: an idle keep-alive connection, closed. Part of a head: too slow.
                if reader.buffer().is_empty() && !reader.get_ref().started() {
                    return Ok(());
                }
                Head::Bad(408, "the request head did not arrive in time\n")
            }
            Err(e) => return Err(e),
        };
        let (request, keep_alive) = match head {
            Head::Closed => return Ok(()),
            Head::Bad(status, why) => {
                let r = Response::new(status, "text/plain; charset=utf-8", Body::Bytes(why.into()));
                return write(&mut writer, limits, r, false, false);
            }
            Head::Request(r, keep_alive) => (r, keep_alive),
        };
        reader.get_mut().reset();
        let head_only = request.method == "HEAD";
        let response = handler(&request);
        write(&mut writer, limits, response, head_only, keep_alive)?;
        if !keep_alive {
            return Ok(());
        }
    }
}

/// What one request head was.
#[derive(Debug)]
pub enum Head {
    /// The connection ended before a request began.
    Closed,
    /// A head that cannot be served: the status and why.
    Bad(u16, &'static str),
    /// A request, and whether the connection stays open after it.
    Request(Request, bool),
}

/// Reads one request head; `Closed` at a clean end of the connection. `Err` only for the
/// reader's own errors (a timeout, a reset).
pub fn read_head<R: BufRead>(reader: &mut R) -> std::io::Result<Head> {
    let mut lines: Vec<String> = Vec::new();
    let mut total = 0usize;
    loop {
        let mut line = Vec::new();
        let n = reader
            .by_ref()
            .take((MAX_HEAD - total + 1) as u64)
            .read_until(b'\n', &mut line)?;
        if n == 0 {
            return Ok(Head::Closed);
        }
        total += n;
        if total > MAX_HEAD {
            return Ok(Head::Bad(431, "the request head is too large\n"));
        }
        if !line.ends_with(b"\n") {
            // The peer closed mid-line.
            return Ok(Head::Closed);
        }
        let Ok(text) = String::from_utf8(line) else {
            return Ok(Head::Bad(400, "the request head is not UTF-8\n"));
        };
        let text = text.trim_end_matches(['\r', '\n']).to_string();
        if text.is_empty() {
            if lines.is_empty() {
                continue; // RFC 9112 §2.2: ignore empty lines before a request line
            }
            break;
        }
        if lines.len() > MAX_HEADERS {
            return Ok(Head::Bad(431, "the request has too many header lines\n"));
        }
        lines.push(text);
    }
    let mut first = lines[0].split(' ');
    let (Some(method), Some(target), Some(version), None) =
        (first.next(), first.next(), first.next(), first.next())
    else {
        return Ok(Head::Bad(400, "a malformed request line\n"));
    };
    if method.is_empty() || !target.starts_with('/') {
        return Ok(Head::Bad(400, "a malformed request line\n"));
    }
    let minor = match version {
        "HTTP/1.1" => 1,
        "HTTP/1.0" => 0,
        _ => return Ok(Head::Bad(505, "HTTP/1.0 and HTTP/1.1 only\n")),
    };
    let mut headers = Vec::new();
    for line in &lines[1..] {
        let Some((k, v)) = line.split_once(':') else {
            return Ok(Head::Bad(400, "a malformed header line\n"));
        };
        headers.push((k.trim().to_string(), v.trim().to_string()));
    }
    let request = Request {
        method: method.to_string(),
        target: target.to_string(),
        headers,
    };
    let has_body = request.header("Transfer-Encoding").is_some()
        || request
            .header("Content-Length")
            .is_some_and(|l| l.trim() != "0");
    if has_body {
        return Ok(Head::Bad(400, "requests with a body are not served\n"));
    }
    let connection = request
        .header("Connection")
        .unwrap_or("")
        .to_ascii_lowercase();
    let keep_alive = if minor == 1 {
        !connection.contains("close")
    } else {
        connection.contains("keep-alive")
    };
    Ok(Head::Request(request, keep_alive))
}

/// A socket write against a deadline that grows with what was written: the answer's first
/// bytes get a timeout's grace, then the client must take [`Limits::min_rate`] bytes a
/// second on average.
struct Paced<'a> {
    out: &'a mut TcpStream,
    started: Instant,
    grace: Duration,
    rate: u64,
    sent: u64,
}

impl Write for Paced<'_> {
    fn write(&mut self, buf: &[u8]) -> std::io::Result<usize> {
        let allowed = self.grace + Duration::from_secs_f64(self.sent as f64 / self.rate.max(1) as f64);
        let left = allowed.saturating_sub(self.started.elapsed());
        if left.is_zero() {
            return Err(std::io::Error::new(
                std::io::ErrorKind::TimedOut,
                "the client takes the answer too slowly",
            ));
        }
        // No progress for a timeout ends it too, whatever allowance the pace has built up
        // (a burst into the socket's buffers earns allowance the client never used).
        self.out.set_write_timeout(Some(left.min(self.grace)))?;
        // At most 64 KiB a call: the deadline is looked at again between chunks.
        let n = self.out.write(&buf[..buf.len().min(64 << 10)])?;
        self.sent += n as u64;
        Ok(n)
    }

    fn flush(&mut self) -> std::io::Result<()> {
        self.out.flush()
    }
}

fn write(
    out: &mut TcpStream,
    limits: &Limits,
    response: Response,
    head_only: bool,
    keep_alive: bool,
) -> std::io::Result<()> {
    let len = response.body.content_length();
    // 204 and 304 have no body, and no length (a 304's would be the representation's).
    let bodiless = matches!(response.status, 204 | 304);
    let mut head = format!(
        "HTTP/1.1 {} {}\r\nServer: fmrh/{}\r\n",
        response.status,
        reason(response.status),
        env!("CARGO_PKG_VERSION")
    );
    if !bodiless {
        head.push_str(&format!("Content-Length: {len}\r\n"));
    }
    let head_only = head_only || bodiless;
    for (k, v) in &response.headers {
        head.push_str(&format!("{k}: {v}\r\n"));
    }
    head.push_str(if keep_alive {
        "Connection: keep-alive\r\n\r\n"
    } else {
        "Connection: close\r\n\r\n"
    });
    let mut paced = Paced {
        out,
        started: Instant::now(),
        grace: limits.timeout,
        rate: limits.min_rate,
        sent: 0,
    };
    let mut out = std::io::BufWriter::with_capacity(64 << 10, &mut paced);
    out.write_all(head.as_bytes())?;
    if !head_only {
        match response.body {
            Body::Bytes(b) => out.write_all(&b)?,
            Body::File(f, n) => copy_exactly(f, n, &mut out)?,
            Body::Parts(mut f, parts, end) => {
                use std::io::Seek;
                for (part_head, r) in parts {
                    out.write_all(&part_head)?;
                    f.seek(std::io::SeekFrom::Start(r.start))?;
                    copy_exactly(f.try_clone()?, r.end - r.start, &mut out)?;
                }
                out.write_all(&end)?;
            }
        }
    }
    out.flush()
}

/// Copies `n` bytes of `f` from where it stands to `out`; an error when the file ends first.
fn copy_exactly(f: std::fs::File, n: u64, out: &mut impl Write) -> std::io::Result<()> {
    let copied = std::io::copy(&mut f.take(n), out)?;
    if copied != n {
        // The file shrank under the server: the announced length cannot be kept, so the
        // connection must end (the client sees a short body).
        out.flush()?;
        return Err(std::io::Error::new(
            std::io::ErrorKind::UnexpectedEof,
            "the file shrank while it was sent",
        ));
    }
    Ok(())
}
