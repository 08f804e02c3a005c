//! The records' own consistency (fast mode): the free list (I-16), the node table (I-10), the
//! block table (I-11), page ownership (I-8), and index entries naming their nodes (I-13).

use zerocopy::IntoBytes;

use super::{Checks, Loaded};

use crate::curve::HilbertKey;
use crate::format::payload;
use crate::format::{
    FreePage, Invariant, NODE_GRID_AGAINST_PARENT, NODE_GRID_BITMAP_FLAGGED, NODE_GRID_HAS_VOIDS,
    NODE_GRID_THIN_MASK, NODE_GRID_THIN_SHIFT,
};
use crate::model::{cluster, NO_PARENT};
use crate::store::pages::PageSet;
use crate::store::{Source, Store};

pub(super) fn check_free_list<S: Source>(store: &Store<S>, l: &Loaded, checks: &mut Checks) {
    let mut prev = None;
    for &FreePage {
        page,
        freed_txn: txn,
    } in &l.free
    {
        if page < 2 || page >= store.page_count() || prev.is_some_and(|p| page <= p) {
            checks.fail(
                Invariant::FreeList,
                format!("free page {page}: out of order or outside the file"),
            );
        }
        if txn > store.txn_id() {
            checks.fail(
                Invariant::FreeList,
                format!("free page {page}: freed by future transaction {txn}"),
            );
        }
        prev = Some(page);
    }
    checks.pass(Invariant::FreeList);
}

/// I-10's part about the top of the tree (format 6.2): it holds exactly the table's nodes
/// of level below its `levels`, each record equal to the table's at its ordinal. (Its shape
/// was checked when the store opened.)
pub(super) fn check_top<S: Source>(store: &Store<S>, l: &Loaded, checks: &mut Checks) {
    let Some(top) = store.top() else {
        return;
    };
    let id = Invariant::NodeTable;
    let expected: Vec<u32> = (0u32..)
        .zip(&l.nodes)
        .filter(|(_, n)| n.level < top.levels)
        .map(|(i, _)| i)
        .collect();
    let held: Vec<u32> = top.nodes.iter().map(|&(o, _)| o).collect();
    if held != expected {
        checks.fail(
            id,
            format!(
                "the top holds {} nodes; the table has {} of level below {}",
                held.len(),
                expected.len(),
                top.levels
            ),
        );
        return;
    }
    for (&(o, _), record) in top.nodes.iter().zip(&top.records) {
        if l.nodes.get(o as usize).map(|r| r.as_bytes()) != Some(record.as_bytes()) {
            checks.fail(id, format!("top: node {o} differs from the table's record"));
            return;
        }
    }
}

pub(super) fn check_nodes<S: Source>(store: &Store<S>, l: &Loaded, checks: &mut Checks) {
    let id = Invariant::NodeTable;
    let d = store.domain();
    let finest = d.finest_level();
    let delta_min = store.header().delta_min;
    // A physical block's grid is the stored data: its error is the storage error, 9Q/16 of a
    // precision (format 2.1), where it has real heights, and 0 otherwise.
    let storage_error = store.header().storage_error();
    let nodes = &l.nodes;
    let count = nodes.len() as u64;
    let (cols, _) = d.nodes_across(finest);
    for (i, n) in nodes.iter().enumerate() {
        let at = format!("node {i}");
        let (level, x, y) = (n.level, n.x.get(), n.y.get());
        if level > finest || !d.exists(level, x, y) {
            checks.fail(
                id,
                format!("{at}: ({level}, {x}, {y}) is not a node of the domain"),
            );
            continue;
        }
        let key = HilbertKey::of_node(finest, level, x, y).0;
        if n.key.get() != key {
            checks.fail(
                id,
                format!("{at}: key {} but (level, x, y) gives {key}", n.key.get()),
            );
        }
        if i > 0 {
            let p = &nodes[i - 1];
            if (p.key.get(), p.level) >= (n.key.get(), level) {
                checks.fail(id, format!("{at}: (key, level) does not increase"));
            }
        }
        let sub = u64::from(n.subtree_len.get());
        if sub == 0 || i as u64 + sub > count {
            checks.fail(
                id,
                format!("{at}: subtree of {sub} nodes overruns the table"),
            );
            continue;
        }
        let parent = n.parent.get();
        if i == 0 {
            if level != 0 || parent != NO_PARENT || sub != count {
                checks.fail(id, "node 0 is not the root of the whole table".into());
            }
        } else if parent == NO_PARENT || parent as usize >= i {
            checks.fail(id, format!("{at}: parent {parent} does not precede it"));
        } else {
            let p = &nodes[parent as usize];
            let end = parent as u64 + u64::from(p.subtree_len.get());
            // The parent's level comes from the file too: 255 has no child level.
            if p.level.checked_add(1) != Some(level)
                || p.x.get() != x / 2
                || p.y.get() != y / 2
                || i as u64 + sub > end
            {
                checks.fail(id, format!("{at}: not a child of its parent {parent}"));
            }
        }
        let (e, m) = (n.static_error.get(), n.monotone_error.get());
        if !(e.is_finite() && e >= 0.0 && m.is_finite() && m >= e) {
            checks.fail(id, format!("{at}: error {e}, e* {m}"));
        }
        let (lo, hi) = (n.min_height.get(), n.max_height.get());
        if !(lo.is_finite() && hi.is_finite() && lo <= hi) {
            checks.fail(id, format!("{at}: height range {lo}..{hi}"));
        }
        if n.valid_samples.get() > d.footprint(level, x, y).samples() {
            checks.fail(
                id,
                format!("{at}: more valid samples than its footprint holds"),
            );
        }
        let flags = n.flags.get();
        let record = store.commit_record();
        // Thinning bits only in a 6.x file whose header says its nodes are thinned by area
        // (§6.1): elsewhere they are reserved.
        let known = if record.grids_thinned() && store.header().thinned_by_area {
            NODE_GRID_HAS_VOIDS
                | NODE_GRID_AGAINST_PARENT
                | NODE_GRID_BITMAP_FLAGGED
                | NODE_GRID_THIN_MASK
        } else if record.grids_against_parents() {
            NODE_GRID_HAS_VOIDS | NODE_GRID_AGAINST_PARENT | NODE_GRID_BITMAP_FLAGGED
        } else {
            NODE_GRID_HAS_VOIDS
        };
        // A thinned grid keeps at least two columns: k <= b - 1.
        let thin = (flags & NODE_GRID_THIN_MASK) >> NODE_GRID_THIN_SHIFT;
        let thin_ok = thin == 0 || (1u32 << thin) < d.block_size();
        if flags & !known != 0
            || (level == finest && flags != 0)
            || (flags & NODE_GRID_BITMAP_FLAGGED != 0 && flags & NODE_GRID_HAS_VOIDS == 0)
            || n.reserved.get() != 0
        {
            checks.fail(
                id,
                format!("{at}: unknown flags {flags:#x} or reserved bits set"),
            );
        } else if !thin_ok {
            checks.fail(
                id,
                format!(
                    "{at}: its grid is thinned by 2^{thin}, more than a grid of {} columns allows",
                    d.block_size()
                ),
            );
        } else if flags & NODE_GRID_AGAINST_PARENT != 0 && i == 0 {
            checks.fail(
                id,
                format!("{at}: the root's grid is coded against a parent"),
            );
        }
        // Children: those kept are exactly the mask's, each right after its elder sibling's
        // subtree.
        let mut mask = 0u8;
        let mut c = i as u64 + 1;
        let end = i as u64 + sub;
        while c < end {
            let Some(ch) = usize::try_from(c).ok().and_then(|c| nodes.get(c)) else {
                break;
            };
            if ch.parent.get() as usize != i {
                checks.fail(
                    id,
                    format!("{at}: node {c} lies in its subtree but is not its child"),
                );
                break;
            }
            mask |= 1 << ((ch.y.get() & 1) * 2 + (ch.x.get() & 1));
            if ch.monotone_error.get() > m {
                checks.fail(id, format!("{at}: child {c} has a larger e*"));
            }
            c += u64::from(ch.subtree_len.get().max(1));
        }
        if mask != n.child_mask {
            checks.fail(
                id,
                format!(
                    "{at}: child mask {:#06b}, children found {mask:#06b}",
                    n.child_mask
                ),
            );
        }
        if sub > 1 && level == finest {
            checks.fail(
                id,
                format!("{at}: a physical block with a subtree of {sub} nodes"),
            );
        } else if sub > 1 {
            let existing = (0..4u32)
                .filter(|q| d.exists(level + 1, 2 * x + (q & 1), 2 * y + (q >> 1)))
                .fold(0u8, |acc, q| acc | 1 << q);
            if m <= delta_min || mask != existing {
                checks.fail(
                    id,
                    format!("{at}: subdivided though e* {m} <= delta_min, or a child is missing"),
                );
            }
        } else if level < finest && m > delta_min {
            checks.fail(
                id,
                format!("{at}: a leaf above the finest level with e* {m} > delta_min {delta_min}"),
            );
        }
        if level == finest {
            let want = if n.valid_samples.get() > 0 {
                storage_error
            } else {
                0.0
            };
            if m != want || e != want {
                checks.fail(
                    id,
                    format!("{at}: a physical block with error {e}, e* {m}; its storage error is {want}"),
                );
            }
            if let Some(b) = l.blocks.get((y * cols + x) as usize) {
                if (n.payload_offset, n.payload_len, n.payload_crc)
                    != (b.payload_offset, b.payload_len, b.payload_crc)
                {
                    checks.fail(id, format!("{at}: payload is not its block's"));
                }
            }
        } else {
            let (gw, gh) = d.grid_dims(level, x, y);
            let raw = payload::grid_len(gw, gh, flags & NODE_GRID_HAS_VOIDS != 0);
            let len = u64::from(n.payload_len.get());
            // 1.x stores the layout as it is; 2.x codes it, within the stored form's bound.
            if !payload_len_fits(store, n.payload_len.get(), raw) {
                checks.fail(
                    id,
                    format!("{at}: grid payload of {len} bytes for a layout of {raw}"),
                );
            }
        }
    }
    checks.pass(id);
}

/// Whether a payload of `len` bytes can hold a layout of `raw` bytes: exactly in 1.x, within
/// the stored form's bound in 2.x.
fn payload_len_fits<S: Source>(store: &Store<S>, len: u32, raw: u64) -> bool {
    if store.commit_record().payloads_coded() {
        u64::from(len) <= payload::max_stored_len(raw)
    } else {
        u64::from(len) == raw
    }
}

pub(super) fn check_blocks<S: Source>(store: &Store<S>, l: &Loaded, checks: &mut Checks) {
    let id = Invariant::BlockTable;
    let d = store.domain();
    let (cols, _) = d.nodes_across(d.finest_level());
    for (i, b) in l.blocks.iter().enumerate() {
        let (x, y) = super::block_xy(i, cols);
        let rect = d
            .footprint(d.finest_level(), x, y)
            .intersect(&d.data_rect())
            .unwrap_or_default();
        let (w, h, v) = (b.width.get(), b.height.get(), b.void_count.get());
        if u64::from(w) != rect.col1 - rect.col0 + 1 || u64::from(h) != rect.row1 - rect.row0 + 1 {
            checks.fail(
                id,
                format!("block ({x}, {y}): {w} x {h}, its data footprint is {rect:?}"),
            );
        } else if u64::from(v) > rect.samples()
            || !payload_len_fits(store, b.payload_len.get(), payload::block_len(w, h, v))
        {
            checks.fail(
                id,
                format!(
                    "block ({x}, {y}): {v} voids, {} payload bytes",
                    b.payload_len.get()
                ),
            );
        }
        // Format 4: a block coded against a grid names its parent, the node at the level
        // above that covers it; before, the field was reserved.
        let against = b.against.get();
        let finest = d.finest_level();
        let parent_ok = against == 0
            || (store.commit_record().blocks_against_parents()
                && finest > 0
                && l.nodes.get((against - 1) as usize).is_some_and(|n| {
                    (n.level, n.x.get(), n.y.get()) == (finest - 1, x / 2, y / 2)
                }));
        if !parent_ok {
            checks.fail(
                id,
                format!(
                    "block ({x}, {y}): coded against node {}, which is not its parent",
                    against - 1
                ),
            );
        }
    }
    checks.pass(id);
}

pub(super) fn check_ownership<S: Source>(
    store: &Store<S>,
    l: &Loaded,
    payload: &PageSet,
    checks: &mut Checks,
) {
    let id = Invariant::PageOwnership;
    let meta = match store.metadata_pages() {
        Ok(m) => m,
        Err(e) => {
            checks.fail(id, format!("walking the tables: {e}"));
            return;
        }
    };
    let mut free = PageSet::new(store.page_count());
    for &FreePage { page, .. } in &l.free {
        if !free.insert(page) {
            checks.fail(
                id,
                format!("page {page} is listed free twice or lies outside the file"),
            );
        }
    }
    let mut orphans = 0u64;
    let mut first_orphan = None;
    for page in 2..store.page_count() {
        let owners = [
            meta.contains(page),
            payload.contains(page),
            free.contains(page),
        ];
        let n = owners.iter().filter(|&&o| o).count();
        if n > 1 {
            checks.fail(id, format!("page {page} is claimed by {n} structures (metadata, payload, free: {owners:?})"));
        } else if n == 0 {
            orphans += 1;
            first_orphan.get_or_insert(page);
        }
    }
    // A newer minor of this major may own pages through a structure this validator does
    // not know, reached through bytes it reads as reserved (format §8): pages that belong
    // to nothing it knows are then not damage it can tell.
    let (major, minor) = store.state().format_version;
    if let Some(first) = first_orphan.filter(|_| !crate::format::commit::is_newer_minor(major, minor)) {
        checks.fail(
            id,
            format!("{orphans} pages belong to no structure (first: page {first})"),
        );
    }
    checks.pass(id);
}

pub(super) fn check_index_entries<S: Source>(store: &Store<S>, l: &Loaded, checks: &mut Checks) {
    for (c, (info, entries)) in store.clusters().iter().zip(&l.indexes).enumerate() {
        let mut max = 0f64;
        for (k, e) in entries.iter().enumerate() {
            let at = format!("cluster {c} entry {k}");
            match l.nodes.get(e.node.get() as usize) {
                Some(n) if n.key == e.key && n.level == e.level && e.reserved == [0; 3] => {
                    max = max.max(n.monotone_error.get());
                }
                _ => checks.fail(
                    Invariant::ClusterIndex,
                    format!(
                        "{at}: names node {} with another key or level",
                        e.node.get()
                    ),
                ),
            }
        }
        if max != info.max_error {
            checks.fail(
                Invariant::ClusterDirectory,
                format!(
                    "cluster {c}: max error {} recorded, {max} found",
                    info.max_error
                ),
            );
        }
        for (edge, list) in l.adjacency[c].iter().enumerate() {
            if let Some(&bad) = list.iter().find(|&&n| n as usize >= l.nodes.len()) {
                checks.fail(
                    Invariant::Adjacency,
                    format!(
                        "cluster {c} {} edge: node {bad} does not exist",
                        cluster::EDGES[edge]
                    ),
                );
            }
        }
    }
    checks.pass(Invariant::ClusterIndex);
}
