//! Fuzz target: a container from the fuzzer, read and verified. Opening, reading and verifying
//! (fast and full) must return a value or an error: never panic, hang or allocate from an
//! unchecked size. And the validator and the reader must agree: a file `verify --full` calls
//! valid opens and reads whole without a corruption error.
//!
//! The first byte picks the mode:
//!
//! * **raw** (even): the rest is the file, byte for byte. The seeds and the dictionary
//!   (`fuzz/container.dict`: magic, tags, page sizes) get it past the magic.
//! * **structure-aware** (odd): the rest edits a valid container (a golden vector, chosen by
//!   the second byte): 4-byte edits, each a 3-byte offset and a value, then every checksum is
//!   made right again, the commit records' and every structured page's (a page is structured
//!   when it starts with a known tag). Random bytes rarely pass a CRC, so without this mode the
//!   fuzzer stops at the checksums; with it, damage reaches the tables, the trees, the
//!   directory and the records behind them. In a file whose metadata is a compressed bundle
//!   (format 3.0), an edit whose offset has its top bit set lands in the decompressed bundle
//!   pages, which are then resealed, compressed again and named by the record.
//!
//! cargo fuzz run --sanitizer none open_verify fuzz/corpus/open_verify -- -dict=fuzz/container.dict

#![no_main]

use libfuzzer_sys::fuzz_target;

mod open_verify_input;

fuzz_target!(|data: &[u8]| open_verify_input::run(data));
