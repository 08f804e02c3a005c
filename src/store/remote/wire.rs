//! One range request and its answer, on the wire: the `Range` and `If-Match` headers out,
//! the status, `Content-Range`, ETag and `multipart/byteranges` body back, with retries and
//! backoff for what is worth another try. [`Client`] pins the version it opened (its length
//! and ETag) and counts what it asked for; it knows nothing of rounds or of what is held
//! (the source around it, `super`, decides those).

use std::io;
use std::ops::Range;
use std::sync::atomic::{AtomicU64, Ordering};
use std::time::Duration;

use super::target::Target;
use super::RemoteOptions;
use crate::error::Result;
use crate::store::source::RequestStats;

/// The requests of one remote object: where they go, the version they are pinned to, and
/// what they cost.
pub(super) struct Client {
    pub(super) url: String,
    target: Target,
    agent: ureq::Agent,
    tries: u32,
    backoff: Duration,
    /// The object's length, pinned at open.
    pub(super) len: u64,
    /// The object's ETag, pinned at open (if the server gave one).
    pub(super) etag: Option<String>,
    requests: AtomicU64,
    bytes: AtomicU64,
    /// Rounds of requests: counted by the source, which decides what goes together.
    pub(super) rounds: AtomicU64,
    retries: AtomicU64,
}

impl Client {
    /// A client for `url` (`http://`, `https://` or `s3://`), not yet pinned.
    pub(super) fn new(url: &str, options: &RemoteOptions) -> Result<Client> {
        let agent: ureq::Agent = ureq::Agent::config_builder()
            .http_status_as_error(false)
            .timeout_connect(Some(Duration::from_secs(10).min(options.timeout)))
            .timeout_global(Some(options.timeout))
            .max_idle_connections_per_host(options.connections.max(1))
            .build()
            .into();
        Ok(Client {
            url: url.to_string(),
            target: Target::parse(url)?,
            agent,
            tries: options.tries,
            backoff: options.backoff,
            len: 0,
            etag: None,
            requests: 0.into(),
            bytes: 0.into(),
            rounds: 0.into(),
            retries: 0.into(),
        })
    }

    /// Whether requests go to S3 (which answers one range a request).
    pub(super) fn is_s3(&self) -> bool {
        matches!(self.target, Target::S3 { .. })
    }

    /// What the client has asked its server for so far.
    pub(super) fn stats(&self) -> RequestStats {
        RequestStats {
            requests: self.requests.load(Ordering::Relaxed),
            bytes: self.bytes.load(Ordering::Relaxed),
            rounds: self.rounds.load(Ordering::Relaxed),
            retries: self.retries.load(Ordering::Relaxed),
        }
    }

    /// One request (`range` as the `Range` header says it, `want` body bytes at most),
    /// with retries and backoff.
    pub(super) fn fetch(&self, range: &str, want: u64, pinned: bool) -> io::Result<Answer> {
        let mut last = None;
        for attempt in 0..self.tries.max(1) {
            if attempt > 0 {
                self.retries.fetch_add(1, Ordering::Relaxed);
                std::thread::sleep(self.backoff.saturating_mul(1 << (attempt - 1)));
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
            self.tries.max(1)
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
        io::Error::other(crate::error::ObjectChanged(format!(
            "{}: the object changed underneath this reader (its ETag or length is no longer \
             {} bytes, {}); open it again",
            self.url,
            self.len,
            self.etag.as_deref().unwrap_or("no ETag")
        )))
    }

    /// Bytes `offset .. offset + len` of the object (checked against its length), pinned.
    pub(super) fn fetch_range(&self, offset: u64, len: usize) -> io::Result<Vec<u8>> {
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
    pub(super) fn fetch_ranges(&self, ranges: &[Range<u64>]) -> io::Result<Vec<Vec<u8>>> {
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
}

/// Parts of an answer: where each starts, and its bytes.
pub type Parts = Vec<(u64, Vec<u8>)>;

/// Requests of a batch: each one's byte range, and the indices of the spans it serves.
pub(super) type Requests = Vec<(Range<u64>, Vec<usize>)>;

/// One answer to a range request.
pub(super) struct Answer {
    /// Its parts: where each starts, and its bytes (one part unless `multipart/byteranges`).
    pub(super) parts: Parts,
    /// The object's total length (`Content-Range`).
    pub(super) total: u64,
    pub(super) etag: Option<String>,
}

/// The parts of a `multipart/byteranges` body (RFC 9110 §14.6): each part's start and
/// bytes, and the object's length. Every part must say its range, all the same length.
pub fn multipart(
    body: &[u8],
    boundary: &str,
) -> std::result::Result<(Parts, u64), String> {
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
pub(super) fn retryable(detail: String) -> io::Error {
    io::Error::new(io::ErrorKind::Interrupted, detail)
}

pub(super) fn failed(detail: String) -> io::Error {
    io::Error::other(detail)
}

/// `Content-Range: bytes a-b/total` as `(a, b, total)`.
pub fn content_range(value: &str) -> Option<(u64, u64, u64)> {
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
pub(super) fn covers(parts: &[(u64, Vec<u8>)], from: u64, to: u64) -> bool {
    from >= to
        || parts
            .iter()
            .any(|(at, b)| *at <= from && at.saturating_add(b.len() as u64) >= to)
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
}
