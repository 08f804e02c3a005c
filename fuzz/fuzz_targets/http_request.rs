//! Fuzz target: the request heads `fmrh serve` reads (`src/http/`), from the fuzzer's bytes as
//! one connection would send them, pipelined, and each request's `Range` header against an
//! object. Each head must be a request, a refusal with a status the server sends (400, 408,
//! 431, 505) or the end of the connection: never a panic, a hang, or a head larger than the
//! limit. Each answered range must lie inside the object, no more than the cap of them,
//! adding up to at most twice the object when there are several; their multipart heads one
//! per range.
//!
//! cargo fuzz run --sanitizer none http_request corpus/http_request

#![no_main]

use libfuzzer_sys::fuzz_target;

mod http_request_input;

fuzz_target!(|data: &[u8]| http_request_input::run(data));
