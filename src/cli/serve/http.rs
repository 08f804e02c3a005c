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
//! Limits: a request head is at most [`MAX_HEAD`] bytes; a connection idle for
//! [`IDLE`] is closed; at most [`MAX_CONNECTIONS`] connections are served at once (more wait
//! in the kernel's backlog, then are answered `503` and closed). A request with a body is
//! refused (`400`): nothing here reads one.

use std::io::{BufRead, BufReader, Read, Write};
use std::net::{TcpListener, TcpStream};
use std::sync::atomic::{AtomicUsize, Ordering};
use std::sync::Arc;
use std::time::Duration;

/// The longest request head (request line and headers) read.
pub const MAX_HEAD: usize = 16 << 10;
/// An idle keep-alive connection is closed after this long.
pub const IDLE: Duration = Duration::from_secs(30);
/// Connections served at once.
pub const MAX_CONNECTIONS: usize = 256;

/// One request: its method, target (path and query, still percent-encoded) and headers.
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

/// A response body: bytes in memory, or `len` bytes of a file from where it stands.
pub enum Body {
    Bytes(Vec<u8>),
    File(std::fs::File, u64),
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
        400 => "Bad Request",
        404 => "Not Found",
        405 => "Method Not Allowed",
        412 => "Precondition Failed",
        416 => "Range Not Satisfiable",
        422 => "Unprocessable Content",
        431 => "Request Header Fields Too Large",
        503 => "Service Unavailable",
        505 => "HTTP Version Not Supported",
        _ => "Internal Server Error",
    }
}

/// Serves `listener` forever: each connection on its own thread, each request answered by
/// `handler`.
pub fn serve<H>(listener: TcpListener, handler: H)
where
    H: Fn(&Request) -> Response + Send + Sync + 'static,
{
    let handler = Arc::new(handler);
    let open = Arc::new(AtomicUsize::new(0));
    for stream in listener.incoming() {
        let Ok(stream) = stream else {
            // Out of descriptors, or a connection reset before it was accepted: go on.
            std::thread::sleep(Duration::from_millis(10));
            continue;
        };
        if open.fetch_add(1, Ordering::AcqRel) >= MAX_CONNECTIONS {
            open.fetch_sub(1, Ordering::AcqRel);
            let mut s = stream;
            let _ = s.write_all(
                b"HTTP/1.1 503 Service Unavailable\r\nContent-Length: 0\r\nConnection: close\r\n\r\n",
            );
            continue;
        }
        let (handler, done) = (Arc::clone(&handler), Arc::clone(&open));
        let spawned = std::thread::Builder::new().spawn(move || {
            let _ = connection(stream, &*handler);
            done.fetch_sub(1, Ordering::AcqRel);
        });
        if spawned.is_err() {
            // No thread to be had: the stream was dropped with the closure (closed).
            open.fetch_sub(1, Ordering::AcqRel);
        }
    }
}

/// Answers the requests of one connection until it closes, idles, or asks to close.
fn connection(stream: TcpStream, handler: &dyn Fn(&Request) -> Response) -> std::io::Result<()> {
    stream.set_read_timeout(Some(IDLE))?;
    stream.set_write_timeout(Some(IDLE))?;
    stream.set_nodelay(true)?;
    let mut reader = BufReader::new(stream.try_clone()?);
    let mut writer = stream;
    loop {
        let (request, keep_alive) = match read_head(&mut reader)? {
            Head::Closed => return Ok(()),
            Head::Bad(status, why) => {
                let r = Response::new(status, "text/plain; charset=utf-8", Body::Bytes(why.into()));
                return write(&mut writer, r, false, false);
            }
            Head::Request(r, keep_alive) => (r, keep_alive),
        };
        let head_only = request.method == "HEAD";
        let response = handler(&request);
        write(&mut writer, response, head_only, keep_alive)?;
        if !keep_alive {
            return Ok(());
        }
    }
}

enum Head {
    Closed,
    Bad(u16, &'static str),
    Request(Request, bool),
}

/// Reads one request head; `Closed` at a clean end of the connection.
fn read_head(reader: &mut BufReader<TcpStream>) -> std::io::Result<Head> {
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
        lines.push(text);
    }
    let mut first = lines[0].split(' ');
    let (Some(method), Some(target), Some(version), None) =
        (first.next(), first.next(), first.next(), first.next())
    else {
        return Ok(Head::Bad(400, "a malformed request line\n"));
    };
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

fn write(
    out: &mut TcpStream,
    response: Response,
    head_only: bool,
    keep_alive: bool,
) -> std::io::Result<()> {
    let len = match &response.body {
        Body::Bytes(b) => b.len() as u64,
        Body::File(_, n) => *n,
    };
    let mut head = format!(
        "HTTP/1.1 {} {}\r\nServer: fmrh/{}\r\nContent-Length: {len}\r\n",
        response.status,
        reason(response.status),
        env!("CARGO_PKG_VERSION")
    );
    for (k, v) in &response.headers {
        head.push_str(&format!("{k}: {v}\r\n"));
    }
    head.push_str(if keep_alive {
        "Connection: keep-alive\r\n\r\n"
    } else {
        "Connection: close\r\n\r\n"
    });
    let mut out = std::io::BufWriter::new(out);
    out.write_all(head.as_bytes())?;
    if !head_only {
        match response.body {
            Body::Bytes(b) => out.write_all(&b)?,
            Body::File(f, n) => {
                let copied = std::io::copy(&mut f.take(n), &mut out)?;
                if copied != n {
                    // The file shrank under the server: the announced length cannot be
                    // kept, so the connection must end (the client sees a short body).
                    out.flush()?;
                    return Err(std::io::Error::new(
                        std::io::ErrorKind::UnexpectedEof,
                        "the file shrank while it was sent",
                    ));
                }
            }
        }
    }
    out.flush()
}
