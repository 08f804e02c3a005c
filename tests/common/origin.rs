//! A small HTTP origin for the remote-read tests (std threads, one request a connection):
//! it serves objects by path with byte ranges (`bytes=a-b`, `bytes=a-`, `bytes=-n`), ETags
//! and `If-Match`, counts what it was asked, and misbehaves on demand: delays, `500`s,
//! connections reset before an answer, bodies cut short, `Range` ignored. Tests queue faults
//! and check that the reader retries or fails clearly, never with wrong data.

#![allow(dead_code)]

use std::collections::{BTreeMap, VecDeque};
use std::io::{BufRead, BufReader, Read, Write};
use std::net::{Shutdown, TcpListener, TcpStream};
use std::sync::{Arc, Mutex};
use std::time::Duration;

/// One misbehaviour, used by the next request that reaches the origin.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Fault {
    /// Wait this long before answering (properly).
    Delay(Duration),
    /// Answer `500 Internal Server Error`.
    Status500,
    /// Close the connection without an answer.
    Reset,
    /// Announce the whole range, send half of it, close.
    Truncate,
    /// Answer `200` with the whole object, as a server without ranges does.
    IgnoreRange,
}

/// An object the origin serves.
#[derive(Clone, Debug)]
pub struct Object {
    pub bytes: Vec<u8>,
    pub etag: String,
}

/// What the origin serves and how it misbehaves.
#[derive(Debug, Default)]
pub struct State {
    pub objects: BTreeMap<String, Object>,
    /// Faults for the next requests, in order.
    pub faults: VecDeque<Fault>,
    /// Every fault applies to every request while set.
    pub always: Option<Fault>,
    /// Requests that reached the origin: (path, range header).
    pub log: Vec<(String, Option<String>)>,
    /// Body bytes sent.
    pub bytes_sent: u64,
    /// Answer only the first range of a multi-range request (as some servers do), instead
    /// of all of them as `multipart/byteranges`.
    pub first_range_only: bool,
}

/// A running origin.
#[derive(Clone)]
pub struct Origin {
    pub state: Arc<Mutex<State>>,
    pub base: String,
}

impl Origin {
    /// Starts an origin on a free port of 127.0.0.1.
    pub fn start() -> Origin {
        let listener = TcpListener::bind("127.0.0.1:0").expect("bind");
        let base = format!("http://{}", listener.local_addr().expect("addr"));
        let state: Arc<Mutex<State>> = Arc::default();
        let shared = Arc::clone(&state);
        std::thread::spawn(move || {
            for stream in listener.incoming() {
                let Ok(stream) = stream else { continue };
                let state = Arc::clone(&shared);
                std::thread::spawn(move || answer(stream, &state));
            }
        });
        Origin { state, base }
    }

    /// Serves `bytes` at `path` (starting with `/`) under `etag` (none when empty, as some
    /// servers and proxies give none); returns its URL.
    pub fn put(&self, path: &str, bytes: Vec<u8>, etag: &str) -> String {
        self.state.lock().unwrap().objects.insert(
            path.to_string(),
            Object {
                bytes,
                etag: if etag.is_empty() {
                    String::new()
                } else {
                    format!("\"{etag}\"")
                },
            },
        );
        format!("{}{path}", self.base)
    }

    /// Queues faults for the next requests.
    pub fn fail(&self, faults: &[Fault]) {
        self.state.lock().unwrap().faults.extend(faults);
    }

    /// Requests so far.
    pub fn requests(&self) -> usize {
        self.state.lock().unwrap().log.len()
    }
}

/// `bytes=...` against an object of `total` bytes: the inclusive range, or `None` when it
/// cannot be satisfied.
fn parse_range(spec: &str, total: u64) -> Option<(u64, u64)> {
    let (a, b) = spec.split_once('-')?;
    if a.is_empty() {
        let n: u64 = b.parse().ok()?;
        if n == 0 || total == 0 {
            return None;
        }
        return Some((total.saturating_sub(n), total - 1));
    }
    let from: u64 = a.parse().ok()?;
    let to = if b.is_empty() {
        total.checked_sub(1)?
    } else {
        b.parse::<u64>().ok()?.min(total.checked_sub(1)?)
    };
    (from <= to).then_some((from, to))
}

fn answer(stream: TcpStream, state: &Mutex<State>) {
    let Ok(clone) = stream.try_clone() else {
        return;
    };
    let mut reader = BufReader::new(clone);
    let mut request_line = String::new();
    if reader.read_line(&mut request_line).unwrap_or(0) == 0 {
        return;
    }
    let path = request_line
        .split_whitespace()
        .nth(1)
        .unwrap_or("/")
        .split('?')
        .next()
        .unwrap_or("/")
        .to_string();
    let (mut range, mut if_match) = (None, None);
    loop {
        let mut line = String::new();
        if reader.read_line(&mut line).unwrap_or(0) == 0 || line == "\r\n" {
            break;
        }
        let lower = line.to_ascii_lowercase();
        if let Some(v) = lower.strip_prefix("range: bytes=") {
            range = Some(v.trim().to_string());
        }
        if lower.starts_with("if-match:") {
            if_match = Some(line[9..].trim().to_string());
        }
    }
    let (fault, object, first_only) = {
        let mut s = state.lock().unwrap();
        s.log.push((path.clone(), range.clone()));
        let fault = s.faults.pop_front().or(s.always);
        (fault, s.objects.get(&path).cloned(), s.first_range_only)
    };
    let mut stream = stream;
    let head = |status: &str, extra: &str, len: usize| {
        format!("HTTP/1.1 {status}\r\nContent-Length: {len}\r\nConnection: close\r\n{extra}\r\n")
    };
    let mut body_len = 0u64;
    let reply: Vec<u8> = match (fault, object) {
        (Some(Fault::Reset), _) => {
            let _ = stream.shutdown(Shutdown::Both);
            return;
        }
        (Some(Fault::Status500), _) => head("500 Internal Server Error", "", 0).into_bytes(),
        (_, None) => head("404 Not Found", "", 0).into_bytes(),
        (fault, Some(obj)) => {
            if let Some(Fault::Delay(d)) = fault {
                std::thread::sleep(d);
            }
            let total = obj.bytes.len() as u64;
            let etag = if obj.etag.is_empty() {
                String::new()
            } else {
                format!("ETag: {}\r\n", obj.etag)
            };
            if if_match.as_ref().is_some_and(|m| *m != obj.etag) {
                head("412 Precondition Failed", "", 0).into_bytes()
            } else if fault == Some(Fault::IgnoreRange) || range.is_none() {
                let mut r = head("200 OK", &etag, obj.bytes.len()).into_bytes();
                r.extend_from_slice(&obj.bytes);
                body_len = total;
                r
            } else if range.as_deref().is_some_and(|r| r.contains(',')) && !first_only {
                let specs: Option<Vec<(u64, u64)>> = range
                    .as_deref()
                    .unwrap_or_default()
                    .split(',')
                    .map(|r| parse_range(r.trim(), total))
                    .collect();
                match specs {
                    None => head("416 Range Not Satisfiable", "", 0).into_bytes(),
                    Some(specs) => {
                        let mut body = Vec::new();
                        for (from, to) in specs {
                            body.extend_from_slice(
                                format!(
                                    "\r\n--XYZZY\r\nContent-Type: application/octet-stream\r\n\
                                     Content-Range: bytes {from}-{to}/{total}\r\n\r\n"
                                )
                                .as_bytes(),
                            );
                            body.extend_from_slice(&obj.bytes[from as usize..=to as usize]);
                        }
                        body.extend_from_slice(b"\r\n--XYZZY--\r\n");
                        if fault == Some(Fault::Truncate) {
                            body.truncate(body.len() / 2);
                        }
                        let extra =
                            format!("Content-Type: multipart/byteranges; boundary=XYZZY\r\n{etag}");
                        let mut out = head("206 Partial Content", &extra, body.len()).into_bytes();
                        body_len = body.len() as u64;
                        out.extend_from_slice(&body);
                        out
                    }
                }
            } else {
                let first = range.as_deref().map(|r| r.split(',').next().unwrap_or(r));
                match first.and_then(|r| parse_range(r.trim(), total)) {
                    None => head(
                        "416 Range Not Satisfiable",
                        &format!("Content-Range: bytes */{total}\r\n"),
                        0,
                    )
                    .into_bytes(),
                    Some((from, to)) => {
                        let body = &obj.bytes[from as usize..=to as usize];
                        let extra = format!("Content-Range: bytes {from}-{to}/{total}\r\n{etag}");
                        let mut out = head("206 Partial Content", &extra, body.len()).into_bytes();
                        let sent = if fault == Some(Fault::Truncate) {
                            &body[..body.len() / 2]
                        } else {
                            body
                        };
                        out.extend_from_slice(sent);
                        body_len = sent.len() as u64;
                        out
                    }
                }
            }
        }
    };
    // Written in chunks, counting what the socket took: a reader that hangs up stops it.
    let head_len = reply.len() as u64 - body_len;
    let mut written = 0u64;
    for chunk in reply.chunks(64 << 10) {
        if stream.write_all(chunk).is_err() {
            break;
        }
        written += chunk.len() as u64;
    }
    state.lock().unwrap().bytes_sent += written.saturating_sub(head_len);
    let _ = stream.flush();
    let _ = stream.shutdown(Shutdown::Write);
    let mut rest = Vec::new();
    let _ = stream.read_to_end(&mut rest);
}
