//! A container read over HTTP(S) range requests or the S3 API (issue 17,
//! `docs/remote-design.md`).
//!
//! **Rounds are the unit.** Over a network a read costs a round trip (tens of milliseconds to
//! object storage) and bandwidth matters less, so [`HttpSource`] spends requests in as few
//! sequential *rounds* as it can:
//!
//! * **Open, one round:** the object's first [`PREFIX_LEN`] bytes (both commit slots at the
//!   default page size) and its last [`RemoteOptions::suffix_len`] ([`SUFFIX_LEN`]: where a
//!   fresh build puts its metadata bundle, format §2), as one multi-range request where the
//!   server answers those (nginx does), else as two requests in parallel (S3). Reads inside
//!   them cost nothing more. The answers also tell the object's length and its ETag.
//! * **Metadata, a round per tree level at most:** after opening, the store advises where
//!   its table pages lie ([`Source::advise_metadata`]); the first read inside that area
//!   fetches it whole when it is at most [`RemoteOptions::metadata_limit`] bytes, and every
//!   index, node and block page is then served from memory. In a larger area (a dataset's
//!   large tiles) a scene names its lookups ahead ([`Source::prefetch`]: the index spans it
//!   scans, the nodes it reads, the children it refines, the records and ancestors it
//!   loads), and the source fetches the pages each level of the trees needs in one round;
//!   a read nothing named fetches its aligned [`RemoteOptions::metadata_chunk`].
//! * **Payloads, one round per batch:** [`Source::read_many`] closes gaps of at most
//!   [`RemoteOptions::merge_gap`] bytes between the ranges asked for (a scene's payloads lie
//!   in Hilbert order, so they cluster), then fetches the requests over
//!   [`RemoteOptions::connections`] connections at once. A batch of `n` requests costs
//!   `ceil(n / connections)` rounds.
//!
//! [`RequestStats`] counts requests, bytes, rounds and retries: the request plan a scene
//! reports.
//!
//! **Consistency.** Every request after the first carries `If-Match` with the ETag the open
//! saw: an object replaced on the server answers `412`, which is reported as changed
//! underneath, never read as the new version's bytes (payload CRCs check every byte besides).
//!
//! **Faults.** Timeouts, connection resets, `5xx` answers and short bodies are retried with
//! exponential backoff ([`RemoteOptions::tries`]); a server that ignores `Range` (a `200`
//! with the whole object) is refused without its body being read. A remote failure is an
//! I/O error, never a corruption report: only bytes that arrived whole are checked.
//!
//! **S3.** `s3://bucket/key` is read with presigned `GET`s (AWS Signature V4, signed by
//! `rusty-s3`, no I/O of its own) from the credentials in the usual environment variables:
//! `AWS_ACCESS_KEY_ID`, `AWS_SECRET_ACCESS_KEY`, `AWS_SESSION_TOKEN`; `AWS_REGION` (or
//! `AWS_DEFAULT_REGION`, else `us-east-1`); `AWS_ENDPOINT_URL` for another S3 server (path
//! style). Without credentials the requests go unsigned (a public bucket).

use std::borrow::Cow;
use std::io;
use std::ops::Range;
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};
use std::sync::{Arc, Mutex, RwLock};
use std::time::Duration;

pub use super::source::RequestStats;
use super::source::Source;
use crate::error::{Error, Result};

/// Bytes asked for at the start of the object at open: commit slot 0's page and slot 1's
/// record at the default page size of 4 KiB (a larger page size costs one more request for
/// slot 1).
pub const PREFIX_LEN: u64 = 4096 + 256;

/// Bytes asked for at the end of the object at open: a fresh build puts its metadata bundle
/// last (format §2), and opening reads the bundle's head, which is the *start* of its
/// stored run; so this covers a whole bundle at the default limit (32 KiB stored,
/// `DEFAULT_BUNDLE_LIMIT`) and its last page's zero tail at the default page size. Any
/// fresh file at the defaults then opens in one round. (16 KiB would save 20 KiB on a
/// small file but cost Puget Sound 1k, whose bundle is 17 KiB, a second round.)
pub const SUFFIX_LEN: u64 = (32 + 4) << 10;

/// Ranges a multi-range request asks for at most (its `Range` header stays under 4 KiB,
/// inside nginx's and most servers' header limits).
pub const MAX_PARTS: usize = 128;

/// Gaps of at most this many bytes are read rather than asked as another part: about what a
/// part's own boundary and headers cost.
const MULTI_RANGE_GAP: u64 = 160;

pub use super::source::is_url;

/// How a [`HttpSource`] spends requests.
#[derive(Clone, Debug)]
pub struct RemoteOptions {
    /// Requests in flight at once within a batch.
    pub connections: usize,
    /// Bytes asked for at the end of the object at open ([`SUFFIX_LEN`] by default): a
    /// metadata bundle within them opens in the same round, a larger one costs a second.
    pub suffix_len: u64,
    /// A metadata area of at most this many bytes is fetched whole on its first read.
    pub metadata_limit: u64,
    /// A larger area is fetched in aligned chunks of this many bytes, each on the first
    /// read inside it.
    pub metadata_chunk: u64,
    /// Chunks and pages fetched ahead are held in memory up to this many bytes in all; the
    /// oldest are dropped first (and fetched again if read again). A batch fetched together
    /// is kept whole while it is the newest, even past the bound.
    pub held_limit: u64,
    /// Gaps of at most this many bytes between the ranges of a batch are read (and dropped)
    /// rather than cost another request (when the server takes one range a request).
    pub merge_gap: u64,
    /// Ask for many ranges in one request (`Range: bytes=a-b,c-d,...`, answered as
    /// `multipart/byteranges`) when the server serves them; S3 does not, so `s3://` never
    /// does. A server that answers otherwise is asked one range a request from then on.
    pub multi_range: bool,
    /// Fetch ahead the pages that a reader names before its lookups
    /// ([`Source::prefetch`]): one round per tree level for a scene's index, node and
    /// block lookups. Off, each page a lookup reaches first outside what is held costs a
    /// round of its own (or fetches its chunk).
    pub read_ahead: bool,
    /// Tries per request: the first and the retries.
    pub tries: u32,
    /// The wait before the first retry; it doubles with each.
    pub backoff: Duration,
    /// The longest a request may take, its body included.
    pub timeout: Duration,
}

impl RemoteOptions {
    /// For the tiles of a dataset: a scene meets many tiles and needs only coarse nodes of
    /// most, so a tile's metadata area is fetched whole only up to 256 KiB and otherwise in
    /// 64 KiB chunks as reads reach them (the tiles' rounds overlap: they are read in
    /// parallel).
    pub fn for_tiles() -> RemoteOptions {
        RemoteOptions {
            metadata_limit: 256 << 10,
            ..RemoteOptions::default()
        }
    }
}

impl Default for RemoteOptions {
    fn default() -> Self {
        RemoteOptions {
            connections: 8,
            suffix_len: SUFFIX_LEN,
            metadata_limit: 2 << 20,
            metadata_chunk: 64 << 10,
            held_limit: 64 << 20,
            merge_gap: 16 << 10,
            multi_range: true,
            read_ahead: true,
            tries: 4,
            backoff: Duration::from_millis(100),
            timeout: Duration::from_secs(60),
        }
    }
}

/// Where the requests go.
enum Target {
    /// A plain URL.
    Http(String),
    /// An object in an S3 bucket: each request gets a freshly presigned URL.
    S3 {
        bucket: Box<rusty_s3::Bucket>,
        key: String,
        credentials: Option<rusty_s3::Credentials>,
    },
}

impl Target {
    fn parse(url: &str) -> Result<Target> {
        let Some(rest) = url.strip_prefix("s3://") else {
            return Ok(Target::Http(url.to_string()));
        };
        let bad = |why: &str| Error::input(Path::new(url), why.to_string());
        let (bucket, key) = rest
            .split_once('/')
            .filter(|(b, k)| !b.is_empty() && !k.is_empty())
            .ok_or_else(|| bad("an S3 URL is s3://BUCKET/KEY"))?;
        let var = |name: &str| std::env::var(name).ok().filter(|v| !v.is_empty());
        let region = var("AWS_REGION")
            .or_else(|| var("AWS_DEFAULT_REGION"))
            .unwrap_or_else(|| "us-east-1".into());
        let (endpoint, style) = match var("AWS_ENDPOINT_URL") {
            Some(e) => (e, rusty_s3::UrlStyle::Path),
            None => (
                format!("https://s3.{region}.amazonaws.com"),
                rusty_s3::UrlStyle::VirtualHost,
            ),
        };
        let endpoint = endpoint
            .parse()
            .map_err(|e| bad(&format!("AWS_ENDPOINT_URL {endpoint:?}: {e}")))?;
        let bucket = rusty_s3::Bucket::new(endpoint, style, bucket.to_string(), region)
            .map_err(|e| bad(&format!("bucket {bucket:?}: {e}")))?;
        Ok(Target::S3 {
            bucket: Box::new(bucket),
            key: key.to_string(),
            credentials: rusty_s3::Credentials::from_env(),
        })
    }

    /// The URL of the next request.
    fn request_url(&self) -> String {
        match self {
            Target::Http(url) => url.clone(),
            Target::S3 {
                bucket,
                key,
                credentials,
            } => {
                use rusty_s3::S3Action;
                bucket
                    .get_object(credentials.as_ref(), key)
                    .sign(Duration::from_secs(900))
                    .to_string()
            }
        }
    }
}

/// The state of the advised metadata area.
#[derive(Clone, Debug, PartialEq)]
enum Area {
    /// No advice, or the area was fetched (its bytes are held) or is too large.
    None,
    /// Advised and not yet fetched.
    Advised(Range<u64>),
}

/// A remote object read with range requests, pinned to the version it opened.
pub struct HttpSource {
    url: String,
    name: PathBuf,
    target: Target,
    agent: ureq::Agent,
    options: RemoteOptions,
    len: u64,
    etag: Option<String>,
    /// Ranges held in memory: the prefix, the suffix, the metadata area.
    held: RwLock<Vec<(u64, Arc<[u8]>)>>,
    /// How many of `held` opening read (kept whatever the bound).
    opened_ranges: usize,
    area: Mutex<Area>,
    /// Whether batches still go as multi-range requests.
    multi_range: AtomicBool,
    requests: AtomicU64,
    bytes: AtomicU64,
    rounds: AtomicU64,
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

/// Parts of an answer: where each starts, and its bytes.
type Parts = Vec<(u64, Vec<u8>)>;

/// Requests of a batch: each one's byte range, and the indices of the spans it serves.
type Requests = Vec<(Range<u64>, Vec<usize>)>;

/// One answer to a range request.
struct Answer {
    /// Its parts: where each starts, and its bytes (one part unless `multipart/byteranges`).
    parts: Parts,
    /// The object's total length (`Content-Range`).
    total: u64,
    etag: Option<String>,
}

/// The parts of a `multipart/byteranges` body (RFC 9110 §14.6): each part's start and
/// bytes, and the object's length. Every part must say its range, all the same length.
fn multipart(body: &[u8], boundary: &str) -> std::result::Result<(Parts, u64), String> {
    let delimiter = format!("--{boundary}");
    let mut at = 0usize;
    let mut parts = Vec::new();
    let mut total = None;
    let line_end = |from: usize| -> Option<usize> {
        body.get(from..)?
            .windows(2)
            .position(|w| w == b"\r\n")
            .map(|p| from + p)
    };
    loop {
        // Skip blank lines before a delimiter.
        while body.get(at..at + 2) == Some(b"\r\n") {
            at += 2;
        }
        let end = line_end(at).ok_or("ends inside a delimiter")?;
        let line = &body[at..end];
        if line == format!("{delimiter}--").as_bytes() {
            break;
        }
        if line != delimiter.as_bytes() {
            return Err("has a part without its delimiter".into());
        }
        at = end + 2;
        let mut range = None;
        loop {
            let end = line_end(at).ok_or("ends inside a part's headers")?;
            let line = &body[at..end];
            at = end + 2;
            if line.is_empty() {
                break;
            }
            let text = String::from_utf8_lossy(line);
            if let Some((name, value)) = text.split_once(':') {
                if name.trim().eq_ignore_ascii_case("content-range") {
                    range = content_range(value);
                }
            }
        }
        let (start, last, whole) = range.ok_or("has a part without a Content-Range")?;
        if *total.get_or_insert(whole) != whole || last < start || last >= whole {
            return Err("has a part with a bad Content-Range".into());
        }
        let len = usize::try_from(last - start + 1).map_err(|_| "has a part too large")?;
        let bytes = body
            .get(at..at.saturating_add(len))
            .ok_or("is shorter than its parts")?;
        parts.push((start, bytes.to_vec()));
        at += len;
    }
    Ok((parts, total.ok_or("has no parts")?))
}

/// A failure worth another try: the network, a `5xx`, a short body.
fn retryable(detail: String) -> io::Error {
    io::Error::new(io::ErrorKind::Interrupted, detail)
}

fn failed(detail: String) -> io::Error {
    io::Error::other(detail)
}

/// `Content-Range: bytes a-b/total` as `(a, b, total)`.
fn content_range(value: &str) -> Option<(u64, u64, u64)> {
    let rest = value.trim().strip_prefix("bytes ")?;
    let (span, total) = rest.split_once('/')?;
    let (a, b) = span.split_once('-')?;
    Some((
        a.trim().parse().ok()?,
        b.trim().parse().ok()?,
        total.trim().parse().ok()?,
    ))
}

/// Whether `parts` (each a start and its bytes) hold every byte of `from .. to`.
fn covers(parts: &[(u64, Vec<u8>)], from: u64, to: u64) -> bool {
    from >= to
        || parts
            .iter()
            .any(|(at, b)| *at <= from && at.saturating_add(b.len() as u64) >= to)
}

impl HttpSource {
    /// Opens `url` (`http://`, `https://` or `s3://`) with the default options.
    pub fn open(url: &str) -> Result<HttpSource> {
        HttpSource::open_with(url, RemoteOptions::default())
    }

    /// Opens `url`: one round, its first [`PREFIX_LEN`] bytes and its last
    /// [`RemoteOptions::suffix_len`], and pins its ETag. Both come in one multi-range
    /// request where the server answers one (nginx does), else as two requests in parallel
    /// (S3); a server that sends the whole object to the multi-range request is asked the
    /// two ranges in a second round.
    pub fn open_with(url: &str, options: RemoteOptions) -> Result<HttpSource> {
        let agent: ureq::Agent = ureq::Agent::config_builder()
            .http_status_as_error(false)
            .timeout_connect(Some(Duration::from_secs(10).min(options.timeout)))
            .timeout_global(Some(options.timeout))
            .max_idle_connections_per_host(options.connections.max(1))
            .build()
            .into();
        let mut source = HttpSource {
            url: url.to_string(),
            name: PathBuf::from(url),
            target: Target::parse(url)?,
            agent,
            options,
            len: 0,
            etag: None,
            held: RwLock::new(Vec::new()),
            opened_ranges: 0,
            area: Mutex::new(Area::None),
            multi_range: AtomicBool::new(false),
            requests: 0.into(),
            bytes: 0.into(),
            rounds: 0.into(),
            retries: 0.into(),
        };
        let s3 = matches!(source.target, Target::S3 { .. });
        let multi_range = source.options.multi_range && !s3;
        let suffix_len = source.options.suffix_len.max(1);
        let io = |e| Error::io(Path::new(url), e);
        source.rounds.fetch_add(1, Ordering::Relaxed);
        // One request for both ends where the server answers multi-range requests.
        let mut opened = None;
        if multi_range {
            let both = format!("bytes=0-{},-{suffix_len}", PREFIX_LEN - 1);
            match source.fetch(&both, PREFIX_LEN + suffix_len + 1024, false) {
                Ok(a) => opened = Some(a),
                // The server sent the whole object (it ignores ranges, or declines these:
                // nginx does when they overlap, in an object shorter than both): one range
                // a request, in a second round.
                Err(e) if e.kind() == io::ErrorKind::Unsupported => {
                    source.rounds.fetch_add(1, Ordering::Relaxed);
                }
                Err(e) => return Err(io(e)),
            }
        }
        let (answers, multi_range) = match opened {
            Some(a) => {
                let head = covers(&a.parts, 0, PREFIX_LEN.min(a.total));
                let tail = covers(&a.parts, a.total.saturating_sub(suffix_len), a.total);
                if head && tail {
                    (vec![a], true)
                } else {
                    // A server that answered one range of the two: the other in a second
                    // round, and one range a request from now on.
                    source.rounds.fetch_add(1, Ordering::Relaxed);
                    let (range, want) = if head {
                        (format!("bytes=-{suffix_len}"), suffix_len)
                    } else {
                        (format!("bytes=0-{}", PREFIX_LEN - 1), PREFIX_LEN)
                    };
                    let other = source.fetch(&range, want, false).map_err(io)?;
                    (vec![a, other], false)
                }
            }
            None => {
                let prefix = format!("bytes=0-{}", PREFIX_LEN - 1);
                let suffix = format!("bytes=-{suffix_len}");
                let (first, last) = std::thread::scope(|s| {
                    let last = s.spawn(|| source.fetch(&suffix, suffix_len, false));
                    let first = source.fetch(&prefix, PREFIX_LEN, false);
                    (first, last.join())
                });
                let first = first.map_err(io)?;
                let last = last
                    .map_err(|_| Error::Internal("a request thread panicked".into()))?
                    .map_err(io)?;
                (vec![first, last], multi_range)
            }
        };
        let first = &answers[0];
        if answers
            .iter()
            .any(|a| a.total != first.total || a.etag != first.etag)
        {
            return Err(io(failed(format!(
                "{url}: the object changed while it was being opened; open it again"
            ))));
        }
        source.len = first.total;
        source.etag = first.etag.clone();
        let held: Vec<(u64, Arc<[u8]>)> = answers
            .into_iter()
            .flat_map(|a| a.parts)
            .map(|(at, bytes)| (at, bytes.into()))
            .collect();
        source.opened_ranges = held.len();
        source.held = RwLock::new(held);
        source.multi_range = AtomicBool::new(multi_range);
        Ok(source)
    }

    /// What the source has asked its server for so far.
    pub fn request_stats(&self) -> RequestStats {
        RequestStats {
            requests: self.requests.load(Ordering::Relaxed),
            bytes: self.bytes.load(Ordering::Relaxed),
            rounds: self.rounds.load(Ordering::Relaxed),
            retries: self.retries.load(Ordering::Relaxed),
        }
    }

    /// The ETag the source pinned, if the server gave one.
    pub fn etag(&self) -> Option<&str> {
        self.etag.as_deref()
    }

    /// The URL it reads.
    pub fn url(&self) -> &str {
        &self.url
    }

    /// The options it was opened with.
    pub fn options(&self) -> &RemoteOptions {
        &self.options
    }

    /// One request (`range` as the `Range` header says it, `want` body bytes at most),
    /// with retries and backoff.
    fn fetch(&self, range: &str, want: u64, pinned: bool) -> io::Result<Answer> {
        let mut last = None;
        for attempt in 0..self.options.tries.max(1) {
            if attempt > 0 {
                self.retries.fetch_add(1, Ordering::Relaxed);
                std::thread::sleep(self.options.backoff.saturating_mul(1 << (attempt - 1)));
            }
            match self.fetch_once(range, want, pinned) {
                Ok(a) => return Ok(a),
                Err(e) if e.kind() == io::ErrorKind::Interrupted => last = Some(e),
                Err(e) => return Err(e),
            }
        }
        let detail = last.map_or_else(|| "no answer".to_string(), |e| e.to_string());
        Err(failed(format!(
            "{detail} (after {} tries)",
            self.options.tries.max(1)
        )))
    }

    /// One request; failures worth another try come back as `Interrupted`.
    fn fetch_once(&self, range: &str, want: u64, pinned: bool) -> io::Result<Answer> {
        let url = &self.url;
        let mut request = self
            .agent
            .get(self.target.request_url())
            .header("Range", range);
        if let (true, Some(etag)) = (pinned, &self.etag) {
            request = request.header("If-Match", etag);
        }
        self.requests.fetch_add(1, Ordering::Relaxed);
        let mut response = match request.call() {
            Ok(r) => r,
            Err(e) => return Err(retryable(format!("{url}: {e}"))),
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
                return Err(io::Error::new(
                    io::ErrorKind::Unsupported,
                    format!(
                        "{url}: the server ignored the Range header and sent the whole object; \
                         fmrh reads remote containers only from servers that serve byte ranges"
                    ),
                ));
            }
            412 => return Err(self.changed()),
            416 => {
                return Err(failed(format!(
                    "{url}: HTTP 416: the object is empty, too short to be a container"
                )))
            }
            404 | 403 | 401 | 410 => {
                return Err(io::Error::new(
                    io::ErrorKind::NotFound,
                    format!("{url}: HTTP {status}"),
                ))
            }
            429 | 500..=599 => return Err(retryable(format!("{url}: HTTP {status}"))),
            _ => return Err(failed(format!("{url}: HTTP {status}"))),
        }
        let etag = header("etag");
        if pinned && self.etag.is_some() && etag.is_some() && etag != self.etag {
            return Err(self.changed());
        }
        let boundary = header("content-type").and_then(|t| {
            let t = t.trim();
            t.to_ascii_lowercase()
                .starts_with("multipart/byteranges")
                .then(|| {
                    t.split(';')
                        .filter_map(|p| p.trim().strip_prefix("boundary="))
                        .map(|b| b.trim_matches('"').to_string())
                        .next()
                })
                .flatten()
        });
        let single = header("content-range").as_deref().and_then(content_range);
        let body = response
            .body_mut()
            .with_config()
            .limit(want)
            .read_to_vec()
            .map_err(|e| retryable(format!("{url}: {e}")))?;
        self.bytes.fetch_add(body.len() as u64, Ordering::Relaxed);
        let (parts, total) = match (boundary, single) {
            (Some(boundary), _) => multipart(&body, &boundary)
                .map_err(|why| retryable(format!("{url}: a multipart answer {why}")))?,
            (None, Some((start, end, total))) => {
                let expect = end
                    .checked_sub(start)
                    .map(|d| d + 1)
                    .filter(|&n| n <= want && end < total)
                    .ok_or_else(|| failed(format!("{url}: Content-Range {start}-{end}/{total}")))?;
                if (body.len() as u64) != expect {
                    return Err(retryable(format!(
                        "{url}: {} bytes of the {expect} the answer announced",
                        body.len()
                    )));
                }
                (vec![(start, body)], total)
            }
            (None, None) => {
                return Err(failed(format!(
                    "{url}: a 206 answer without a valid Content-Range"
                )))
            }
        };
        if pinned && total != self.len {
            return Err(self.changed());
        }
        Ok(Answer { parts, total, etag })
    }

    /// The error for an object that is no longer the version this reader opened.
    fn changed(&self) -> io::Error {
        failed(format!(
            "{}: the object changed underneath this reader (its ETag is no longer {}); open \
             it again",
            self.url,
            self.etag.as_deref().unwrap_or("what it was")
        ))
    }

    /// Bytes `offset .. offset + len` of the object (checked against its length), pinned.
    fn fetch_range(&self, offset: u64, len: usize) -> io::Result<Vec<u8>> {
        let end = offset + len as u64;
        let answer = self.fetch(&format!("bytes={offset}-{}", end - 1), len as u64, true)?;
        match <[_; 1]>::try_from(answer.parts) {
            Ok([(start, body)]) if start == offset && body.len() == len => Ok(body),
            _ => Err(failed(format!(
                "{}: asked for bytes {offset}..{end}, got something else",
                self.url
            ))),
        }
    }

    /// `ranges` (sorted, disjoint) in one multi-range request, each range's bytes in order.
    /// `Unsupported` when the server does not answer multi-range requests.
    fn fetch_ranges(&self, ranges: &[Range<u64>]) -> io::Result<Vec<Vec<u8>>> {
        let spec: Vec<String> = ranges
            .iter()
            .map(|r| format!("{}-{}", r.start, r.end - 1))
            .collect();
        let sum: u64 = ranges.iter().map(|r| r.end - r.start).sum();
        // Each part's boundary and headers: well under 256 bytes with any real server.
        let want = sum + 256 * ranges.len() as u64 + 1024;
        let answer = self.fetch(&format!("bytes={}", spec.join(",")), want, true)?;
        let mut out = Vec::with_capacity(ranges.len());
        for r in ranges {
            // A server may coalesce ranges into fewer parts: take each from the part that
            // holds it.
            let piece = answer.parts.iter().find_map(|(start, body)| {
                let end = start + body.len() as u64;
                (r.start >= *start && r.end <= end).then(|| {
                    let from = usize::try_from(r.start - start).unwrap_or(usize::MAX);
                    let to = usize::try_from(r.end - start).unwrap_or(usize::MAX);
                    body.get(from..to).map(<[u8]>::to_vec)
                })
            });
            match piece.flatten() {
                Some(p) => out.push(p),
                None => {
                    return Err(io::Error::new(
                        io::ErrorKind::Unsupported,
                        format!("{}: the answer left out a range asked for", self.url),
                    ))
                }
            }
        }
        Ok(out)
    }

    /// `job` run for each of `jobs` over [`RemoteOptions::connections`] threads; counts
    /// `ceil(jobs / connections)` rounds.
    fn parallel<J: Sync, T: Send>(
        &self,
        jobs: &[J],
        job: impl Fn(&J) -> io::Result<T> + Sync,
    ) -> Vec<io::Result<T>> {
        if jobs.is_empty() {
            return Vec::new();
        }
        let connections = self.options.connections.max(1);
        self.rounds
            .fetch_add(jobs.len().div_ceil(connections) as u64, Ordering::Relaxed);
        super::workers::run_bounded(jobs, connections, job)
            .unwrap_or_else(|| vec![Err(failed("a request was not made".into()))])
    }

    /// The held bytes covering `offset .. end`, if any.
    fn held(&self, offset: u64, end: u64) -> io::Result<Option<Vec<u8>>> {
        self.with_held(offset, end, <[u8]>::to_vec)
    }

    /// Whether the bytes `offset .. end` are held (nothing copied).
    fn holds(&self, offset: u64, end: u64) -> io::Result<bool> {
        Ok(self.with_held(offset, end, |_| ())?.is_some())
    }

    /// `f` of the held bytes covering `offset .. end`, if any.
    fn with_held<T>(
        &self,
        offset: u64,
        end: u64,
        f: impl FnOnce(&[u8]) -> T,
    ) -> io::Result<Option<T>> {
        let held = self
            .held
            .read()
            .map_err(|_| failed("the held ranges were poisoned".into()))?;
        for (at, bytes) in held.iter() {
            if offset >= *at && end <= at + bytes.len() as u64 {
                let from = usize::try_from(offset - at).unwrap_or(usize::MAX);
                let to = usize::try_from(end - at).unwrap_or(usize::MAX);
                if let Some(b) = bytes.get(from..to) {
                    return Ok(Some(f(b)));
                }
            }
        }
        Ok(None)
    }

    /// Whether `offset .. end` lies in the advised metadata area, not yet fetched, and
    /// small enough to fetch whole.
    fn area_fetches_whole(&self, offset: u64, end: u64) -> bool {
        self.area.lock().is_ok_and(|a| {
            matches!(&*a, Area::Advised(r) if offset >= r.start && end <= r.end
                && r.end - r.start <= self.options.metadata_limit)
        })
    }

    /// Fetches the advised metadata area if `offset .. end` lies in it and it is small
    /// enough: one round, then held.
    fn fetch_area(&self, offset: u64, end: u64) -> io::Result<()> {
        let area = self
            .area
            .lock()
            .map_err(|_| failed("the metadata area was poisoned".into()))?;
        let Area::Advised(range) = area.clone() else {
            return Ok(());
        };
        if offset < range.start || end > range.end {
            return Ok(());
        }
        let whole = range.end - range.start <= self.options.metadata_limit;
        let fetch = if whole {
            range.clone()
        } else {
            // The aligned chunk (or chunks) of the area holding the read.
            let chunk = self.options.metadata_chunk.max(1);
            let from = range.start + (offset - range.start) / chunk * chunk;
            let to = (range.start + (end - range.start).div_ceil(chunk) * chunk).min(range.end);
            from..to
        };
        // Held while fetching: another reader of the same area waits rather than fetching
        // it again.
        let mut area = area;
        if whole {
            *area = Area::None;
        }
        let len = usize::try_from(fetch.end - fetch.start)
            .map_err(|_| failed("metadata area too large".into()))?;
        self.rounds.fetch_add(1, Ordering::Relaxed);
        let bytes = self.fetch_range(fetch.start, len)?;
        self.hold(vec![(fetch.start, bytes)], whole)?;
        drop(area);
        Ok(())
    }

    /// Holds `pieces` (where each starts, its bytes). Bounded by
    /// [`RemoteOptions::held_limit`]: the oldest pieces go first (a later read fetches them
    /// again), never the ranges opening read, nor these when `keep` (a whole area).
    fn hold(&self, pieces: Vec<(u64, Vec<u8>)>, keep: bool) -> io::Result<()> {
        let mut held = self
            .held
            .write()
            .map_err(|_| failed("the held ranges were poisoned".into()))?;
        let fresh = pieces.len();
        held.extend(pieces.into_iter().map(|(at, b)| (at, Arc::from(b))));
        let mut total: u64 = held.iter().map(|(_, b)| b.len() as u64).sum();
        while total > self.options.held_limit && !keep {
            // The oldest piece that is neither opening's nor one of these.
            let Some(i) = (self.opened_ranges..held.len().saturating_sub(fresh)).next() else {
                break;
            };
            total -= held.remove(i).1.len() as u64;
        }
        Ok(())
    }

    /// `spans` (sorted by start) fetched in one round where the server allows: as
    /// multi-range requests of up to [`MAX_PARTS`] ranges each, else merged across gaps of
    /// [`RemoteOptions::merge_gap`] bytes, one range a request; either way over
    /// [`RemoteOptions::connections`] connections at once. Returns each request's byte range
    /// with the indices of the spans it serves, and its bytes.
    fn fetch_spans(&self, spans: &[(u64, u64)]) -> io::Result<(Requests, Vec<Vec<u8>>)> {
        let mut fetched = None;
        if self.multi_range.load(Ordering::Relaxed) && spans.len() > 1 {
            // Gaps smaller than a part's own headers cost nothing to read.
            let requests = merge(spans, MULTI_RANGE_GAP);
            let groups: Vec<&[(Range<u64>, Vec<usize>)]> = requests.chunks(MAX_PARTS).collect();
            let answers = self.parallel(&groups, |group| {
                let ranges: Vec<Range<u64>> = group.iter().map(|(r, _)| r.clone()).collect();
                self.fetch_ranges(&ranges)
            });
            let mut bodies = Vec::with_capacity(requests.len());
            let mut unsupported = false;
            for answer in answers {
                match answer {
                    Ok(b) => bodies.extend(b),
                    Err(e) if e.kind() == io::ErrorKind::Unsupported => unsupported = true,
                    Err(e) => return Err(e),
                }
            }
            if unsupported {
                // One range a request from now on.
                self.multi_range.store(false, Ordering::Relaxed);
            } else {
                fetched = Some((requests, bodies));
            }
        }
        let (requests, bodies) = match fetched {
            Some(f) => f,
            None => {
                let requests = merge(spans, self.options.merge_gap);
                let bodies = self
                    .parallel(&requests, |(range, _)| {
                        let len = usize::try_from(range.end - range.start).unwrap_or(usize::MAX);
                        self.fetch_range(range.start, len)
                    })
                    .into_iter()
                    .collect::<io::Result<Vec<_>>>()?;
                (requests, bodies)
            }
        };
        Ok((requests, bodies))
    }

    /// Whether batches still go as multi-range requests: the options allow it, the target
    /// is not S3, and the server has answered every one so far. A dataset opens its tiles
    /// with what its manifest's source learned.
    pub fn multi_range(&self) -> bool {
        self.multi_range.load(Ordering::Relaxed)
    }

    /// Bytes held in memory: the ranges opening read and the metadata fetched since.
    pub fn held_bytes(&self) -> u64 {
        self.held
            .read()
            .map(|h| h.iter().map(|(_, b)| b.len() as u64).sum())
            .unwrap_or(0)
    }

    fn check_range(&self, offset: u64, len: usize) -> io::Result<u64> {
        offset
            .checked_add(len as u64)
            .filter(|&e| e <= self.len)
            .ok_or_else(|| {
                io::Error::new(
                    io::ErrorKind::UnexpectedEof,
                    format!("{len} bytes at offset {offset} lie past the end"),
                )
            })
    }
}

/// `ranges` (sorted by start) grouped into requests: neighbours at most `gap` bytes apart
/// share one. Returns each request's byte range and the indices of the ranges it serves.
fn merge(ranges: &[(u64, u64)], gap: u64) -> Vec<(Range<u64>, Vec<usize>)> {
    let mut out: Vec<(Range<u64>, Vec<usize>)> = Vec::new();
    for (i, &(start, end)) in ranges.iter().enumerate() {
        match out.last_mut() {
            Some((r, members)) if start <= r.end.saturating_add(gap) => {
                r.end = r.end.max(end);
                members.push(i);
            }
            _ => out.push((start..end, vec![i])),
        }
    }
    out
}

impl Source for HttpSource {
    fn len(&self) -> u64 {
        self.len
    }

    fn read_at(&self, offset: u64, len: usize) -> io::Result<Cow<'_, [u8]>> {
        let end = self.check_range(offset, len)?;
        if len == 0 {
            return Ok(Cow::Owned(Vec::new()));
        }
        if let Some(b) = self.held(offset, end)? {
            return Ok(Cow::Owned(b));
        }
        self.fetch_area(offset, end)?;
        if let Some(b) = self.held(offset, end)? {
            return Ok(Cow::Owned(b));
        }
        self.rounds.fetch_add(1, Ordering::Relaxed);
        self.fetch_range(offset, len).map(Cow::Owned)
    }

    /// The ranges not already held are fetched in one round where the server allows: as
    /// multi-range requests of up to [`MAX_PARTS`] ranges each, else merged across gaps of
    /// [`RemoteOptions::merge_gap`] bytes, one range a request; either way over
    /// [`RemoteOptions::connections`] connections at once.
    fn read_many(&self, ranges: &[(u64, usize)]) -> io::Result<Vec<Cow<'_, [u8]>>> {
        let mut out: Vec<Option<Vec<u8>>> = vec![None; ranges.len()];
        let mut wanted: Vec<(u64, u64, usize)> = Vec::new();
        for (i, &(offset, len)) in ranges.iter().enumerate() {
            let end = self.check_range(offset, len)?;
            if len == 0 {
                out[i] = Some(Vec::new());
                continue;
            }
            match self.held(offset, end)? {
                Some(b) => out[i] = Some(b),
                None => wanted.push((offset, end, i)),
            }
        }
        wanted.sort_unstable();
        let spans: Vec<(u64, u64)> = wanted.iter().map(|&(a, b, _)| (a, b)).collect();
        let (requests, bodies) = self.fetch_spans(&spans)?;
        for ((range, members), body) in requests.iter().zip(bodies) {
            for &m in members {
                let (offset, end, i) = wanted[m];
                let from = usize::try_from(offset - range.start).unwrap_or(usize::MAX);
                let to = usize::try_from(end - range.start).unwrap_or(usize::MAX);
                let piece = body
                    .get(from..to)
                    .ok_or_else(|| failed("a range outside its request".into()))?;
                out[i] = Some(piece.to_vec());
            }
        }
        out.into_iter()
            .map(|b| {
                b.map(Cow::Owned)
                    .ok_or_else(|| failed("a range was not read".into()))
            })
            .collect()
    }

    /// With `If-Match` on every request the bytes cannot change under the reader.
    fn stable(&self) -> bool {
        true
    }

    fn name(&self) -> &Path {
        &self.name
    }

    fn request_stats(&self) -> Option<RequestStats> {
        Some(HttpSource::request_stats(self))
    }

    fn advise_metadata(&self, area: Range<u64>) {
        let end = area.end.min(self.len);
        if let Ok(mut a) = self.area.lock() {
            *a = Area::Advised(area.start..end);
        }
    }

    fn prefetches(&self) -> bool {
        self.options.read_ahead
    }

    /// The ranges not already held, in one round (as [`Source::read_many`] batches), then
    /// held. A range inside an advised metadata area small enough to fetch whole fetches
    /// the area instead (one round as well, and every later page is then at hand).
    fn prefetch(&self, ranges: &[(u64, usize)]) -> io::Result<()> {
        let mut wanted: Vec<(u64, u64)> = Vec::new();
        for &(offset, len) in ranges {
            let end = self.check_range(offset, len)?;
            if len == 0 || self.holds(offset, end)? {
                continue;
            }
            if self.area_fetches_whole(offset, end) {
                self.fetch_area(offset, end)?;
                if self.holds(offset, end)? {
                    continue;
                }
            }
            wanted.push((offset, end));
        }
        if wanted.is_empty() {
            return Ok(());
        }
        wanted.sort_unstable();
        let (requests, bodies) = self.fetch_spans(&wanted)?;
        let pieces = requests
            .into_iter()
            .zip(bodies)
            .map(|((range, _), body)| (range.start, body))
            .collect();
        self.hold(pieces, false)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn content_ranges_parse_and_bad_ones_do_not() {
        assert_eq!(content_range("bytes 0-99/1000"), Some((0, 99, 1000)));
        assert_eq!(content_range(" bytes 5-5/6 "), Some((5, 5, 6)));
        assert_eq!(content_range("bytes */1000"), None);
        assert_eq!(content_range("items 0-1/2"), None);
    }

    #[test]
    fn multipart_bodies_give_their_parts_and_bad_ones_an_error() {
        let body = b"\r\n--B\r\nContent-Type: x\r\nContent-Range: bytes 2-4/10\r\n\r\nabc\r\n\
                     --B\r\ncontent-range: bytes 7-7/10\r\n\r\nz\r\n--B--\r\n";
        let (parts, total) = multipart(body, "B").unwrap();
        assert_eq!(total, 10);
        assert_eq!(parts, vec![(2, b"abc".to_vec()), (7, b"z".to_vec())]);
        // Cut short, a part without its range, a range past the object, another boundary.
        assert!(multipart(&body[..40], "B").is_err());
        assert!(multipart(b"--B\r\n\r\nabc\r\n--B--\r\n", "B").is_err());
        assert!(multipart(
            b"--B\r\nContent-Range: bytes 2-40/10\r\n\r\nabc\r\n--B--\r\n",
            "B"
        )
        .is_err());
        assert!(multipart(body, "C").is_err());
        assert!(multipart(b"--B--\r\n", "B").is_err());
    }

    proptest::proptest! {
        /// Whatever a server sends, parsing gives parts or an error, never a panic; a body
        /// made of real parts gives exactly those parts back.
        #[test]
        fn multipart_parsing_is_total_and_exact(
            junk in proptest::collection::vec(proptest::num::u8::ANY, 0..300),
            parts in proptest::collection::vec(
                (0u64..1000, proptest::collection::vec(proptest::num::u8::ANY, 1..40)),
                1..6,
            ),
            cut in 0usize..2000,
        ) {
            let _ = multipart(&junk, "B");
            let total = 2000;
            let mut body = Vec::new();
            for (start, bytes) in &parts {
                body.extend_from_slice(
                    format!(
                        "\r\n--B\r\nContent-Range: bytes {start}-{}/{total}\r\n\r\n",
                        start + bytes.len() as u64 - 1
                    )
                    .as_bytes(),
                );
                body.extend_from_slice(bytes);
            }
            body.extend_from_slice(b"\r\n--B--\r\n");
            let (got, t) = multipart(&body, "B").unwrap();
            proptest::prop_assert_eq!(t, total);
            proptest::prop_assert_eq!(&got, &parts);
            // Cut anywhere short of its end: an error or fewer parts, never other bytes.
            if cut < body.len() {
                if let Ok((some, _)) = multipart(&body[..cut], "B") {
                    proptest::prop_assert!(some.len() <= parts.len());
                    proptest::prop_assert_eq!(&some[..], &parts[..some.len()]);
                }
            }
        }
    }

    #[test]
    fn ranges_merge_across_small_gaps_only() {
        let r = [(0, 10), (12, 20), (100, 110), (105, 130), (200, 201)];
        let m = merge(&r, 2);
        let spans: Vec<_> = m.iter().map(|(s, _)| s.clone()).collect();
        assert_eq!(spans, vec![0..20, 100..130, 200..201]);
        assert_eq!(m[1].1, vec![2, 3]);
        assert_eq!(merge(&r, 0).len(), 4);
        assert_eq!(merge(&r, 1000).len(), 1);
        assert!(merge(&[], 5).is_empty());
    }

    #[test]
    fn s3_urls_need_a_bucket_and_a_key() {
        assert!(Target::parse("s3://bucket").is_err());
        assert!(Target::parse("s3:///key").is_err());
        assert!(Target::parse("s3://bucket/").is_err());
        assert!(Target::parse("s3://bucket/a/b.fmrh").is_ok());
        assert!(matches!(
            Target::parse("http://h/x"),
            Ok(Target::Http(u)) if u == "http://h/x"
        ));
    }
}
