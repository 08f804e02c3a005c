//! The crate's rooms are layered one way (ARCHITECTURE.md): every `crate::ROOM` a source file
//! names, in code or in an intra-doc link, is a room of its own layer or one below. This reads
//! `src/` as text, so a new import that runs back up (a format that reaches for the store, a
//! scene that reaches for a mesh) fails here, naming the file, the line and the rooms.

use std::path::{Path, PathBuf};

/// The layers, bottom first; rooms of one layer may use each other.
const LAYERS: &[&[&str]] = &[
    &[
        "curve", "codec", "globe", "geoid", "crs", "error", "progress", "http",
    ],
    &["heightfield"],
    &["model"],
    &["format"],
    &["store", "ingest"],
    &["scene"],
    &["mesh", "render", "export"],
    &["dataset"],
    &["terrain"],
    &["pyramid"],
    &["cli"],
];

fn layer(room: &str) -> Option<usize> {
    LAYERS.iter().position(|l| l.contains(&room))
}

fn rust_files(dir: &Path, out: &mut Vec<PathBuf>) {
    for e in std::fs::read_dir(dir).unwrap() {
        let p = e.unwrap().path();
        if p.is_dir() {
            rust_files(&p, out);
        } else if p.extension().is_some_and(|x| x == "rs") {
            out.push(p);
        }
    }
}

#[test]
fn every_room_uses_only_its_layer_and_those_below() {
    let src = PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("src");
    let mut files = Vec::new();
    rust_files(&src, &mut files);
    files.sort();
    let mut checked = 0;
    let mut back = Vec::new();
    for f in &files {
        let rel = f.strip_prefix(&src).unwrap();
        let first = rel
            .components()
            .next()
            .unwrap()
            .as_os_str()
            .to_string_lossy();
        let room = first.trim_end_matches(".rs").to_string();
        let Some(own) = layer(&room) else {
            // lib.rs and main.rs stand above every room.
            assert!(
                ["lib", "main"].contains(&room.as_str()),
                "{}: a room no layer names; add it to LAYERS and ARCHITECTURE.md",
                rel.display()
            );
            continue;
        };
        let text = std::fs::read_to_string(f).unwrap();
        for (n, line) in text.lines().enumerate() {
            for (at, _) in line.match_indices("crate::") {
                // `fmrh::crate::` never occurs; a word before `crate` (e.g. `$crate`) is not ours.
                if line[..at].ends_with(|c: char| c.is_alphanumeric() || c == '_' || c == '$') {
                    continue;
                }
                let name: String = line[at + 7..]
                    .chars()
                    .take_while(|c| c.is_alphanumeric() || *c == '_')
                    .collect();
                if let Some(theirs) = layer(&name) {
                    checked += 1;
                    if theirs > own {
                        back.push(format!(
                            "{}:{}: {room} (layer {own}) uses {name} (layer {theirs})",
                            rel.display(),
                            n + 1
                        ));
                    }
                }
            }
        }
    }
    assert!(
        checked > 500,
        "only {checked} uses read: the scan is broken"
    );
    assert!(
        back.is_empty(),
        "imports that run back up:\n{}",
        back.join("\n")
    );
}
