//! The validator: every numbered invariant of `format-spec/container.md`, checked by name.
//!
//! Verification is an explicit, typed operation. [`verify`] returns a [`VerifyReport`] with
//! one [`CheckReport`] per invariant: passed, failed (with located messages), or skipped
//! because a check it depends on failed. *Fast* mode checks the commit slots, every page, the
//! shape of every table, page ownership, every payload's CRC and zero gaps, and the records'
//! own consistency. *Full* mode adds the semantics: every cluster is the cut it claims to be
//! (cover, bound, minimality), the adjacency lists are right, and the whole model (errors,
//! ranges, grids, void stand-ins) equals a fresh build from the physical blocks.
//!
//! Only a file that cannot be recognised at all (no commit record with the magic, an unknown
//! major version) is an `Err`: the CLI's exit code 2. Anything else is a report. The validator
//! never panics and never hangs (every page is visited at most once). It never allocates from
//! a stored size it has not first checked against the file's real length.

use serde::Serialize;

use super::btree::PageSet;
use super::{choose_slot, read_slots, specs, Slot, Source, Store};
use crate::curve::HilbertKey;
use crate::error::{Error, Result};
use crate::format::payload::{self, BlockView, GridView};
use crate::format::{
    invariant as inv, is_zero, BlockRecord, IndexEntry, NodeRecord, COMMIT_RECORD_LEN,
    NODE_GRID_HAS_VOIDS, PAYLOAD_ALIGN, VOID_BITS,
};
use crate::heightfield::Heightfield;
use crate::model::{cluster, BuildOptions, Model, SampleRect, Thresholds, NO_PARENT};

/// At most this many messages are kept per check (all are counted).
const MAX_MESSAGES: usize = 20;

/// The outcome of one check.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize)]
#[serde(rename_all = "lowercase")]
pub enum CheckStatus {
    /// The invariant holds.
    Passed,
    /// The invariant is broken; see the messages.
    Failed,
    /// Not checked: a check it depends on failed, or the mode does not include it.
    Skipped,
}

/// One invariant's result.
#[derive(Clone, Debug, Serialize)]
pub struct CheckReport {
    /// `I-1`, `I-2`, ...
    pub id: &'static str,
    /// What the invariant is about.
    pub name: &'static str,
    /// Passed, failed or skipped.
    pub status: CheckStatus,
    /// How many failures were found.
    pub failure_count: u64,
    /// The first failures, each located.
    pub failures: Vec<String>,
}

/// The result of [`verify`].
#[derive(Clone, Debug, Serialize)]
pub struct VerifyReport {
    /// `fast` or `full`.
    pub mode: &'static str,
    /// Whether every check that ran passed and none was skipped for a failure.
    pub valid: bool,
    /// The transaction id of the commit record in use, if one was valid.
    pub txn_id: Option<u64>,
    /// Bytes in the file.
    pub file_length: u64,
    /// One entry per invariant, in id order.
    pub checks: Vec<CheckReport>,
}

const CHECKS: [(&str, &str); 16] = [
    (inv::COMMIT_RECORD, "commit record"),
    (inv::VERSION, "format version"),
    (inv::FILE_LENGTH, "file length"),
    (inv::INACTIVE_SLOT, "inactive commit slot"),
    (inv::PAGE, "page headers and checksums"),
    (inv::DATASET_HEADER, "dataset header"),
    (inv::TREE_SHAPE, "table shape"),
    (inv::PAGE_OWNERSHIP, "page ownership"),
    (inv::PAYLOAD, "payloads"),
    (inv::NODE_TABLE, "node table"),
    (inv::BLOCK_TABLE, "block table"),
    (inv::CLUSTER_DIRECTORY, "cluster directory"),
    (inv::CLUSTER_INDEX, "cluster indexes and cuts"),
    (inv::ADJACENCY, "adjacency lists"),
    (inv::MEASURED, "measured content"),
    (inv::FREE_LIST, "free list"),
];

struct Checks {
    reports: Vec<CheckReport>,
    ran: Vec<bool>,
}

impl Checks {
    fn new() -> Checks {
        Checks {
            reports: CHECKS
                .iter()
                .map(|&(id, name)| CheckReport {
                    id,
                    name,
                    status: CheckStatus::Skipped,
                    failure_count: 0,
                    failures: Vec::new(),
                })
                .collect(),
            ran: vec![false; CHECKS.len()],
        }
    }

    fn slot(&mut self, id: &str) -> &mut CheckReport {
        let i = CHECKS.iter().position(|c| c.0 == id).unwrap_or(0);
        self.ran[i] = true;
        &mut self.reports[i]
    }

    fn pass(&mut self, id: &str) {
        let r = self.slot(id);
        if r.status == CheckStatus::Skipped {
            r.status = CheckStatus::Passed;
        }
    }

    fn fail(&mut self, id: &str, message: String) {
        let r = self.slot(id);
        r.status = CheckStatus::Failed;
        r.failure_count += 1;
        if r.failures.len() < MAX_MESSAGES {
            r.failures.push(message);
        }
    }

    fn error(&mut self, e: Error) {
        match e {
            Error::Corrupt {
                invariant,
                location,
                detail,
            } => self.fail(invariant, format!("{location}: {detail}")),
            other => self.fail(inv::PAGE, other.to_string()),
        }
    }

    fn finish(self, mode: &'static str, txn_id: Option<u64>, file_length: u64) -> VerifyReport {
        let valid = self.reports.iter().all(|r| r.status != CheckStatus::Failed)
            && self.reports.iter().any(|r| r.status == CheckStatus::Passed);
        VerifyReport {
            mode,
            valid,
            txn_id,
            file_length,
            checks: self.reports,
        }
    }
}

/// Verifies the container in `src` (see the module docs). `Err` only for a file that is not
/// a recognisable fmrh container.
pub fn verify<S: Source>(src: S, full: bool) -> Result<VerifyReport> {
    let mode = if full { "full" } else { "fast" };
    let file_length = src.len();
    let mut checks = Checks::new();
    let slots = read_slots(&src)?;
    let (slot, record) = match choose_slot(&slots) {
        Ok(x) => x,
        Err(e @ Error::Unsupported { .. }) => return Err(e),
        Err(e) => {
            checks.error(e);
            return Ok(checks.finish(mode, None, file_length));
        }
    };
    checks.pass(inv::COMMIT_RECORD);
    checks.pass(inv::VERSION);
    let txn = record.txn_id.get();
    if file_length == record.file_length.get() {
        checks.pass(inv::FILE_LENGTH);
    } else {
        checks.fail(
            inv::FILE_LENGTH,
            format!(
                "file: {file_length} bytes; the commit record says {}{}",
                record.file_length.get(),
                if file_length < record.file_length.get() {
                    " (truncated)"
                } else {
                    " (an interrupted transaction left pages past the end; `fmrh recover` cuts \
                     them)"
                }
            ),
        );
    }
    match &slots[1 - slot as usize] {
        Slot::Empty => checks.pass(inv::INACTIVE_SLOT),
        Slot::Valid(r) if r.txn_id.get() < txn => checks.pass(inv::INACTIVE_SLOT),
        Slot::Valid(r) => checks.fail(
            inv::INACTIVE_SLOT,
            format!(
                "commit slot {}: transaction {} is not older than the active {txn}",
                1 - slot,
                r.txn_id.get()
            ),
        ),
        Slot::Invalid(e) => checks.fail(
            inv::INACTIVE_SLOT,
            format!(
                "commit slot {}: neither zero nor a valid record ({e}); an interrupted commit \
                 leaves a torn record, which `fmrh recover` clears",
                1 - slot
            ),
        ),
    }
    // The rest of each slot page, after the record, is zero.
    let p = u64::from(record.page_size.get());
    for s in 0..2u64 {
        let tail = p - COMMIT_RECORD_LEN as u64;
        match src.read_at(s * p + COMMIT_RECORD_LEN as u64, tail as usize) {
            Ok(b) if is_zero(&b) => {}
            _ => checks.fail(
                if s == u64::from(slot) {
                    inv::COMMIT_RECORD
                } else {
                    inv::INACTIVE_SLOT
                },
                format!("commit slot {s}: the page after the record is not zero"),
            ),
        }
    }
    if file_length < record.file_length.get() {
        return Ok(checks.finish(mode, Some(txn), file_length));
    }
    let store = match Store::from_source(src) {
        Ok(s) => s,
        Err(e @ Error::Unsupported { .. }) => return Err(e),
        Err(e) => {
            checks.error(e);
            return Ok(checks.finish(mode, Some(txn), file_length));
        }
    };
    for id in [
        inv::PAGE,
        inv::DATASET_HEADER,
        inv::TREE_SHAPE,
        inv::CLUSTER_DIRECTORY,
    ] {
        checks.pass(id);
    }
    let loaded = match Loaded::read(&store) {
        Ok(l) => l,
        Err(e) => {
            checks.error(e);
            return Ok(checks.finish(mode, Some(txn), file_length));
        }
    };
    check_free_list(&store, &loaded, &mut checks);
    check_nodes(&store, &loaded, &mut checks);
    check_blocks(&store, &loaded, &mut checks);
    let payload_pages = check_payloads(&store, &loaded, &mut checks);
    check_ownership(&store, &loaded, &payload_pages, &mut checks);
    check_index_entries(&store, &loaded, &mut checks);
    if full
        && !checks
            .reports
            .iter()
            .any(|r| r.status == CheckStatus::Failed)
    {
        check_cuts(&store, &loaded, &mut checks);
        check_adjacency(&store, &loaded, &mut checks);
        check_measured(&store, &loaded, &mut checks);
    }
    Ok(checks.finish(mode, Some(txn), file_length))
}

/// The tables, read once.
struct Loaded {
    nodes: Vec<NodeRecord>,
    blocks: Vec<BlockRecord>,
    free: Vec<(u64, u64)>,
    indexes: Vec<Vec<IndexEntry>>,
    adjacency: Vec<[Vec<u32>; 4]>,
}

impl Loaded {
    fn read<S: Source>(store: &Store<S>) -> Result<Loaded> {
        let c = &store.commit;
        let nodes = store.all_records(&c.node_table, specs::NODES)?;
        let blocks = store.all_records(&c.block_table, specs::BLOCKS)?;
        let free = store
            .free_list()?
            .iter()
            .map(|f| (f.page.get(), f.freed_txn.get()))
            .collect();
        let mut indexes = Vec::new();
        let mut adjacency = Vec::new();
        for cl in store.clusters() {
            indexes.push(store.all_records(&cl.index, specs::INDEX)?);
        }
        for c in 0..store.clusters().len() {
            let mut lists: [Vec<u32>; 4] = Default::default();
            for (edge, list) in lists.iter_mut().enumerate() {
                *list = store.adjacency(c, edge)?;
            }
            adjacency.push(lists);
        }
        Ok(Loaded {
            nodes,
            blocks,
            free,
            indexes,
            adjacency,
        })
    }
}

fn check_free_list<S: Source>(store: &Store<S>, l: &Loaded, checks: &mut Checks) {
    let mut prev = None;
    for &(page, txn) in &l.free {
        if page < 2 || page >= store.page_count() || prev.is_some_and(|p| page <= p) {
            checks.fail(
                inv::FREE_LIST,
                format!("free page {page}: out of order or outside the file"),
            );
        }
        if txn > store.txn_id() {
            checks.fail(
                inv::FREE_LIST,
                format!("free page {page}: freed by future transaction {txn}"),
            );
        }
        prev = Some(page);
    }
    checks.pass(inv::FREE_LIST);
}

fn check_nodes<S: Source>(store: &Store<S>, l: &Loaded, checks: &mut Checks) {
    let id = inv::NODE_TABLE;
    let d = store.domain();
    let finest = d.finest_level();
    let delta_min = store.header().delta_min;
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
            if p.level + 1 != level
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
        if flags & !NODE_GRID_HAS_VOIDS != 0
            || (level == finest && flags != 0)
            || n.reserved.get() != 0
        {
            checks.fail(
                id,
                format!("{at}: unknown flags {flags:#x} or reserved bits set"),
            );
        }
        // Children: those kept are exactly the mask's, each right after its elder sibling's
        // subtree.
        let mut mask = 0u8;
        let mut c = i as u64 + 1;
        let end = i as u64 + sub;
        while c < end {
            let ch = &nodes[c as usize];
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
        if sub > 1 {
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
            if m != 0.0 {
                checks.fail(id, format!("{at}: a physical block with error {m}"));
            }
            if let Some(b) = l.blocks.get((y * cols + x) as usize) {
                if (n.payload_offset, n.payload_len, n.payload_crc)
                    != (b.payload_offset, b.payload_len, b.payload_crc)
                {
                    checks.fail(id, format!("{at}: payload is not its block's"));
                }
            }
        } else {
            let (gw, gh) = payload::grid_dims(d, level, x, y);
            let want = payload::grid_len(gw, gh, flags & NODE_GRID_HAS_VOIDS != 0);
            if u64::from(n.payload_len.get()) != want {
                checks.fail(
                    id,
                    format!(
                        "{at}: grid payload of {} bytes, expected {want}",
                        n.payload_len.get()
                    ),
                );
            }
        }
    }
    checks.pass(id);
}

fn check_blocks<S: Source>(store: &Store<S>, l: &Loaded, checks: &mut Checks) {
    let id = inv::BLOCK_TABLE;
    let d = store.domain();
    let (cols, _) = d.nodes_across(d.finest_level());
    for (i, b) in l.blocks.iter().enumerate() {
        let (x, y) = (i as u32 % cols, i as u32 / cols);
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
            || u64::from(b.payload_len.get()) != payload::block_len(w, h, v)
            || b.reserved.get() != 0
        {
            checks.fail(
                id,
                format!(
                    "block ({x}, {y}): {v} voids, {} payload bytes",
                    b.payload_len.get()
                ),
            );
        }
    }
    checks.pass(id);
}

/// Checks every payload (I-9): in the file, aligned, disjoint, CRC, zero gaps, block
/// content. Returns the pages payloads occupy.
fn check_payloads<S: Source>(store: &Store<S>, l: &Loaded, checks: &mut Checks) -> PageSet {
    let id = inv::PAYLOAD;
    let d = store.domain();
    let finest = d.finest_level();
    let (cols, _) = d.nodes_across(finest);
    let p = u64::from(store.page_size());
    let mut pages = PageSet::new(store.page_count());
    // (offset, len, crc, what)
    let mut runs: Vec<(u64, u32, u32, Payload)> =
        Vec::with_capacity(l.nodes.len() + l.blocks.len());
    for (i, b) in l.blocks.iter().enumerate() {
        runs.push((
            b.payload_offset.get(),
            b.payload_len.get(),
            b.payload_crc.get(),
            Payload::Block(i),
        ));
    }
    for (i, n) in l.nodes.iter().enumerate() {
        if n.level < finest {
            runs.push((
                n.payload_offset.get(),
                n.payload_len.get(),
                n.payload_crc.get(),
                Payload::Grid(i),
            ));
        }
    }
    runs.sort_unstable_by_key(|r| r.0);
    let start = 2 * p;
    let end_of_file = store.page_count() * p;
    let mut prev_end: Option<u64> = None;
    for &(offset, len, crc, what) in &runs {
        let at = format!("{what} payload at byte {offset}");
        let end = offset.saturating_add(u64::from(len));
        if offset < start || end > end_of_file || offset % PAYLOAD_ALIGN != 0 {
            checks.fail(id, format!("{at}: misplaced or misaligned ({len} bytes)"));
            continue;
        }
        match prev_end {
            Some(pe) if offset < pe => {
                checks.fail(id, format!("{at}: overlaps the payload before it"));
                continue;
            }
            Some(pe) => zero_gap(store, pe, offset, p, checks),
            None => zero_gap(store, offset - offset % p, offset, p, checks),
        }
        prev_end = Some(end);
        for page in offset / p..end.div_ceil(p) {
            pages.insert(page);
        }
        let bytes = match store.payload(offset, len, crc) {
            Ok(b) => b,
            Err(e) => {
                checks.error(e);
                continue;
            }
        };
        if let Payload::Block(i) = what {
            let b = &l.blocks[i];
            let (x, y) = (i as u32 % cols, i as u32 / cols);
            let Some(view) =
                BlockView::new(&bytes, b.width.get(), b.height.get(), b.void_count.get())
            else {
                continue; // the length was reported under I-11
            };
            let mut voids = 0u32;
            let mut bad = 0u64;
            for s in view.samples() {
                let v = s.get();
                if v.is_nan() {
                    voids += 1;
                    bad += u64::from(v.to_bits() != VOID_BITS);
                } else {
                    bad += u64::from(!v.is_finite());
                }
            }
            bad += view
                .stand_ins()
                .iter()
                .filter(|s| !s.get().is_finite())
                .count() as u64;
            if voids != b.void_count.get() || bad > 0 {
                checks.fail(id, format!("block ({x}, {y}): {voids} NaN samples for {} recorded voids, {bad} non-canonical or infinite values", b.void_count.get()));
            }
        }
    }
    if let Some(pe) = prev_end {
        zero_gap(store, pe, pe.next_multiple_of(p), p, checks);
    }
    checks.pass(id);
    pages
}

#[derive(Clone, Copy, Debug)]
enum Payload {
    Block(usize),
    Grid(usize),
}

impl std::fmt::Display for Payload {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            Payload::Block(i) => write!(f, "block {i}"),
            Payload::Grid(i) => write!(f, "node {i} grid"),
        }
    }
}

/// Checks that the bytes from `from` to `to` that share a page with a payload are zero: the
/// tail of `from`'s page and the head of `to`'s page (whole pages between belong to someone
/// else or to nobody, which I-8 reports).
fn zero_gap<S: Source>(store: &Store<S>, from: u64, to: u64, p: u64, checks: &mut Checks) {
    if from >= to || store.commit_record().flags.get() & crate::format::COMMIT_PAYLOAD_SLACK != 0 {
        return;
    }
    // Only the pages the gap shares with a payload: the tail of the page holding the byte
    // before `from`, and the head of the page holding the byte at `to`.
    let mut ranges: Vec<(u64, u64)> = Vec::new();
    if !from.is_multiple_of(p) {
        ranges.push((from, to.min((from / p + 1) * p)));
    }
    if !to.is_multiple_of(p) {
        let head = (from.max(to / p * p), to);
        match ranges.last_mut() {
            Some(last) if last.1 >= head.0 => last.1 = last.1.max(head.1),
            _ => ranges.push(head),
        }
    }
    for (a, b) in ranges {
        match store.source().read_at(a, (b - a) as usize) {
            Ok(bytes) if is_zero(&bytes) => {}
            Ok(_) => checks.fail(
                inv::PAYLOAD,
                format!("bytes {a}..{b} between payloads are not zero"),
            ),
            Err(e) => checks.fail(inv::FILE_LENGTH, format!("bytes {a}..{b}: {e}")),
        }
    }
}

fn check_ownership<S: Source>(
    store: &Store<S>,
    l: &Loaded,
    payload: &PageSet,
    checks: &mut Checks,
) {
    let id = inv::PAGE_OWNERSHIP;
    let meta = store.metadata_pages();
    let mut free = PageSet::new(store.page_count());
    for &(page, _) in &l.free {
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
    if let Some(first) = first_orphan {
        checks.fail(
            id,
            format!("{orphans} pages belong to no structure (first: page {first})"),
        );
    }
    checks.pass(id);
}

fn check_index_entries<S: Source>(store: &Store<S>, l: &Loaded, checks: &mut Checks) {
    for (c, (info, entries)) in store.clusters().iter().zip(&l.indexes).enumerate() {
        let mut max = 0f64;
        for (k, e) in entries.iter().enumerate() {
            let at = format!("cluster {c} entry {k}");
            match l.nodes.get(e.node.get() as usize) {
                Some(n) if n.key == e.key && n.level == e.level && e.reserved == [0; 3] => {
                    max = max.max(n.monotone_error.get());
                }
                _ => checks.fail(
                    inv::CLUSTER_INDEX,
                    format!(
                        "{at}: names node {} with another key or level",
                        e.node.get()
                    ),
                ),
            }
        }
        if max != info.max_error {
            checks.fail(
                inv::CLUSTER_DIRECTORY,
                format!(
                    "cluster {c}: max error {} recorded, {max} found",
                    info.max_error
                ),
            );
        }
        for (edge, list) in l.adjacency[c].iter().enumerate() {
            if let Some(&bad) = list.iter().find(|&&n| n as usize >= l.nodes.len()) {
                checks.fail(
                    inv::ADJACENCY,
                    format!(
                        "cluster {c} {} edge: node {bad} does not exist",
                        cluster::EDGES[edge]
                    ),
                );
            }
        }
    }
    checks.pass(inv::CLUSTER_INDEX);
}

fn check_cuts<S: Source>(store: &Store<S>, l: &Loaded, checks: &mut Checks) {
    let id = inv::CLUSTER_INDEX;
    let d = store.domain();
    let finest = d.finest_level();
    let (cols, rows) = d.nodes_across(finest);
    let total = u64::from(cols) * u64::from(rows);
    for (c, (info, entries)) in store.clusters().iter().zip(&l.indexes).enumerate() {
        let delta = info.threshold;
        let mut covered = 0u64;
        let mut prev_end = 0u64;
        for (k, e) in entries.iter().enumerate() {
            let at = format!("cluster {c} entry {k}");
            let Some(n) = l.nodes.get(e.node.get() as usize) else {
                continue;
            };
            let (key, level) = (n.key.get(), n.level);
            if key < prev_end {
                checks.fail(
                    id,
                    format!("{at}: overlaps the node before it (no overlap)"),
                );
            }
            prev_end = key.saturating_add(HilbertKey::span(finest, level));
            let side = 1u64 << (finest - level);
            let (x0, y0) = (u64::from(n.x.get()) * side, u64::from(n.y.get()) * side);
            covered += ((x0 + side).min(u64::from(cols)) - x0.min(u64::from(cols)))
                * ((y0 + side).min(u64::from(rows)) - y0.min(u64::from(rows)));
            let m = n.monotone_error.get();
            if m > delta {
                checks.fail(
                    id,
                    format!("{at}: e* {m} exceeds the threshold {delta} (bound)"),
                );
            }
            let parent = n.parent.get();
            if parent != NO_PARENT
                && l.nodes
                    .get(parent as usize)
                    .is_some_and(|p| p.monotone_error.get() <= delta)
            {
                checks.fail(
                    id,
                    format!("{at}: its parent already meets {delta} (minimality)"),
                );
            }
        }
        if covered != total {
            checks.fail(
                id,
                format!("cluster {c}: covers {covered} of {total} physical blocks (cover)"),
            );
        }
    }
}

fn check_adjacency<S: Source>(store: &Store<S>, l: &Loaded, checks: &mut Checks) {
    let d = store.domain();
    for (c, entries) in l.indexes.iter().enumerate() {
        let cut: Vec<u32> = entries.iter().map(|e| e.node.get()).collect();
        let want = cluster::edge_nodes_by(d, &cut, |i| {
            let n = &l.nodes[i as usize];
            d.footprint(n.level, n.x.get(), n.y.get())
        });
        for (edge, (stored, want)) in l.adjacency[c].iter().zip(want).enumerate() {
            if *stored != want {
                checks.fail(
                    inv::ADJACENCY,
                    format!(
                        "cluster {c} {} edge: {} nodes stored, {} touch it (or the order differs)",
                        cluster::EDGES[edge],
                        stored.len(),
                        want.len()
                    ),
                );
            }
        }
    }
    checks.pass(inv::ADJACENCY);
}

/// I-15: rebuilds the model from the physical blocks and compares everything derived.
fn check_measured<S: Source>(store: &Store<S>, l: &Loaded, checks: &mut Checks) {
    let id = inv::MEASURED;
    let d = *store.domain();
    let (w, h) = (u64::from(d.width()), u64::from(d.height()));
    if w * h * 4 > store.commit.file_length.get() {
        checks.fail(id, "the data size exceeds what the file can hold".into());
        return;
    }
    // Assemble the samples; blocks that share an edge must agree on it.
    let finest = d.finest_level();
    let (cols, _) = d.nodes_across(finest);
    let mut samples = vec![0f32; (w * h) as usize];
    for (i, b) in l.blocks.iter().enumerate() {
        let (x, y) = (i as u32 % cols, i as u32 / cols);
        let block = match store.block(x, y) {
            Ok(b) => b,
            Err(e) => return checks.error(e),
        };
        let view = block.view();
        let r = block.rect;
        let mut disagree = 0u64;
        for row in r.row0..=r.row1 {
            for col in r.col0..=r.col1 {
                let v = view.samples()
                    [((row - r.row0) * u64::from(b.width.get()) + col - r.col0) as usize]
                    .get();
                let slot = &mut samples[(row * w + col) as usize];
                let shared = (col == r.col0 && x > 0) || (row == r.row0 && y > 0);
                if shared && slot.to_bits() != v.to_bits() {
                    disagree += 1;
                }
                *slot = v;
            }
        }
        if disagree > 0 {
            checks.fail(
                id,
                format!("block ({x}, {y}): {disagree} samples differ from its neighbours' copies"),
            );
        }
    }
    let hf = match Heightfield::new(d.width(), d.height(), samples) {
        Ok(hf) => hf,
        Err(e) => return checks.fail(id, format!("stored samples: {e}")),
    };
    let options = BuildOptions {
        block_size: d.block_size(),
        thresholds: Thresholds::Explicit(store.clusters().iter().map(|c| c.threshold).collect()),
    };
    let model = match Model::build(hf, &options) {
        Ok(m) => m,
        Err(e) => return checks.fail(id, format!("rebuilding: {e}")),
    };
    let tree = model.tree();
    if tree.nodes().len() != l.nodes.len() {
        checks.fail(
            id,
            format!(
                "{} nodes stored, the blocks give {}",
                l.nodes.len(),
                tree.nodes().len()
            ),
        );
        return;
    }
    for (i, (s, n)) in l.nodes.iter().zip(tree.nodes()).enumerate() {
        let same = s.key.get() == n.key.0
            && s.level == n.level
            && s.child_mask == n.child_mask
            && s.static_error.get().to_bits() == n.static_error.to_bits()
            && s.monotone_error.get().to_bits() == n.monotone_error.to_bits()
            && s.min_height.get().to_bits() == n.min_height.to_bits()
            && s.max_height.get().to_bits() == n.max_height.to_bits()
            && s.valid_samples.get() == n.valid_samples;
        if !same {
            checks.fail(id, format!("node {i}: stored error/range/count differ from the blocks' (stored e {} e* {}, measured e {} e* {})", s.static_error.get(), s.monotone_error.get(), n.static_error, n.monotone_error));
            continue;
        }
        if n.level < finest {
            let full = model.node_grid(i as u32);
            let (clipped, gw, _) = super::write::clipped_grid(&model, i as u32);
            let b = full.size;
            let ok = store.grid(s).is_ok_and(|g| {
                let v: GridView<'_> = g.view();
                let has = s.flags.get() & NODE_GRID_HAS_VOIDS != 0;
                has == clipped.void.iter().any(|&x| x)
                    && v.stored_width == gw
                    && v.stored()
                        .iter()
                        .zip(&clipped.heights)
                        .all(|(a, b)| a.get().to_bits() == b.to_bits())
                    && (0..b * b).all(|k| {
                        let (gi, gj) = (k % b, k / b);
                        v.is_void(gi, gj) == full.void[k as usize]
                            && v.height(gi, gj).to_bits() == full.heights[k as usize].to_bits()
                    })
            });
            if !ok {
                checks.fail(
                    id,
                    format!("node {i}: its grid is not the decimation of the blocks"),
                );
            }
        }
    }
    for (c, (mine, entries)) in model.clusters().iter().zip(&l.indexes).enumerate() {
        if mine.nodes.len() != entries.len()
            || mine
                .nodes
                .iter()
                .zip(entries)
                .any(|(a, e)| *a != e.node.get())
        {
            checks.fail(
                id,
                format!("cluster {c}: the stored cut differs from the rebuilt one"),
            );
        }
    }
    // Stand-ins: each void's mended height.
    let raster = model.raster();
    for (i, b) in l.blocks.iter().enumerate() {
        if b.void_count.get() == 0 {
            continue;
        }
        let (x, y) = (i as u32 % cols, i as u32 / cols);
        let Ok(block) = store.block(x, y) else {
            continue;
        };
        let view = block.view();
        let r: SampleRect = block.rect;
        let mut k = 0usize;
        let mut wrong = 0u64;
        for row in r.row0..=r.row1 {
            for col in r.col0..=r.col1 {
                if !raster.is_valid(col, row) {
                    let stored = view.stand_ins().get(k).map(|v| v.get().to_bits());
                    wrong += u64::from(stored != Some(raster.value(col, row).to_bits()));
                    k += 1;
                }
            }
        }
        if wrong > 0 {
            checks.fail(
                id,
                format!("block ({x}, {y}): {wrong} void stand-ins are not the mended heights"),
            );
        }
    }
    checks.pass(id);
}
