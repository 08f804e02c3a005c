//! Fuzz target: what a server answers the remote reader (`src/store/remote/wire.rs`): a
//! `multipart/byteranges` body under a boundary, and a `Content-Range` value. Each must parse
//! to parts that are what they say (every part's bytes exactly its range's length, its range
//! inside the object, one object length for all) or be refused: never a panic, a hang, or an
//! allocation larger than the body.
//!
//! The first byte is the boundary's length (mod 71, RFC 2046's limit is 70); the boundary
//! follows, then the body.
//!
//! cargo fuzz run --sanitizer none remote_response corpus/remote_response

#![no_main]

use libfuzzer_sys::fuzz_target;

mod remote_response_input;

fuzz_target!(|data: &[u8]| remote_response_input::run(data));
