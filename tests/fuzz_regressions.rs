//! The fuzz corpora in `fuzz/corpus/` (the seeds, and every input that once made a target
//! panic, named `regress-*`) replay on every test run through the targets' own input handling:
//! no input may panic, and a file the validator calls valid must open and read whole.
//! Found by `open_verify`'s structure-aware mode (issue 13): a node whose parent's level is 255
//! (`level + 1` overflowed in the validator), and a physical block with a subtree (the
//! validator asked whether level `L + 1` exists).

#[path = "../fuzz/fuzz_targets/http_request_input.rs"]
mod http_request_input;
#[path = "../fuzz/fuzz_targets/open_verify_input.rs"]
mod open_verify_input;
#[cfg(feature = "remote")]
#[path = "../fuzz/fuzz_targets/remote_response_input.rs"]
mod remote_response_input;

use std::path::PathBuf;

fn corpus(target: &str) -> Vec<(PathBuf, Vec<u8>)> {
    let dir = PathBuf::from(env!("CARGO_MANIFEST_DIR"))
        .join("fuzz/corpus")
        .join(target);
    let mut files: Vec<_> = std::fs::read_dir(&dir)
        .unwrap_or_else(|e| panic!("{}: {e}", dir.display()))
        .map(|e| e.unwrap().path())
        .collect();
    files.sort();
    files
        .into_iter()
        .map(|p| {
            let bytes = std::fs::read(&p).unwrap();
            (p, bytes)
        })
        .collect()
}

#[test]
fn open_verify_corpus_replays() {
    let inputs = corpus("open_verify");
    assert!(inputs
        .iter()
        .any(|(p, _)| p.to_string_lossy().contains("regress-")));
    for (path, bytes) in inputs {
        eprintln!("{}", path.display());
        open_verify_input::run(&bytes);
    }
}

#[test]
fn http_request_corpus_replays() {
    let inputs = corpus("http_request");
    assert!(!inputs.is_empty());
    for (path, bytes) in inputs {
        eprintln!("{}", path.display());
        http_request_input::run(&bytes);
    }
}

#[cfg(feature = "remote")]
#[test]
fn remote_response_corpus_replays() {
    let inputs = corpus("remote_response");
    assert!(!inputs.is_empty());
    for (path, bytes) in inputs {
        eprintln!("{}", path.display());
        remote_response_input::run(&bytes);
    }
}
