//! Every structured page is bound to the state that wrote it (format 1.2, container.md §4,
//! §11.6): a reader of an old state that follows a reference into a page a later commit reused
//! gets `Error::Superseded`, never that page's bytes as its own; the same mismatch in the
//! latest state is corruption (I-5), reported as such; and a registered reader never meets
//! reuse at all, because the writer keeps its pages. A state with a metadata bundle (format
//! 3.0) holds its tables in memory from its opening, so an old reader keeps reading its own
//! tables, and its payloads are still bound by their CRCs.

mod common;

use std::borrow::Cow;
use std::io;
use std::path::Path;

use fmrh::model::SampleRect;
use fmrh::store::{Container, Store};
use fmrh::store::{FileSource, Source};
use fmrh::{Error, Heightfield};

/// A file source that does not register its state: what a reader on a system without
/// open-file-description locks, or a tool that bypasses them, is.
struct Unregistered(FileSource);

impl Source for Unregistered {
    fn len(&self) -> u64 {
        self.0.len()
    }
    fn read_at(&self, offset: u64, len: usize) -> io::Result<Cow<'_, [u8]>> {
        self.0.read_at(offset, len)
    }
    fn stable(&self) -> bool {
        false
    }
    fn name(&self) -> &Path {
        self.0.name()
    }
    fn refresh_len(&self) -> io::Result<u64> {
        self.0.refresh_len()
    }
}

fn field() -> Heightfield {
    Heightfield::from_fn(300, 260, |x, y| ((x * 13 + y * 7) % 101) as f32 * 0.5).unwrap()
}

/// Creates the test file, its metadata bundled or in pages of its own.
fn create(path: &Path, paged: bool) {
    let field = field();
    let model = fmrh::model::Model::build(field.clone(), &Default::default()).unwrap();
    let mut options = fmrh::store::WriteOptions::default();
    if paged {
        options.bundle_limit = 0;
    }
    fmrh::store::write_file(&model, &field.metadata, path, &options, false).unwrap();
}

/// Commits four replacements and returns each commit's (reuse limit, pages reused).
fn commit_four(path: &Path, paged: bool) -> Vec<(u64, u64)> {
    let container = Container::open(path).unwrap();
    if paged {
        container.set_bundle_limit(0);
    }
    let out = (0..4)
        .map(|i| {
            let mut txn = container.begin_write().unwrap();
            let patch = Heightfield::from_fn(40, 30, |x, _| 500.0 + i as f32 + x as f32).unwrap();
            txn.replace_region(20 + 50 * i, 100, &patch).unwrap();
            let s = txn.commit().unwrap();
            (s.reuse_limit, s.pages_reused)
        })
        .collect();
    container.close().unwrap();
    out
}

#[test]
fn an_old_state_reading_a_reused_page_gets_superseded_never_data() {
    old_state_reads(true);
}

#[test]
fn an_old_bundled_state_reads_its_own_tables_and_never_reused_payloads() {
    old_state_reads(false);
}

/// Every block record of `store`, row-major.
fn blocks_of<S: Source>(store: &Store<S>) -> Result<Vec<fmrh::format::StoredBlock>, Error> {
    let d = *store.domain();
    let (cols, rows) = d.nodes_across(d.finest_level());
    (0..rows)
        .flat_map(|y| (0..cols).map(move |x| (x, y)))
        .map(|(x, y)| store.stored_block(x, y))
        .collect()
}

fn old_state_reads(paged: bool) {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("t.fmrh");
    create(&path, paged);
    let old = Store::from_source(Unregistered(FileSource::open(&path).unwrap())).unwrap();
    assert!(!old.is_registered());
    let txn = old.txn_id();
    // The bundled store holds its tables from the start; the paged one reads its table pages
    // only below, after the commits reused them (reading a window reads node records too:
    // the parents of blocks coded against their grids). What the state held is read now by
    // another reader, closed before the commits (so it holds no state back).
    let nodes_before = (!paged).then(|| old.nodes().unwrap());
    let (before, reference) = {
        let r = Store::open(&path).unwrap();
        let before = r.read_window(r.domain().data_rect()).unwrap();
        (
            before,
            paged.then(|| (r.nodes().unwrap(), blocks_of(&r).unwrap())),
        )
    };

    let commits = commit_four(&path, paged);
    assert!(
        commits.iter().any(|&(_, reused)| reused > 0),
        "no commit reused a page: {commits:?}"
    );
    // Nobody registered state 1, so the writer was free to reuse its pages.
    assert!(commits.iter().skip(1).all(|&(limit, _)| limit > txn));

    match nodes_before {
        // The paged store reads its tables now. Which of the old state's table pages the
        // commits reused depends on the allocator and the payloads' sizes, so every table is
        // read: each read gives the old state's records exactly (as a reader that read them
        // before the commits saw them) or Superseded, and at least one meets a reused page.
        None => {
            let (nodes_then, blocks_then) = reference.expect("read before the commits");
            let mut superseded = 0;
            let mut check = |what: &str, r: Result<bool, Error>| match r {
                Ok(same) => assert!(same, "the old {what} read as another state's"),
                Err(Error::Superseded {
                    txn: held, latest, ..
                }) => {
                    assert!(held == txn && latest > txn, "{held} {latest}");
                    superseded += 1;
                }
                Err(e) => panic!("the old {what}: expected Superseded, got {e}"),
            };
            check("node table", old.nodes().map(|n| n == nodes_then));
            check("block table", blocks_of(&old).map(|b| b == blocks_then));
            assert!(superseded > 0, "no read of the old state met a reused page");
        }
        // The bundle was read whole at opening: the old tables, exactly.
        Some(before) => assert_eq!(old.nodes().unwrap(), before),
    }
    // Whatever else the old store reads is its own state's, or the same error.
    match old.read_window(old.domain().data_rect()) {
        Ok(w) => assert_eq!(w.samples(), before.samples()),
        Err(Error::Superseded { .. }) => {}
        Err(e) => panic!("expected Superseded, got {e}"),
    }
    // Opening again reads the latest state, whole.
    let new = Store::open(&path).unwrap();
    assert!(new.txn_id() > txn);
    let w = new
        .read_window(SampleRect {
            col0: 20,
            row0: 100,
            col1: 20,
            row1: 100,
        })
        .unwrap();
    assert_eq!(w.samples(), &[500.0]);
}

#[test]
fn a_registered_reader_keeps_its_state_while_commits_go_on() {
    for paged in [true, false] {
        registered_reader(paged);
    }
}

fn registered_reader(paged: bool) {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("t.fmrh");
    create(&path, paged);
    let reader = Store::open(&path).unwrap();
    if !fmrh::store::lock::SUPPORTED {
        assert!(!reader.is_registered());
        return;
    }
    assert!(reader.is_registered());
    let before = reader.read_window(reader.domain().data_rect()).unwrap();
    for (limit, _) in commit_four(&path, paged) {
        assert_eq!(
            limit,
            reader.txn_id(),
            "a commit ignored the registered reader"
        );
    }
    let after = reader.read_window(reader.domain().data_rect()).unwrap();
    assert_eq!(after.samples(), before.samples());
    assert_eq!(
        reader.nodes().unwrap().len() as u64,
        reader.header().node_count
    );
}

#[test]
fn a_wrong_txn_tag_in_the_latest_state_is_corruption() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("t.fmrh");
    create(&path, true);
    let mut bytes = std::fs::read(&path).unwrap();
    let p = u32::from_le_bytes(bytes[12..16].try_into().unwrap()) as usize;
    // The node table's root (commit record bytes 72..80): give it another transaction's tag
    // and a CRC that matches, as a stale page from an older state would have.
    let root = u64::from_le_bytes(bytes[72..80].try_into().unwrap()) as usize;
    let page = &mut bytes[root * p..(root + 1) * p];
    assert_eq!(&page[..4], b"FMNT");
    page[18..20].copy_from_slice(&7u16.to_le_bytes());
    let crc = crc32fast::hash(&page[8..]);
    page[4..8].copy_from_slice(&crc.to_le_bytes());
    // Opening does not reach the page; the first lookup that does refuses it.
    let store = Store::from_bytes(&bytes[..]).unwrap();
    assert_wrong_tag(store.node(0).map(|_| ()), &bytes);
}

/// `result` is the I-5 error of a page with another transaction's txn tag, and the
/// validator calls `bytes` invalid (not busy).
fn assert_wrong_tag(result: Result<(), Error>, bytes: &[u8]) {
    match result {
        Err(Error::Corrupt {
            invariant, detail, ..
        }) => {
            assert_eq!(invariant, fmrh::types::Invariant::Page);
            assert!(detail.contains("txn tag"), "{detail}");
        }
        Err(e) => panic!("expected I-5, got {e}"),
        Ok(()) => panic!("a page of another transaction was accepted"),
    }
    let report =
        fmrh::store::verify(fmrh::store::Bytes(bytes), fmrh::store::VerifyMode::Fast).unwrap();
    assert!(!report.valid && !report.busy);
}

/// In a bundle, a page with another transaction's tag (CRC made right, bundle recompressed
/// and its CRC in the record made right) is refused when the state is opened: I-5, never a
/// table read as this state's.
#[test]
fn a_wrong_txn_tag_in_a_bundle_is_corruption_at_open() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("t.fmrh");
    create(&path, false);
    let mut bytes = std::fs::read(&path).unwrap();
    let p = common::bundle::page_size(&bytes);
    common::bundle::rewrite(&mut bytes, |raw| {
        let last = raw.len() / p - 1;
        let page = &mut raw[last * p..(last + 1) * p];
        page[18..20].copy_from_slice(&7u16.to_le_bytes());
        common::bundle::reseal_page(page);
    });
    assert_wrong_tag(Store::from_bytes(&bytes[..]).map(|_| ()), &bytes);
}
