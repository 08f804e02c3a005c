//! What the tile pyramid tests share: the bundled SRTM tile N43E006 built as a container,
//! `fmrh export` run into a directory or an archive, and a directory of `z/x/y.ext` tiles
//! read back.

#![allow(dead_code)]

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

/// Tiles by `(z, x, y)`: their bytes.
pub type Tiles = BTreeMap<(u8, u32, u32), Vec<u8>>;

/// The bundled SRTM tile N43E006 (3", 1201²), as a container `dir/n6.fmrh`.
pub fn n43e006(dir: &Path) -> PathBuf {
    let dem = super::bundled_dir().join("srtm3-pyhgtmap/N43E006.hgt.gz");
    let file = dir.join("n6.fmrh");
    super::fmrh_ok(&[
        "build",
        "-q",
        dem.to_str().unwrap(),
        "-o",
        file.to_str().unwrap(),
    ]);
    file
}

/// `fmrh export -q FILE ARGS… -o OUT` for each of `outs`.
pub fn export(file: &Path, args: &[&str], outs: &[&Path]) {
    for out in outs {
        let mut all = vec!["export", "-q", file.to_str().unwrap()];
        all.extend_from_slice(args);
        all.extend(["-o", out.to_str().unwrap()]);
        super::fmrh_ok(&all);
    }
}

/// Every `z/x/y.ext` file under `dir`: `(z, x, y)` and its bytes.
pub fn tiles_in(dir: &Path, ext: &str) -> Tiles {
    let mut out = BTreeMap::new();
    for z in std::fs::read_dir(dir).unwrap().flatten() {
        let Ok(zn) = z.file_name().to_string_lossy().parse::<u8>() else {
            continue;
        };
        for x in std::fs::read_dir(z.path()).unwrap().flatten() {
            let xn: u32 = x.file_name().to_string_lossy().parse().unwrap();
            for y in std::fs::read_dir(x.path()).unwrap().flatten() {
                let name = y.file_name().to_string_lossy().into_owned();
                let yn: u32 = name
                    .strip_suffix(&format!(".{ext}"))
                    .unwrap_or_else(|| panic!("{name} is not a .{ext} tile"))
                    .parse()
                    .unwrap();
                out.insert((zn, xn, yn), std::fs::read(y.path()).unwrap());
            }
        }
    }
    out
}
