//! The fuzz target's input handling (shared with `tests/fuzz_regressions.rs`, which
//! replays the corpus through it): the request heads `fmrh serve` reads (`src/http/`), from the fuzzer's bytes as
//! one connection would send them, pipelined, and each request's `Range` header against an
//! object. Each head must be a request, a refusal with a status the server sends (400, 408,
//! 431, 505) or the end of the connection: never a panic, a hang, or a head larger than the
//! limit. Each answered range must lie inside the object, no more than the cap of them,
//! adding up to at most twice the object when there are several; their multipart heads one
//! per range.

use fmrh::http::ranges::{self, Asked, MAX_RANGES};
use fmrh::http::{read_head, Head, MAX_HEAD};

/// One input, as the target takes it.
pub fn run(data: &[u8]) {
    // The object's length: from the first bytes, so that it varies with the input.
    let len = data.get(..4).map_or(0, |b| {
        u64::from(u32::from_le_bytes(b.try_into().unwrap_or([0; 4])))
    });
    let mut reader: &[u8] = data.get(4..).unwrap_or(&[]);
    for _ in 0..64 {
        let before = reader.len();
        match read_head(&mut reader) {
            Ok(Head::Request(request, _)) => {
                assert!(
                    before - reader.len() <= MAX_HEAD + 2,
                    "a head past the limit"
                );
                assert!(request.target.starts_with('/'));
                assert!(!request.method.is_empty());
                match ranges::parse(request.header("Range"), len) {
                    Asked::Ranges(rs) => {
                        assert!(!rs.is_empty() && rs.len() <= MAX_RANGES);
                        for r in &rs {
                            assert!(r.start < r.end && r.end <= len, "{r:?} of {len}");
                        }
                        let total: u64 = rs.iter().map(|r| r.end - r.start).sum();
                        assert!(rs.len() == 1 || total <= len.saturating_mul(2));
                        let (parts, _) = ranges::multipart_heads(&rs, len, "b");
                        assert_eq!(parts.len(), rs.len());
                    }
                    Asked::Unsatisfiable | Asked::Whole => {}
                }
            }
            Ok(Head::Bad(status, _)) => {
                assert!(matches!(status, 400 | 408 | 431 | 505), "status {status}");
                break;
            }
            Ok(Head::Closed) | Err(_) => break,
        }
    }
}
