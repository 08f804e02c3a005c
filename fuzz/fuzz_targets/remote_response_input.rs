//! The fuzz target's input handling (shared with `tests/fuzz_regressions.rs`, which
//! replays the corpus through it): what a server answers the remote reader (`src/store/remote/wire.rs`): a
//! `multipart/byteranges` body under a boundary, and a `Content-Range` value. Each must parse
//! to parts that are what they say (every part's bytes exactly its range's length, its range
//! inside the object, one object length for all) or be refused: never a panic, a hang, or an
//! allocation larger than the body.
//!
//! The first byte is the boundary's length (mod 71, RFC 2046's limit is 70); the boundary
//! follows, then the body.

use fmrh::store::remote::parse::{content_range, multipart};

/// One input, as the target takes it.
pub fn run(data: &[u8]) {
    let Some((&n, rest)) = data.split_first() else {
        return;
    };
    let n = usize::from(n) % 71;
    let Some(boundary) = rest.get(..n) else {
        return;
    };
    let body = &rest[n..];
    let boundary = String::from_utf8_lossy(boundary);
    if let Ok((parts, total)) = multipart(body, &boundary) {
        let mut bytes = 0usize;
        for (start, part) in &parts {
            assert!(!part.is_empty());
            assert!(start.saturating_add(part.len() as u64) <= total);
            bytes += part.len();
        }
        assert!(bytes <= body.len(), "parts hold more than the body");
    }
    // A `Content-Range` value: any text parses to numbers or to nothing, without a panic
    // (the reader checks the numbers against what it asked before it trusts them).
    let _ = std::str::from_utf8(body).ok().and_then(content_range);
}
