//! Every DEM of `../shared/data` goes into a container and comes out unchanged: the build
//! writes a file that passes the full validator (every error recomputed from its blocks), and
//! reading the whole data window back gives the source `.f32` bit for bit, voids as NaN. The
//! file size is checked against the raw size (blocks + coarse grids + tables).

mod common;

use std::path::Path;

use fmrh::model::{BuildOptions, Model};
use fmrh::store::Store;
use fmrh::store::{verify, write_file, FileSource, WriteOptions};

fn datasets() -> Vec<std::path::PathBuf> {
    let mut out = Vec::new();
    for dir in std::fs::read_dir(common::data_dir()).expect("../shared/data exists") {
        let dir = dir.unwrap().path();
        if !dir.is_dir() {
            continue;
        }
        for f in std::fs::read_dir(&dir).unwrap() {
            let f = f.unwrap().path();
            if f.extension().is_some_and(|e| e == "f32") {
                out.push(f);
            }
        }
    }
    out.sort();
    assert!(
        out.len() >= 15,
        "expected the 15 shared DEMs, found {}",
        out.len()
    );
    out
}

fn roundtrip(source: &Path, dir: &Path) {
    let field = fmrh::ingest::load(source, &Default::default()).unwrap();
    let model = Model::build(field.clone(), &BuildOptions::default()).unwrap();
    let path = dir.join("out.fmrh");
    let summary = write_file(
        &model,
        &field.metadata,
        &path,
        &WriteOptions::default(),
        true,
    )
    .unwrap();
    let raw = 4 * u64::from(field.width()) * u64::from(field.height());
    let ratio = summary.file_length as f64 / raw as f64;
    // Blocks repeat their shared edges (a few %), coarse grids add at most a third, tables
    // and fixed pages the rest; the smallest DEMs pay most for the fixed pages.
    assert!(ratio < 1.6, "{}: {ratio:.3} x raw", source.display());
    let file = std::fs::File::open(&path).unwrap();
    let report = verify(
        FileSource::new(file, &path).unwrap(),
        fmrh::store::VerifyMode::Full,
    )
    .unwrap();
    assert!(report.valid, "{}: {:#?}", source.display(), report.checks);
    let store = Store::open(&path).unwrap();
    let back = store.read_window(store.domain().data_rect()).unwrap();
    let original = std::fs::read(source).unwrap();
    let mut bytes = Vec::with_capacity(original.len());
    for v in back.samples() {
        bytes.extend_from_slice(&v.to_le_bytes());
    }
    assert!(
        bytes == original,
        "{}: extraction differs from the source",
        source.display()
    );
}

#[test]
fn every_shared_dem_roundtrips_through_a_verified_container() {
    let dir = tempfile::tempdir().unwrap();
    for source in datasets() {
        roundtrip(&source, dir.path());
    }
}
