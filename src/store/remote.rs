//! A container read over HTTP(S) range requests (issue 17, `docs/remote-design.md`).
//!
//! [`HttpSource`] opens with one request for the object's first 128 KiB (both commit slots at
//! any page size, and a small file's bundle), which also tells the object's length and its
//! ETag, then one for its last 64 KiB (where a fresh build's metadata bundle ends the file);
//! reads those ranges cover cost no request. Every later request carries `If-Match` with the
//! ETag: an object replaced on the server answers `412`, which is reported as changed
//! underneath, never read as the new version's bytes. A server that ignores `Range` (a `200`
//! with the whole object) is refused without reading the body. Timeouts, resets and `5xx`
//! are retried with backoff; short bodies are retried once. A remote failure is an I/O error,
//! never a corruption report: only bytes that arrived whole are checked.

use std::borrow::Cow;
use std::io;
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicU64, Ordering};
use std::sync::Mutex;
use std::time::Duration;

use super::source::Source;
use crate::error::{Error, Result};

/// Bytes asked for with the first request: both slots at the largest page size.
pub const PREFIX_LEN: u64 = 128 << 10;

/// Bytes asked for at the end of the object at open.
pub const SUFFIX_LEN: u64 = 64 << 10;

/// Tries per request (the first and the retries).
const TRIES: u32 = 4;

/// Whether `text` names a remote object this build can read.
pub fn is_url(text: &str) -> bool {
    text.starts_with("http://") || text.starts_with("https://")
}

/// What a [`HttpSource`] has asked its server for.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, serde::Serialize)]
pub struct RequestStats {
    /// Range requests answered (retries included).
    pub requests: u64,
    /// Body bytes received.
    pub bytes: u64,
    /// Requests that were retries.
    pub retries: u64,
}

/// A remote object read with range requests, pinned to the version it opened.
pub struct HttpSource {
    url: String,
    name: PathBuf,
    agent: ureq::Agent,
    len: u64,
    etag: Option<String>,
    /// Ranges read at open: the prefix and the suffix.
    held: Mutex<Vec<(u64, Vec<u8>)>>,
    requests: AtomicU64,
    bytes: AtomicU64,
    retries: AtomicU64,
}

impl std::fmt::Debug for HttpSource {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("HttpSource")
            .field("url", &self.url)
            .field("len", &self.len)
            .field("etag", &self.etag)
            .finish_non_exhaustive()
    }
}

/// One answer to a range request.
struct Answer {
    /// The object's total length (`Content-Range`).
    total: Option<u64>,
    etag: Option<String>,
    body: Vec<u8>,
}

fn io_error(kind: io::ErrorKind, detail: String) -> io::Error {
    io::Error::new(kind, detail)
}

impl HttpSource {
    /// Opens `url` (`http://` or `https://`): reads its first [`PREFIX_LEN`] bytes and its
    /// last [`SUFFIX_LEN`], and pins its ETag.
    pub fn open(url: &str) -> Result<HttpSource> {
        let name = PathBuf::from(url);
        let agent: ureq::Agent = ureq::Agent::config_builder()
            .http_status_as_error(false)
            .timeout_connect(Some(Duration::from_secs(10)))
            .timeout_global(Some(Duration::from_secs(60)))
            .build()
            .into();
        let mut source = HttpSource {
            url: url.to_string(),
            name,
            agent,
            len: 0,
            etag: None,
            held: Mutex::new(Vec::new()),
            requests: 0.into(),
            bytes: 0.into(),
            retries: 0.into(),
        };
        let first = source
            .fetch(&format!("bytes=0-{}", PREFIX_LEN - 1), PREFIX_LEN, false)
            .map_err(|e| Error::io(&source.name, e))?;
        let Some(total) = first.total else {
            return Err(Error::input(
                &source.name,
                "the server gave no Content-Range: it does not serve byte ranges",
            ));
        };
        source.len = total;
        source.etag = first.etag;
        let mut held = vec![(0, first.body)];
        if total > PREFIX_LEN {
            let from = total.saturating_sub(SUFFIX_LEN).max(PREFIX_LEN);
            let suffix = source
                .fetch(&format!("bytes={from}-{}", total - 1), total - from, true)
                .map_err(|e| Error::io(&source.name, e))?;
            held.push((from, suffix.body));
        }
        source.held = Mutex::new(held);
        Ok(source)
    }

    /// What the source has asked its server for so far.
    pub fn request_stats(&self) -> RequestStats {
        RequestStats {
            requests: self.requests.load(Ordering::Relaxed),
            bytes: self.bytes.load(Ordering::Relaxed),
            retries: self.retries.load(Ordering::Relaxed),
        }
    }

    /// The ETag the source pinned, if the server gave one.
    pub fn etag(&self) -> Option<&str> {
        self.etag.as_deref()
    }

    /// One range request (`range` as the header says it, `want` bytes), with retries.
    fn fetch(&self, range: &str, want: u64, pinned: bool) -> io::Result<Answer> {
        let mut last = None;
        for attempt in 0..TRIES {
            if attempt > 0 {
                self.retries.fetch_add(1, Ordering::Relaxed);
                std::thread::sleep(Duration::from_millis(100 << (attempt - 1)));
            }
            match self.fetch_once(range, want, pinned) {
                Ok(a) => return Ok(a),
                // Worth another try: the network, the server's 5xx, a short body.
                Err(e) if matches!(e.kind(), io::ErrorKind::Interrupted) => last = Some(e),
                Err(e) => return Err(e),
            }
        }
        Err(last.unwrap_or_else(|| io_error(io::ErrorKind::Other, "no answer".into())))
    }

    /// One request; retryable failures come back as `Interrupted`.
    fn fetch_once(&self, range: &str, want: u64, pinned: bool) -> io::Result<Answer> {
        let retry = |detail: String| io_error(io::ErrorKind::Interrupted, detail);
        let mut request = self.agent.get(&self.url).header("Range", range);
        if let (true, Some(etag)) = (pinned, &self.etag) {
            request = request.header("If-Match", etag);
        }
        self.requests.fetch_add(1, Ordering::Relaxed);
        let mut response = match request.call() {
            Ok(r) => r,
            Err(e) => return Err(retry(format!("{}: {e}", self.url))),
        };
        let status = response.status().as_u16();
        let header = |name: &str| {
            response
                .headers()
                .get(name)
                .and_then(|v| v.to_str().ok())
                .map(str::to_string)
        };
        match status {
            206 => {}
            200 => {
                // The whole object is coming: refuse it unread.
                return Err(io_error(
                    io::ErrorKind::Unsupported,
                    format!(
                        "{}: the server ignored the Range header and sent the whole object; \
                         fmrh reads remote containers only from servers that serve byte ranges",
                        self.url
                    ),
                ));
            }
            412 => {
                return Err(io_error(
                    io::ErrorKind::Other,
                    format!(
                        "{}: the object changed underneath this reader (its ETag is no longer \
                         {}); open it again",
                        self.url,
                        self.etag.as_deref().unwrap_or("?")
                    ),
                ))
            }
            404 | 403 | 401 | 410 => {
                return Err(io_error(
                    io::ErrorKind::NotFound,
                    format!("{}: HTTP {status}", self.url),
                ))
            }
            500..=599 => return Err(retry(format!("{}: HTTP {status}", self.url))),
            _ => {
                return Err(io_error(
                    io::ErrorKind::Other,
                    format!("{}: HTTP {status}", self.url),
                ))
            }
        }
        let total = header("content-range")
            .and_then(|v| v.rsplit_once('/').and_then(|(_, t)| t.trim().parse().ok()));
        let etag = header("etag");
        if pinned && self.etag.is_some() && etag.is_some() && etag != self.etag {
            return Err(io_error(
                io::ErrorKind::Other,
                format!(
                    "{}: the object changed underneath this reader (ETag)",
                    self.url
                ),
            ));
        }
        let body = response
            .body_mut()
            .with_config()
            .limit(want)
            .read_to_vec()
            .map_err(|e| retry(format!("{}: {e}", self.url)))?;
        self.bytes.fetch_add(body.len() as u64, Ordering::Relaxed);
        let expect = total.map_or(want, |t: u64| want.min(t));
        if (body.len() as u64) < expect {
            return Err(retry(format!(
                "{}: {} bytes of the {expect} asked for",
                self.url,
                body.len()
            )));
        }
        Ok(Answer { total, etag, body })
    }
}

impl Source for HttpSource {
    fn len(&self) -> u64 {
        self.len
    }

    fn read_at(&self, offset: u64, len: usize) -> io::Result<Cow<'_, [u8]>> {
        let end = offset.checked_add(len as u64).filter(|&e| e <= self.len);
        let Some(end) = end else {
            return Err(io_error(
                io::ErrorKind::UnexpectedEof,
                format!("{len} bytes at offset {offset} lie past the end"),
            ));
        };
        if len == 0 {
            return Ok(Cow::Owned(Vec::new()));
        }
        {
            let held = self
                .held
                .lock()
                .map_err(|_| io_error(io::ErrorKind::Other, "poisoned".into()))?;
            for (at, bytes) in held.iter() {
                if offset >= *at && end <= at + bytes.len() as u64 {
                    // Inside a held range of at most 128 KiB.
                    let from = usize::try_from(offset - at).unwrap_or(usize::MAX);
                    if let Some(b) = bytes.get(from..from.saturating_add(len)) {
                        return Ok(Cow::Owned(b.to_vec()));
                    }
                }
            }
        }
        let answer = self.fetch(&format!("bytes={offset}-{}", end - 1), len as u64, true)?;
        if answer.body.len() != len {
            return Err(io_error(
                io::ErrorKind::UnexpectedEof,
                format!(
                    "{}: {} bytes of the {len} asked for",
                    self.url,
                    answer.body.len()
                ),
            ));
        }
        Ok(Cow::Owned(answer.body))
    }

    /// With `If-Match` on every request the bytes cannot change under the reader.
    fn stable(&self) -> bool {
        true
    }

    fn name(&self) -> &Path {
        &self.name
    }
}
