//! HTTP byte ranges (RFC 9110 §14): what a `Range` header asks of an object of a given
//! length, and the `multipart/byteranges` body that answers several ranges at once. Pure
//! functions, no I/O: the server reads the bytes, this says which.
//!
//! The remote reader (`src/store/remote/`) opens a container with one multi-range request
//! (its first 4 KiB and its last 36 KiB) and reads payloads with single ranges, so a server
//! it can use answers both; this module follows the RFC where the reader does not care
//! either: a header that does not parse is ignored (the whole object, `200`), a satisfiable
//! range is clipped to the object, and a set of ranges none of which is satisfiable is a
//! `416`.

use std::ops::Range;

/// Ranges one request may ask for before the server answers with the whole object instead
/// (the remote reader asks for at most 128, its `MAX_PARTS`).
pub const MAX_RANGES: usize = 256;

/// What a `Range` header asks of an object.
#[derive(Clone, Debug, PartialEq, Eq)]
pub enum Asked {
    /// No header, or one this server ignores (not `bytes`, malformed, too many ranges, or
    /// ranges that add up to more than twice the object): `200` with the whole object.
    Whole,
    /// The satisfiable ranges, clipped to the object, in the order asked: `206`.
    Ranges(Vec<Range<u64>>),
    /// Well formed, but no range starts inside the object: `416`.
    Unsatisfiable,
}

/// Parses `header` (the `Range` header's value, if any) against an object of `len` bytes.
pub fn parse(header: Option<&str>, len: u64) -> Asked {
    let Some(header) = header else {
        return Asked::Whole;
    };
    let Some((unit, specs)) = header.split_once('=') else {
        return Asked::Whole;
    };
    if !unit.trim().eq_ignore_ascii_case("bytes") {
        return Asked::Whole;
    }
    let mut ranges = Vec::new();
    let mut asked = 0usize;
    for spec in specs.split(',') {
        let spec = spec.trim();
        if spec.is_empty() {
            // RFC 9110's list syntax allows empty elements.
            continue;
        }
        asked += 1;
        if asked > MAX_RANGES {
            return Asked::Whole;
        }
        let Some((first, last)) = spec.split_once('-') else {
            return Asked::Whole;
        };
        let number = |t: &str| -> Option<u64> {
            (!t.is_empty() && t.bytes().all(|b| b.is_ascii_digit()))
                .then(|| t.parse().ok())
                .flatten()
        };
        let range = match (first.trim(), last.trim()) {
            ("", suffix) => {
                // The last `n` bytes.
                let Some(n) = number(suffix) else {
                    return Asked::Whole;
                };
                (n > 0 && len > 0).then(|| len.saturating_sub(n)..len)
            }
            (first, "") => {
                let Some(a) = number(first) else {
                    return Asked::Whole;
                };
                (a < len).then_some(a..len)
            }
            (first, last) => {
                let (Some(a), Some(b)) = (number(first), number(last)) else {
                    return Asked::Whole;
                };
                if b < a {
                    // An invalid range-spec makes the whole header invalid.
                    return Asked::Whole;
                }
                (a < len).then(|| a..b.saturating_add(1).min(len))
            }
        };
        ranges.extend(range);
    }
    if asked == 0 {
        return Asked::Whole;
    }
    if ranges.is_empty() {
        return Asked::Unsatisfiable;
    }
    // Overlapping ranges could ask for the object many times over (RFC 9110 §14.2 lets a
    // server refuse them): past twice its length, the object once.
    let total: u64 = ranges.iter().map(|r| r.end - r.start).sum();
    if ranges.len() > 1 && total > len.saturating_mul(2) {
        return Asked::Whole;
    }
    Asked::Ranges(ranges)
}

/// `Content-Range` for `range` of an object of `len` bytes.
pub fn content_range(range: &Range<u64>, len: u64) -> String {
    format!("bytes {}-{}/{len}", range.start, range.end - 1)
}

/// One part of a `multipart/byteranges` body: its head, then the bytes of its range.
pub type Part = (Vec<u8>, Range<u64>);

/// The `multipart/byteranges` body answering `ranges` of an object of `len` bytes with
/// `boundary`, as the head of each part (its delimiter, `Content-Type` and `Content-Range`)
/// beside its range, and the closing delimiter. The server sends each head and then the
/// range's bytes from the file, so an answer costs no memory in proportion to its parts.
pub fn multipart_heads(
    ranges: &[Range<u64>],
    len: u64,
    boundary: &str,
) -> (Vec<Part>, Vec<u8>) {
    let parts = ranges
        .iter()
        .map(|r| {
            let head = format!(
                "\r\n--{boundary}\r\nContent-Type: application/octet-stream\r\nContent-Range: {}\r\n\r\n",
                content_range(r, len)
            );
            (head.into_bytes(), r.clone())
        })
        .collect();
    (parts, format!("\r\n--{boundary}--\r\n").into_bytes())
}

/// The whole `multipart/byteranges` body, `read(range)` giving each range's bytes (what
/// [`multipart_heads`] describes, gathered: for tests).
#[cfg(test)]
pub fn multipart<E>(
    ranges: &[Range<u64>],
    len: u64,
    boundary: &str,
    mut read: impl FnMut(&Range<u64>) -> Result<Vec<u8>, E>,
) -> Result<Vec<u8>, E> {
    let (parts, end) = multipart_heads(ranges, len, boundary);
    let mut body = Vec::new();
    for (head, r) in parts {
        body.extend_from_slice(&head);
        body.extend_from_slice(&read(&r)?);
    }
    body.extend_from_slice(&end);
    Ok(body)
}

#[cfg(test)]
// A one-element `Vec` of a range is what `Asked::Ranges` holds for one range.
#[allow(clippy::single_range_in_vec_init)]
mod tests {
    use super::*;
    use proptest::prelude::*;

    #[test]
    fn forms_of_a_range() {
        let r = |h: &str| parse(Some(h), 100);
        assert_eq!(parse(None, 100), Asked::Whole);
        assert_eq!(r("bytes=0-9"), Asked::Ranges(vec![0..10]));
        assert_eq!(r("bytes=90-"), Asked::Ranges(vec![90..100]));
        assert_eq!(r("bytes=-10"), Asked::Ranges(vec![90..100]));
        assert_eq!(r("bytes=-1000"), Asked::Ranges(vec![0..100]));
        assert_eq!(r("bytes=95-1000"), Asked::Ranges(vec![95..100]));
        assert_eq!(r("BYTES = 0-0, -1"), Asked::Ranges(vec![0..1, 99..100]));
        assert_eq!(
            r("bytes=0-4351,-36864"),
            Asked::Ranges(vec![0..100, 0..100])
        );
        // Unsatisfiable: nothing starts inside.
        assert_eq!(r("bytes=100-"), Asked::Unsatisfiable);
        assert_eq!(r("bytes=-0"), Asked::Unsatisfiable);
        assert_eq!(parse(Some("bytes=-5"), 0), Asked::Unsatisfiable);
        // One satisfiable range of two is answered alone.
        assert_eq!(r("bytes=200-300,5-6"), Asked::Ranges(vec![5..7]));
        // Ignored: not bytes, malformed, reversed.
        for h in [
            "items=0-1",
            "bytes",
            "bytes=",
            "bytes=a-b",
            "bytes=5-4",
            "bytes=1",
            "bytes=+1-2",
            "bytes=0-1-2",
        ] {
            assert_eq!(r(h), Asked::Whole, "{h}");
        }
        // Too many, or the object many times over.
        let many = vec!["0-0"; MAX_RANGES + 1].join(",");
        assert_eq!(r(&format!("bytes={many}")), Asked::Whole);
        assert_eq!(r("bytes=0-,0-,0-"), Asked::Whole);
    }

    #[test]
    fn a_multipart_body_says_where_each_part_lies() {
        let object: Vec<u8> = (0..20).collect();
        let body = multipart(&[2..5, 10..11], 20, "B", |r| {
            Ok::<_, ()>(object[r.start as usize..r.end as usize].to_vec())
        })
        .unwrap_or_default();
        let mut expected = b"\r\n--B\r\nContent-Type: application/octet-stream\r\nContent-Range: bytes 2-4/20\r\n\r\n".to_vec();
        expected.extend_from_slice(&[2, 3, 4]);
        expected.extend_from_slice(
            b"\r\n--B\r\nContent-Type: application/octet-stream\r\nContent-Range: bytes 10-10/20\r\n\r\n",
        );
        expected.push(10);
        expected.extend_from_slice(b"\r\n--B--\r\n");
        assert_eq!(body, expected);
    }

    proptest! {
        /// Any header: no panic, and every range answered is non-empty and inside the object.
        #[test]
        fn answered_ranges_lie_inside_the_object(header in "[ -~]{0,40}", len in 0u64..1000) {
            if let Asked::Ranges(ranges) = parse(Some(&header), len) {
                prop_assert!(!ranges.is_empty());
                for r in ranges {
                    prop_assert!(r.start < r.end && r.end <= len, "{r:?} of {len}");
                }
            }
        }

        /// A well-formed `a-b` is answered with exactly its bytes clipped to the object.
        #[test]
        fn a_closed_range_is_clipped(a in 0u64..2000, n in 0u64..2000, len in 0u64..1000) {
            let asked = parse(Some(&format!("bytes={a}-{}", a + n)), len);
            if a < len {
                prop_assert_eq!(asked, Asked::Ranges(vec![a..(a + n + 1).min(len)]));
            } else {
                prop_assert_eq!(asked, Asked::Unsatisfiable);
            }
        }
    }
}
