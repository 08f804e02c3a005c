//! Opening a container: read the two commit slots, choose the state (format §3), then check
//! every metadata page that state reaches before anything else is read.
//!
//! The bytes are decoded by [`crate::format`]; this file only decides what to read. The
//! dataset header and the cluster directory are decoded here, before a [`Store`] exists, so
//! a store always holds a checked header.

use super::btree::{self, PageSet, Pages};
use super::source::Source;
use super::Store;
use crate::error::{Error, Result};
use crate::format::blob::{blob_page_content, check_blob_ref};
use crate::format::commit::{self, NoState, Slot};
use crate::format::dataset::MAX_DATASET_HEADER_LEN;
use crate::format::directory::{self, MAX_DIRECTORY_LEN};
use crate::format::tables::state_trees;
use crate::format::{
    tag, BlobRef, DatasetHeader, Invariant, TreeRef, Violation, COMMIT_RECORD_LEN, FORMAT_MAJOR,
};

/// The record bytes of a slot at `offset`, or `None` when the file ends first. A failed read
/// that is not the end of the file is an I/O error.
fn slot_bytes<S: Source + ?Sized>(src: &S, offset: u64) -> Result<Option<Vec<u8>>> {
    if offset.saturating_add(COMMIT_RECORD_LEN as u64) > src.len() {
        return Ok(None);
    }
    match src.read_at(offset, COMMIT_RECORD_LEN) {
        Ok(bytes) => Ok(Some(bytes.into_owned())),
        Err(e) if e.kind() == std::io::ErrorKind::UnexpectedEof => Ok(None),
        Err(e) => Err(Error::io(src.name(), e)),
    }
}

/// Reads and classifies both commit slots. Slot 1 lies one page in, at the page size slot 0
/// names; when slot 0 names none, every allowed page size is tried, and the first sealed
/// record whose page size is its offset is slot 1.
pub(crate) fn read_slots<S: Source + ?Sized>(src: &S) -> Result<[Slot; 2]> {
    let first = slot_bytes(src, 0)?;
    let slot0 = match &first {
        None => Slot::missing(0),
        Some(b) => commit::classify(b, 0, 0),
    };
    let at = |p: u32| -> Result<Slot> {
        Ok(match slot_bytes(src, u64::from(p))? {
            None => Slot::missing(1),
            Some(b) => commit::classify(&b, 1, u64::from(p)),
        })
    };
    let named = slot0.page_size();
    let slot1 = match named {
        Some(p) => at(p)?,
        None => {
            let mut found = None;
            for p in commit::candidate_page_sizes() {
                let s = at(p)?;
                if matches!(s, Slot::Valid(_) | Slot::Foreign { .. }) {
                    found = Some(s);
                    break;
                }
            }
            found.unwrap_or(Slot::Invalid {
                why: Violation::new(
                    Invariant::CommitRecord,
                    "commit slot 1",
                    "no valid record at any page size",
                ),
                has_magic: false,
            })
        }
    };
    Ok([slot0, slot1])
}

/// The error for a file whose slots give no state, about the file `src` names.
pub(crate) fn no_state<S: Source + ?Sized>(src: &S, why: NoState) -> Error {
    match why {
        NoState::NotAContainer => Error::input(
            src.name(),
            "not an fmrh container (no commit record with the FMRH magic)",
        ),
        NoState::Unsupported { major, minor } => Error::unsupported(
            src.name(),
            format!(
                "format version {major}.{minor} (a newer writer's state); this reader reads \
                 {FORMAT_MAJOR}.x"
            ),
        ),
        NoState::Corrupt(v) => v.in_file(src.name()),
    }
}

/// Reads and checks a blob of at most `max_len` bytes, adding its pages to `seen`.
fn read_blob<S: Source + ?Sized>(
    pages: &Pages<'_, S>,
    blob: &BlobRef,
    tag: [u8; 4],
    max_len: u64,
    name: &str,
    seen: &mut PageSet,
) -> Result<Vec<u8>> {
    let count = check_blob_ref(blob, max_len, pages.page_size, pages.page_count, name)
        .map_err(|v| pages.corrupt(v))?;
    // `max_len` bounds the allocation, whatever the record says.
    let mut out = Vec::with_capacity(usize::try_from(blob.length.get()).unwrap_or(0));
    for i in 0..count {
        let page_no = blob.first_page.get() + i;
        if !seen.insert(page_no) {
            return Err(pages.corrupt(Violation::new(
                Invariant::PageOwnership,
                format!("{name} page {page_no}"),
                "page reached twice",
            )));
        }
        let page = pages.get(page_no, tag)?;
        let content = blob_page_content(&page, blob, i, tag, pages.page_size, name)
            .map_err(|v| pages.corrupt(v))?;
        out.extend_from_slice(content);
    }
    Ok(out)
}

/// Opens the state `src` holds, checking every metadata page it reaches (see the docs of
/// [`crate::store`] for what that costs).
pub(crate) fn open<S: Source>(src: S) -> Result<Store<S>> {
    let slots = read_slots(&src)?;
    let (slot, commit) = commit::choose(&slots).map_err(|why| no_state(&src, why))?;
    commit::check_length(&commit, src.len()).map_err(|v| v.in_file(src.name()))?;
    let page_size = commit.page_size.get();
    let page_count = commit.file_length.get() / u64::from(page_size);
    let pages = Pages {
        src: &src,
        page_size,
        page_count,
        check: true,
    };
    let mut seen = PageSet::new(page_count);
    let header_bytes = read_blob(
        &pages,
        &commit.roots.dataset_header,
        tag::DATASET_HEADER,
        MAX_DATASET_HEADER_LEN,
        "dataset header",
        &mut seen,
    )?;
    let header = DatasetHeader::decode(&header_bytes).map_err(|v| pages.corrupt(v))?;
    let dir = read_blob(
        &pages,
        &commit.roots.cluster_directory,
        tag::CLUSTER_DIRECTORY,
        MAX_DIRECTORY_LEN,
        "cluster directory",
        &mut seen,
    )?;
    let clusters = directory::decode(&dir, &header, commit.roots.adjacency.records.get())
        .map_err(|v| pages.corrupt(v))?;
    let expect = |tree: &TreeRef, n: u64, what: &str| -> Result<()> {
        if tree.records.get() != n {
            return Err(pages.corrupt(Violation::new(
                Invariant::TreeShape,
                what,
                format!("{} records, expected {n}", tree.records.get()),
            )));
        }
        Ok(())
    };
    expect(&commit.roots.node_table, header.node_count, "node table")?;
    expect(&commit.roots.block_table, header.block_count, "block table")?;
    for (spec, tree) in state_trees(&commit.roots, &clusters) {
        btree::walk(&pages, &tree, spec, &mut seen, &mut |_, _| Ok(()))?;
    }
    Ok(Store {
        src,
        page_size,
        page_count,
        slot,
        commit,
        header,
        clusters,
        metadata_pages: seen,
    })
}
