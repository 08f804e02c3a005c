//! Payloads (I-9): inside the file, aligned, disjoint, CRC, zero gaps between them, and
//! block samples finite or the canonical void.

use super::{Checks, Loaded};
use crate::error::Result;
use crate::format::payload::BlockView;
use crate::format::{
    is_zero, payload_align, Invariant, PayloadRef, COMMIT_PAYLOAD_SLACK, VOID_BITS,
};
use crate::progress::{Phase, Progress, Unit};
use crate::store::pages::PageSet;
use crate::store::{Source, Store};

/// Checks every payload (I-9): in the file, aligned, disjoint, CRC, zero gaps, block
/// content. Returns the pages payloads occupy.
pub(super) fn check_payloads<S: Source>(
    store: &Store<S>,
    l: &Loaded,
    checks: &mut Checks,
    progress: &dyn Progress,
) -> Result<PageSet> {
    let id = Invariant::Payload;
    let d = store.domain();
    let finest = d.finest_level();
    let (cols, _) = d.nodes_across(finest);
    let p = u64::from(store.page_size());
    let mut pages = PageSet::new(store.page_count());
    let mut runs: Vec<(PayloadRef, Payload)> = Vec::with_capacity(l.nodes.len() + l.blocks.len());
    for (i, b) in l.blocks.iter().enumerate() {
        runs.push((b.payload(), Payload::Block(i)));
    }
    for (i, n) in l.nodes.iter().enumerate() {
        if n.level < finest {
            runs.push((n.payload(), Payload::Grid(i)));
        }
    }
    // The metadata bundle's stored bytes are placed like a payload (format §6.7); opening
    // checked their CRC and content.
    let bundle = store.commit_record().bundle;
    if bundle.is_present() {
        runs.push((bundle.payload(), Payload::Bundle));
    }
    runs.sort_unstable_by_key(|r| r.0.offset);
    let start = 2 * p;
    let end_of_file = store.page_count() * p;
    let mut prev_end: Option<u64> = None;
    let coded = store.commit_record().payloads_coded();
    let align = payload_align(coded);
    let total: u64 = runs.iter().map(|r| u64::from(r.0.len)).sum();
    let phase = Phase::start(progress, "checking payloads", total, Unit::Bytes);
    let mut prev: Option<PayloadRef> = None;
    let mut last_parent = None;
    for &(r, what) in &runs {
        let (offset, len) = (r.offset, r.len);
        let at = format!("{what} payload at byte {offset}");
        // Records with identical payloads may share one (format §7): its place is checked
        // once, its content against every record's own shape.
        let shared = coded && prev == Some(r) && !matches!(what, Payload::Bundle);
        prev = Some(r);
        phase.advance(u64::from(len));
        if !shared {
            let end = r.end();
            if offset < start || end > end_of_file || offset % align != 0 {
                checks.fail(id, format!("{at}: misplaced or misaligned ({len} bytes)"));
                continue;
            }
            match prev_end {
                Some(pe) if offset < pe => {
                    checks.fail(id, format!("{at}: overlaps the payload before it"));
                    continue;
                }
                Some(pe) => zero_gap(store, pe, offset, p, checks)?,
                None => zero_gap(store, offset - offset % p, offset, p, checks)?,
            }
            prev_end = Some(end);
            for page in offset / p..end.div_ceil(p) {
                pages.insert(page);
            }
        }
        if matches!(what, Payload::Bundle) {
            // Opening checked the record's CRC and the pages it read; a 5.0 bundle's other
            // pages are read when a lookup reaches them: every one is checked here.
            checks.absorb(store.check_bundle_pages())?;
            continue;
        }
        let Some(bytes) = checks.absorb(store.payload(r))? else {
            continue;
        };
        if let Payload::Grid(i) = what {
            // A coded grid must decode to its layout: against its parent's grid when it is
            // coded so (format 5), which the store decodes (and keeps) first.
            let n = l.nodes[i].decode();
            if store.commit_record().payloads_coded() {
                if let Err(e) = store.grid_from(&n, bytes.clone()) {
                    checks.fail(id, format!("{at}: {e}"));
                }
            }
        }
        if let Payload::Block(i) = what {
            let b = &l.blocks[i];
            let (x, y) = (i % cols as usize, i / cols as usize);
            let bytes = if store.commit_record().payloads_coded() {
                let (x, y) = super::block_xy(i, cols);
                let info = b.decode();
                // A block coded against its parent's grid (format 4) decodes with it; a
                // parent's children follow it in file order, so one grid is kept at a time.
                if let Err(e) = store.keep_parent(x, y, &info, &mut last_parent) {
                    checks.fail(id, format!("block ({x}, {y}): {e}"));
                    continue;
                }
                match store.block_with(x, y, info, bytes, last_parent.as_deref()) {
                    Ok(block) => std::borrow::Cow::Owned(block.bytes().to_vec()),
                    Err(e) => {
                        checks.fail(id, format!("block ({x}, {y}): {e}"));
                        continue;
                    }
                }
            } else {
                bytes
            };
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
    drop(phase);
    if let Some(pe) = prev_end {
        zero_gap(store, pe, pe.next_multiple_of(p), p, checks)?;
    }
    checks.pass(id);
    Ok(pages)
}

#[derive(Clone, Copy, Debug)]
enum Payload {
    Block(usize),
    Grid(usize),
    Bundle,
}

impl std::fmt::Display for Payload {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            Payload::Block(i) => write!(f, "block {i}"),
            Payload::Grid(i) => write!(f, "node {i} grid"),
            Payload::Bundle => write!(f, "metadata bundle"),
        }
    }
}

/// Checks that the bytes from `from` to `to` that share a page with a payload are zero: the
/// tail of `from`'s page and the head of `to`'s page (whole pages between belong to someone
/// else or to nobody, which I-8 reports).
fn zero_gap<S: Source>(
    store: &Store<S>,
    from: u64,
    to: u64,
    p: u64,
    checks: &mut Checks,
) -> Result<()> {
    if from >= to || store.commit_record().has_flag(COMMIT_PAYLOAD_SLACK) {
        return Ok(());
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
        // A gap lies within one page.
        let len = usize::try_from(b - a).unwrap_or(0);
        if let Some(bytes) = checks.absorb(crate::store::source::read(store.source(), a, len))? {
            if !is_zero(&bytes) {
                checks.fail(
                    Invariant::Payload,
                    format!("bytes {a}..{b} between payloads are not zero"),
                );
            }
        }
    }
    Ok(())
}
