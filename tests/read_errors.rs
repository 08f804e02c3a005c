//! Errors say what happened. A read the operating system fails is an I/O error wherever it
//! happens (the commit slots, the metadata bundle, a table page, a payload, the validator),
//! never corruption and
//! never "not a container"; a read past the end of a file shorter than it claims is
//! corruption (I-3); and every error names its file. A source that fails a chosen read with
//! `EIO` stands in for a failing disk.

mod common;

use std::borrow::Cow;
use std::io;
use std::path::Path;
use std::sync::atomic::{AtomicU64, Ordering};
use std::sync::Mutex;

use common::txn::{build_bytes, build_bytes_paged};
use fmrh::model::Thresholds;
use fmrh::store::{verify, Source};
use fmrh::{store::Store, store::VerifyMode, types::Invariant, Error, Heightfield};

/// Bytes that fail (with `EIO`) every read touching `bad`, once `armed_after` reads have
/// passed. Its length is the bytes' length when made: cutting the bytes later is a file
/// truncated under a reader.
#[derive(Debug)]
struct FailingSource {
    bytes: Mutex<Vec<u8>>,
    len: u64,
    bad: std::ops::Range<u64>,
    armed_after: u64,
    reads: AtomicU64,
}

impl Source for FailingSource {
    fn len(&self) -> u64 {
        self.len
    }

    fn read_at(&self, offset: u64, len: usize) -> io::Result<Cow<'_, [u8]>> {
        let n = self.reads.fetch_add(1, Ordering::Relaxed);
        let end = offset + len as u64;
        if n >= self.armed_after && offset < self.bad.end && end > self.bad.start {
            return Err(io::Error::from_raw_os_error(5)); // EIO
        }
        self.bytes
            .lock()
            .unwrap()
            .get(offset as usize..end as usize)
            .map(|b| Cow::Owned(b.to_vec()))
            .ok_or_else(|| io::Error::new(io::ErrorKind::UnexpectedEof, "past the end"))
    }

    fn stable(&self) -> bool {
        false
    }

    fn name(&self) -> &Path {
        Path::new("/disk/failing.fmrh")
    }
}

fn terrain() -> Heightfield {
    Heightfield::from_fn(150, 120, |x, y| ((x * 7 + y * 3) % 41) as f32).unwrap()
}

/// A container whose tables lie in pages of their own, read as lookups reach them.
fn container() -> Vec<u8> {
    build_bytes_paged(&terrain(), 17, &Thresholds::Ladder)
}

/// The same container with its metadata in a bundle (format §6.7, 5.0: a frame per page).
fn bundled() -> Vec<u8> {
    build_bytes(&terrain(), 17, &Thresholds::Ladder)
}

/// Where the bundle's stored bytes lie (commit record bytes 176..188).
fn bundle_range(bytes: &[u8]) -> std::ops::Range<u64> {
    let offset = u64::from_le_bytes(bytes[176..184].try_into().unwrap());
    let len = u32::from_le_bytes(bytes[184..188].try_into().unwrap());
    assert!(len > 0, "the container has a bundle");
    offset..offset + u64::from(len)
}

fn failing(bytes: Vec<u8>, bad: std::ops::Range<u64>, armed_after: u64) -> FailingSource {
    FailingSource {
        len: bytes.len() as u64,
        bytes: Mutex::new(bytes),
        bad,
        armed_after,
        reads: AtomicU64::new(0),
    }
}

fn assert_io(e: Error, what: &str) {
    match e {
        Error::Io { path, source } => {
            assert_eq!(path, Path::new("/disk/failing.fmrh"), "{what}");
            assert_eq!(source.raw_os_error(), Some(5), "{what}");
        }
        other => panic!("{what}: {other} is not an I/O error"),
    }
}

#[test]
fn a_failed_read_of_a_commit_slot_is_an_io_error() {
    let bytes = container();
    for bad in [0..1, 4096..4097] {
        let e = Store::from_source(failing(bytes.clone(), bad.clone(), 0)).unwrap_err();
        assert_io(e, &format!("slot read at {bad:?}"));
        let e = verify(failing(bytes.clone(), bad.clone(), 0), VerifyMode::Fast).unwrap_err();
        assert_io(e, &format!("verify, slot read at {bad:?}"));
    }
}

#[test]
fn a_failed_read_of_a_table_page_or_payload_is_an_io_error() {
    let bytes = container();
    let store = Store::from_bytes(bytes.clone()).unwrap();
    let root = store.node(0).unwrap();
    let p = u64::from(store.page_size());
    let len = bytes.len() as u64;
    // Every page past the slots fails once opening is over: lookups, scans and payloads.
    let opened = {
        let s = failing(bytes.clone(), 2 * p..len, u64::MAX);
        let st = Store::from_source(s).unwrap();
        st.source().reads.load(Ordering::Relaxed)
    };
    let store = Store::from_source(failing(bytes.clone(), 2 * p..len, opened)).unwrap();
    assert_io(store.node(0).unwrap_err(), "node lookup");
    assert_io(store.payload(root.payload).unwrap_err(), "payload");
    let scan = store
        .scan_hilbert(0, 0..=u64::MAX)
        .map(|s| s.collect::<Result<Vec<_>, _>>());
    let e = match scan {
        Err(e) | Ok(Err(e)) => e,
        Ok(Ok(_)) => panic!("the scan read nothing"),
    };
    assert_io(e, "scan");
    // Opening itself, when a metadata page fails.
    let e = Store::from_source(failing(bytes.clone(), 2 * p..len, 0)).unwrap_err();
    assert_io(e, "open");
    // The validator stops with the I/O error rather than calling the file invalid.
    let e = verify(failing(bytes, 2 * p..len, 2), VerifyMode::Full).unwrap_err();
    assert_io(e, "verify");
}

/// The same container as format 4.0 wrote it: the bundle one frame, read whole at open.
fn bundled_4_0() -> Vec<u8> {
    common::vector("v4.0/hills-20x13-voids.fmrh")
}

/// Where the head of a 5.0 bundle ends (commit record bytes 196..200): the frame table and
/// the frames opening reads.
fn head_end(bytes: &[u8]) -> u64 {
    bundle_range(bytes).start + u64::from(u32::from_le_bytes(bytes[196..200].try_into().unwrap()))
}

/// With the metadata in a 4.0 bundle (one frame), a failed read of it fails opening with the
/// I/O error (not a corruption report), and once open, lookups and scans read nothing that
/// could fail.
#[test]
fn a_failed_read_of_a_whole_bundle_is_an_io_error_and_lookups_read_nothing() {
    let bytes = bundled_4_0();
    let range = bundle_range(&bytes);
    let e =
        Store::from_source(failing(bytes.clone(), range.start..range.start + 1, 0)).unwrap_err();
    assert_io(e, "open, bundle read");
    let e = verify(failing(bytes.clone(), range.clone(), 0), VerifyMode::Fast).unwrap_err();
    assert_io(e, "verify, bundle read");
    let opened = {
        let st = Store::from_source(failing(bytes.clone(), 0..0, u64::MAX)).unwrap();
        st.source().reads.load(Ordering::Relaxed)
    };
    // Everything but payloads fails after opening: tables come from memory.
    let store = Store::from_source(failing(bytes.clone(), 0..range.end, opened)).unwrap();
    store.node(0).unwrap();
    store
        .scan_hilbert(0, 0..=u64::MAX)
        .unwrap()
        .collect::<Result<Vec<_>, _>>()
        .unwrap();
    let (cols, rows) = store.domain().nodes_across(store.domain().finest_level());
    store.stored_block(cols - 1, rows - 1).unwrap();
}

/// With the metadata in a 5.0 bundle (a frame per page), a failed read of its head fails
/// opening with the I/O error; once open, a failed read of a frame a lookup reaches is the
/// lookup's I/O error, never corruption; and a page read once is not read again.
#[test]
fn a_failed_read_of_a_bundle_frame_is_an_io_error_where_it_is_read() {
    let bytes = bundled();
    let range = bundle_range(&bytes);
    let head = head_end(&bytes);
    assert!(head < range.end, "the bundle has frames past its head");
    let e = Store::from_source(failing(bytes.clone(), range.start..head, 0)).unwrap_err();
    assert_io(e, "open, head read");
    let e = verify(failing(bytes.clone(), head..range.end, 0), VerifyMode::Fast).unwrap_err();
    assert_io(e, "verify, frame read");
    // Opening reads nothing past the head.
    let store = Store::from_source(failing(bytes.clone(), head..range.end, 0)).unwrap();
    assert_io(store.node(0).unwrap_err(), "node lookup, frame read");
    let e = match store
        .scan_hilbert(0, 0..=u64::MAX)
        .map(|s| s.collect::<Result<Vec<_>, _>>())
    {
        Err(e) | Ok(Err(e)) => e,
        Ok(Ok(_)) => panic!("the scan read no frame"),
    };
    assert_io(e, "scan, frame read");
    // Frames read once are kept: after a whole pass, every table lookup reads nothing.
    let opened = {
        let st = Store::from_source(failing(bytes.clone(), 0..0, u64::MAX)).unwrap();
        st.nodes().unwrap();
        st.scan_hilbert(0, 0..=u64::MAX)
            .unwrap()
            .collect::<Result<Vec<_>, _>>()
            .unwrap();
        st.source().reads.load(Ordering::Relaxed)
    };
    let store = Store::from_source(failing(bytes.clone(), 0..range.end, opened)).unwrap();
    store.nodes().unwrap();
    store
        .scan_hilbert(0, 0..=u64::MAX)
        .unwrap()
        .collect::<Result<Vec<_>, _>>()
        .unwrap();
    let reads = store.source().reads.load(Ordering::Relaxed);
    store.nodes().unwrap();
    store.node(0).unwrap();
    assert_eq!(store.source().reads.load(Ordering::Relaxed), reads);
}

/// A damaged byte in a 4.0 bundle's stored bytes fails its CRC at open: corruption (I-9),
/// naming the file, and the validator reports it rather than failing. In a 5.0 bundle, a
/// damaged byte in the head fails opening the same way, and one in a later frame fails its
/// frame's CRC when a lookup reaches it (I-5), and the validator, which reads every frame.
#[test]
fn a_damaged_bundle_is_corrupt_where_it_is_read() {
    let corrupt_named = |e: Error, want: Invariant| match e {
        Error::Corrupt {
            path, invariant, ..
        } => {
            assert_eq!(invariant, want);
            assert_eq!(path, Path::new("/disk/failing.fmrh"));
        }
        other => panic!("{other}"),
    };
    let mut old = bundled_4_0();
    let range = bundle_range(&old);
    old[(range.start + range.end) as usize / 2] ^= 0x10;
    let e = Store::from_source(failing(old.clone(), 0..0, u64::MAX)).unwrap_err();
    corrupt_named(e, Invariant::Payload);
    assert!(
        !verify(failing(old, 0..0, u64::MAX), VerifyMode::Fast)
            .unwrap()
            .valid
    );

    let clean = bundled();
    let range = bundle_range(&clean);
    let head = head_end(&clean);
    let mut in_head = clean.clone();
    in_head[(range.start + head) as usize / 2] ^= 0x10;
    let e = Store::from_source(failing(in_head.clone(), 0..0, u64::MAX)).unwrap_err();
    assert!(matches!(e, Error::Corrupt { .. }), "{e}");
    assert!(
        !verify(failing(in_head, 0..0, u64::MAX), VerifyMode::Fast)
            .unwrap()
            .valid
    );
    let mut later = clean.clone();
    later[(head + range.end) as usize / 2] ^= 0x10;
    let store = Store::from_source(failing(later.clone(), 0..0, u64::MAX)).unwrap();
    let rect = store.domain().data_rect();
    let e = store
        .nodes()
        .and_then(|_| store.read_window(rect))
        .unwrap_err();
    corrupt_named(e, Invariant::Page);
    assert!(
        !verify(failing(later, 0..0, u64::MAX), VerifyMode::Fast)
            .unwrap()
            .valid
    );
}

#[test]
fn a_file_cut_under_a_reader_is_corrupt_and_named() {
    // Opened whole, then cut before the root's payload: the store's bounds say the payload
    // lies inside the file, the read finds the end first.
    let store = Store::from_source(failing(container(), 0..0, u64::MAX)).unwrap();
    let root = store.node(0).unwrap();
    store
        .source()
        .bytes
        .lock()
        .unwrap()
        .truncate(root.payload.offset as usize);
    match store.payload(root.payload) {
        Err(Error::Corrupt {
            path, invariant, ..
        }) => {
            assert_eq!(invariant, Invariant::FileLength);
            assert_eq!(path, Path::new("/disk/failing.fmrh"));
        }
        other => panic!("{:?}", other.map(|b| b.len())),
    }
}

#[test]
fn every_error_names_its_file() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("damaged.fmrh");
    let mut bytes = container();
    // Damage a byte of the node table's root page (commit record bytes 72..80).
    let root = u64::from_le_bytes(bytes[72..80].try_into().unwrap()) as usize;
    bytes[root * 4096 + 200] ^= 0xff;
    std::fs::write(&path, &bytes).unwrap();
    // Opening reads the slots, the header and the directory only; the damaged page is
    // checked, and refused, when a lookup first reaches it.
    let store = Store::open(&path).unwrap();
    let e = store.node(0).unwrap_err();
    assert!(e.to_string().contains(&*path.to_string_lossy()), "{e}");
    assert!(matches!(e, Error::Corrupt { .. }), "{e}");
    drop(store);
    let report = fmrh::store::verify(
        fmrh::store::FileSource::open(&path).unwrap(),
        fmrh::store::VerifyMode::Fast,
    )
    .unwrap();
    assert!(!report.valid);
    let missing = dir.path().join("missing.fmrh");
    let e = Store::open(&missing).unwrap_err();
    assert!(matches!(e, Error::Io { .. }), "{e}");
    assert!(e.to_string().contains("missing.fmrh"), "{e}");
    let text = dir.path().join("notes.txt");
    std::fs::write(&text, vec![b'x'; 10_000]).unwrap();
    let e = Store::open(&text).unwrap_err();
    assert!(matches!(e, Error::Input { .. }), "{e}");
    assert!(e.to_string().contains("notes.txt"), "{e}");
}
