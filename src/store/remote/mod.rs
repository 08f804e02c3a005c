//! A container read over HTTP(S) range requests or the S3 API (issue 17,
//! `docs/remote-design.md`): [`HttpSource`] decides what to fetch in which round and holds
//! what it fetched; `wire` makes one request and reads its answer; `target` says where a
//! request goes (a URL, or a presigned S3 `GET`).
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
//! * **Metadata, a round per tree level at most:** a state with a top of the tree (format
//!   6.2) advises nothing: its scenes name the subtrees they refine into, one round. Otherwise,
//!   after opening, the store advises where
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

mod target;
mod wire;

/// The response parsers, for the fuzz targets: a `multipart/byteranges` body and a
/// `Content-Range` value, as the reader takes them from a server.
#[cfg(feature = "testing")]
pub mod parse {
    pub use super::wire::{content_range, multipart};
}

use std::borrow::Cow;
use std::io;
use std::ops::Range;
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::{Arc, Mutex, RwLock};
use std::time::Duration;

pub use super::source::RequestStats;
use super::source::Source;
use crate::error::{Error, Result};
use wire::{covers, failed, Client, Requests};

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

#[cfg(any(test, feature = "testing"))]
pub use super::any::is_url;

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
    /// Its requests, and the version they are pinned to.
    client: Client,
    name: PathBuf,
    options: RemoteOptions,
    /// Ranges held in memory: the prefix, the suffix, the metadata area.
    held: RwLock<Vec<(u64, Arc<[u8]>)>>,
    /// How many of `held` opening read (kept whatever the bound).
    opened_ranges: usize,
    area: Mutex<Area>,
    /// Whether batches still go as multi-range requests.
    multi_range: AtomicBool,
}

impl std::fmt::Debug for HttpSource {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("HttpSource")
            .field("url", &self.client.url)
            .field("len", &self.client.len)
            .field("etag", &self.client.etag)
            .finish_non_exhaustive()
    }
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
        let mut source = HttpSource {
            client: Client::new(url, &options)?,
            name: PathBuf::from(url),
            options,
            held: RwLock::new(Vec::new()),
            opened_ranges: 0,
            area: Mutex::new(Area::None),
            multi_range: AtomicBool::new(false),
        };
        let s3 = source.client.is_s3();
        let multi_range = source.options.multi_range && !s3;
        let suffix_len = source.options.suffix_len.max(1);
        let io = |e| Error::io(Path::new(url), e);
        source.client.rounds.fetch_add(1, Ordering::Relaxed);
        // One request for both ends where the server answers multi-range requests.
        let mut opened = None;
        if multi_range {
            let both = format!("bytes=0-{},-{suffix_len}", PREFIX_LEN - 1);
            match source
                .client
                .fetch(&both, PREFIX_LEN + suffix_len + 1024, false)
            {
                Ok(a) => opened = Some(a),
                // The server sent the whole object (it ignores ranges, or declines these:
                // nginx does when they overlap, in an object shorter than both): one range
                // a request, in a second round.
                Err(e) if e.kind() == io::ErrorKind::Unsupported => {
                    source.client.rounds.fetch_add(1, Ordering::Relaxed);
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
                    source.client.rounds.fetch_add(1, Ordering::Relaxed);
                    let (range, want) = if head {
                        (format!("bytes=-{suffix_len}"), suffix_len)
                    } else {
                        (format!("bytes=0-{}", PREFIX_LEN - 1), PREFIX_LEN)
                    };
                    let other = source.client.fetch(&range, want, false).map_err(io)?;
                    (vec![a, other], false)
                }
            }
            None => {
                let prefix = format!("bytes=0-{}", PREFIX_LEN - 1);
                let suffix = format!("bytes=-{suffix_len}");
                let (first, last) = std::thread::scope(|s| {
                    let last = s.spawn(|| source.client.fetch(&suffix, suffix_len, false));
                    let first = source.client.fetch(&prefix, PREFIX_LEN, false);
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
        source.client.len = first.total;
        source.client.etag = first.etag.clone();
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
        self.client.stats()
    }

    /// The ETag the source pinned, if the server gave one.
    pub fn etag(&self) -> Option<&str> {
        self.client.etag.as_deref()
    }

    /// The URL it reads.
    pub fn url(&self) -> &str {
        &self.client.url
    }

    /// The options it was opened with.
    pub fn options(&self) -> &RemoteOptions {
        &self.options
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
        self.client
            .rounds
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
        self.client.rounds.fetch_add(1, Ordering::Relaxed);
        let bytes = self.client.fetch_range(fetch.start, len)?;
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
                self.client.fetch_ranges(&ranges)
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
                        self.client.fetch_range(range.start, len)
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
            .filter(|&e| e <= self.client.len)
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
        self.client.len
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
        self.client.rounds.fetch_add(1, Ordering::Relaxed);
        self.client.fetch_range(offset, len).map(Cow::Owned)
    }

    /// The ranges not already held are fetched in one round where the server allows: as
    /// multi-range requests of up to [`MAX_PARTS`] ranges each, else merged across gaps of
    /// [`RemoteOptions::merge_gap`] bytes, one range a request; either way over
    /// [`RemoteOptions::connections`] connections at once.
    /// One range request, past the ranges held (the prefix with the slots was fetched at
    /// open): with no usable ETag, only a fresh read sees a re-upload of the same length.
    fn read_fresh(&self, offset: u64, len: usize) -> io::Result<Cow<'_, [u8]>> {
        self.check_range(offset, len)?;
        if len == 0 {
            return Ok(Cow::Owned(Vec::new()));
        }
        self.client.rounds.fetch_add(1, Ordering::Relaxed);
        self.client.fetch_range(offset, len).map(Cow::Owned)
    }

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
        let end = area.end.min(self.client.len);
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
}
