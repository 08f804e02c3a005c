//! The cleaner of one commit: which kept payloads to move so that the pages they sit on can
//! be freed.
//!
//! A page is freed only when no payload of the new state touches it. A build packs payloads
//! end to end, and a commit packs its own the same way, so a page holds parts of several
//! payloads; an edit replaces some of them and the page stays, held by the rest. Left alone,
//! pages fill with dead bytes: 300 edits grew a mostly-sea SRTM tile to 12.5× a fresh build
//! of the same samples, 86 % of it dead payload bytes (issue 39).
//!
//! **The rule.** The *waste* of the kept pages is their dead bytes: for each page a kept
//! payload touches, the page size less the kept bytes on it. While the waste is at most
//! [`MAX_WASTE_PERCENT`] % of the kept bytes (plus [`GRACE_PAGES`] pages, so that a small file
//! does not churn for a page), nothing moves. Past it, segments of [`SEGMENT_PAGES`] aligned
//! pages are cleaned, the most waste per kept byte first, each by moving every kept payload
//! that touches it into the pages this commit writes (packed end to end with its own), until
//! the waste is down to [`CLEAN_TO_PERCENT`] %, or until the moves reach the commit's budget
//! (half the reusable holes' bytes, at least two segments; the cleaning goes on at the next
//! commit): moves that outgrow the holes are appended, and the file swings by them until the
//! next commit cuts what they freed (Puget Sound 1k's largest size between every 100 edits
//! went from 1.53 to 1.65x a fresh build down to 1.50 to 1.56x). A segment is cleaned only
//! when that lowers the waste: its payloads that straddle into the pages beside it thin
//! those pages.
//!
//! **Holes.** Free pages inside the file are overhead too (a file is cut back only where
//! free pages end it). The allocator hands out the first free run that holds what is asked
//! (`alloc`), so payloads gather at the front; but a hole takes only a payload that fits it,
//! and a commit frees about what it writes, so holes stay where edits left them (a quarter
//! of Puget Sound 1k after 1,000 edits, single pages between live ones). So when the
//! reusable holes, less what the commit's tables will take, pass [`MAX_HOLES_PERCENT`] % of
//! the file (+ [`GRACE_PAGES`]), the commit empties the file's *tail* into them
//! ([`tail_to_move`]): from the last page back, every kept payload on a page is moved, up to
//! half the holes' bytes beyond the allowance and never a payload longer than the longest
//! hole, and never past a page the commit wrote; the next commit cuts the emptied end off.
//! Moving the last segments at *every* commit was tried first and churned: the holes a
//! commit leaves are the old copies it freed, which the next one fills anyway, and on the
//! SRTM tile the whole file moved at every commit. Past an allowance only, with the
//! cleaner's budget above, Puget Sound 1k measured 1.35 to 1.42x a fresh build every 100
//! edits (against 1.52 to 1.64 before), for 19 MB moved over the 1,000 commits against 9 MB,
//! with a waste allowance of 25 %; at 15 % (now), 1.26 to 1.38x for 64 MB.
//!
//! **Why it stays bounded, and cheap.** After every commit the pages kept from older states
//! waste at most `MAX_WASTE_PERCENT` % (+ grace) of what they hold, unless no segment's
//! cleaning would lower the waste (tested: `after_edits_what_stays_is_within_the_allowance`
//! finds none in a packed file thinned by edits); the pages the commit wrote
//! itself are packed, with one partial page at the end of each run. A commit adds to the
//! waste only the bytes it replaced on kept pages, so the cleaner moves, on average, about
//! what a commit replaces times `u / (1 - u)`, `u` the fill of the segments it cleans: the
//! emptiest first, so `u` is low. The gap between the two percentages lets one cleaning pay
//! for several commits. Two rules by the page were tried first and churned, because payloads
//! straddle pages: moving whatever sits on a page less than 80 % full moved a third of Puget
//! Sound 1k at every commit, and cleaning the emptiest pages first under this allowance
//! moved the whole file at once (each payload moved off a sparse page thinned the full page
//! beside it).
//!
//! Moving a payload changes its place, never its bytes: its CRC, its coding and whatever it is
//! coded against stay as they were. The old pages are freed as of this commit like any
//! replaced payload's, so a snapshot of an older state keeps reading them (format §11.3).

use std::collections::{BTreeMap, BTreeSet};

use crate::format::payload::PayloadRef;

/// The waste the kept pages may reach before a commit cleans, in percent of the kept bytes.
/// 15 % (cleaning to 8 %) was tried first, before the cleaner had a budget and the tail
/// rule: over 400 edits of Puget Sound 1k it moved 41 MB (against 3.2 MB) and left the file
/// *larger* (1.71x a fresh build against 1.60x), since the pages it freed were holes in the
/// middle of the file that later commits filled only slowly. With the budget (moves about
/// what the holes take) and the tail rule, 25 % held Puget Sound 1k at 1.35 to 1.42x after
/// every 100 edits (1.56 between rows) for 19 MB moved over 1,000 edits, and 15 % at 1.26 to
/// 1.38x (1.41 between) for 64 MB; Puget Sound 4k's largest between rows went from 1.16 to
/// 1.09x. 12 % gained 0.02 more for another 35 MB: the rest is not waste (module docs).
pub const MAX_WASTE_PERCENT: u64 = 15;

/// The waste a cleaning commit brings it down to, in percent of the kept bytes: below the
/// allowance, so that one cleaning pays for several commits. In practice a cleaning stops
/// at the commit's budget first (10 and 12 % moved the same bytes over 1,000 edits).
pub const CLEAN_TO_PERCENT: u64 = 10;

/// The cleaner's unit: aligned groups of this many pages, each cleaned whole (every kept
/// payload touching it moves). A page at a time churned: payloads straddle pages, so moving
/// one off a sparse page thins the full pages beside it, and on Puget Sound 1k the whole
/// file moved at once. A segment's straddlers thin at most one page at each end.
pub const SEGMENT_PAGES: u64 = 16;

/// Waste allowed beyond the percentages, in pages: a file of a few pages does not move its
/// payloads to win back one.
pub const GRACE_PAGES: u64 = 2;

/// Of `kept` (the payloads a commit keeps in place, duplicates allowed), those to move,
/// each once, in file order (the rules in the module's docs); no segment is begun once
/// `budget` bytes move (the caller's: about what the holes can take, so that the moves
/// fill holes rather than grow the file). Empty payloads touch no page and never move.
pub fn payloads_to_move(kept: &[PayloadRef], page_size: u32, budget: u64) -> Vec<PayloadRef> {
    let mut plan = Plan::new(kept, page_size);
    let p = plan.p;
    let allowed = |held: u64, percent: u64| held * percent / 100 + GRACE_PAGES * p;
    if plan.waste <= allowed(plan.held, MAX_WASTE_PERCENT) {
        return Vec::new();
    }
    // The segments with the most waste per kept byte (ties by place, so the choice is
    // reproducible), each only when cleaning it lowers the waste.
    let mut order: Vec<(u64, u64, u64)> = plan
        .segments()
        .into_iter()
        .filter(|&(_, w, _)| w > 0)
        .map(|(seg, w, b)| (w, b, seg))
        .collect();
    order.sort_by(|x, y| {
        (u128::from(y.0) * u128::from(x.1))
            .cmp(&(u128::from(x.0) * u128::from(y.1)))
            .then(x.2.cmp(&y.2))
    });
    for (_, _, seg) in order {
        if plan.waste <= allowed(plan.held, CLEAN_TO_PERCENT) || plan.moved_bytes >= budget {
            break;
        }
        plan.clean(seg);
    }
    plan.moved()
}

/// The cleaner's working state: the kept payloads, their bytes on each page, which move.
struct Plan {
    page_size: u32,
    p: u64,
    refs: Vec<PayloadRef>,
    /// Kept bytes on each page (payloads never overlap); 0 once emptied.
    live: BTreeMap<u64, u64>,
    /// The payloads touching each page.
    on: BTreeMap<u64, Vec<usize>>,
    moved: Vec<bool>,
    /// Bytes of the payloads that stay.
    held: u64,
    /// Waste of the pages they touch.
    waste: u64,
    /// Bytes of the payloads that move.
    moved_bytes: u64,
}

impl Plan {
    fn new(kept: &[PayloadRef], page_size: u32) -> Plan {
        let p = u64::from(page_size);
        let unique: BTreeSet<(u64, u32, u32)> = kept
            .iter()
            .filter(|r| r.len > 0)
            .map(|r| (r.offset, r.len, r.crc))
            .collect();
        let refs: Vec<PayloadRef> = unique
            .into_iter()
            .map(|(offset, len, crc)| PayloadRef { offset, len, crc })
            .collect();
        let mut live: BTreeMap<u64, u64> = BTreeMap::new();
        let mut on: BTreeMap<u64, Vec<usize>> = BTreeMap::new();
        for (i, r) in refs.iter().enumerate() {
            for (page, bytes) in page_parts(r, page_size) {
                *live.entry(page).or_default() += bytes;
                on.entry(page).or_default().push(i);
            }
        }
        Plan {
            page_size,
            p,
            held: live.values().sum(),
            waste: live.values().map(|&b| p - b.min(p)).sum(),
            moved: vec![false; refs.len()],
            moved_bytes: 0,
            refs,
            live,
            on,
        }
    }

    /// Each segment holding kept bytes, in file order: (segment, waste, kept bytes).
    fn segments(&self) -> Vec<(u64, u64, u64)> {
        let mut segments: BTreeMap<u64, (u64, u64)> = BTreeMap::new();
        for (&page, &bytes) in self.live.iter().filter(|(_, &b)| b > 0) {
            let e = segments.entry(page / SEGMENT_PAGES).or_default();
            e.0 += self.p - bytes.min(self.p);
            e.1 += bytes;
        }
        segments.into_iter().map(|(s, (w, b))| (s, w, b)).collect()
    }

    /// Moves every kept payload touching segment `seg` when that lowers the waste (a page
    /// emptied stops wasting; a page its straddlers thin wastes what it lost). Returns
    /// whether it did.
    fn clean(&mut self, seg: u64) -> bool {
        let mut takes: BTreeMap<u64, u64> = BTreeMap::new();
        let mut movers = Vec::new();
        for page in seg * SEGMENT_PAGES..(seg + 1) * SEGMENT_PAGES {
            for &i in self.on.get(&page).map(Vec::as_slice).unwrap_or(&[]) {
                if !self.moved[i] && !movers.contains(&i) {
                    movers.push(i);
                    for (pg, bytes) in page_parts(&self.refs[i], self.page_size) {
                        *takes.entry(pg).or_default() += bytes;
                    }
                }
            }
        }
        let (mut gain, mut loss) = (0u64, 0u64);
        for (&pg, &t) in &takes {
            let b = self.live.get(&pg).copied().unwrap_or(0);
            if t >= b {
                gain += self.p - b.min(self.p);
            } else {
                loss += t;
            }
        }
        if movers.is_empty() || gain <= loss {
            return false;
        }
        self.waste = (self.waste + loss).saturating_sub(gain);
        for (&pg, &t) in &takes {
            if let Some(b) = self.live.get_mut(&pg) {
                *b -= t.min(*b);
            }
        }
        for i in movers {
            self.moved[i] = true;
            let len = u64::from(self.refs[i].len);
            self.held -= len;
            self.moved_bytes += len;
        }
        true
    }

    /// The payloads to move, in file order.
    fn moved(self) -> Vec<PayloadRef> {
        self.refs
            .into_iter()
            .zip(self.moved)
            .filter(|&(_, m)| m)
            .map(|(r, _)| r)
            .collect()
    }
}

/// Reusable free pages inside a file beyond this percentage of its pages (plus
/// [`GRACE_PAGES`]) make a commit empty the file's tail into them ([`tail_to_move`]).
pub const MAX_HOLES_PERCENT: u64 = 8;

/// What a page at the end of the file is to [`tail_to_move`].
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum TailPage {
    /// Free, or freed by this commit whatever it holds (the old state's tables, a payload
    /// no new record keeps): nothing stays on it.
    Leaves,
    /// Kept payloads touch it: they move, or it stays.
    Kept,
    /// This commit wrote it: it stays, and so does everything before it.
    Stays,
}

/// Of `kept`, the payloads to move so that the file's tail empties (a later commit then
/// cuts it off), when the reusable free pages inside the file (`holes`, after this commit's
/// own writes took theirs) pass [`MAX_HOLES_PERCENT`] % of its `end` pages plus
/// [`GRACE_PAGES`]. Walking back from the last page (`page(p)` says what each is): pages
/// that leave are passed, a page kept payloads touch has them all moved, a page this
/// commit wrote stops the walk; so does the budget, half the holes' bytes beyond the
/// allowance, and a payload longer than the longest hole (`largest_hole` pages): the moved
/// payloads are to go into the holes, not past the end, and runs do not fill holes whole.
/// The caller counts in `holes` only what the rest of the commit (its tables) leaves. Returns the payloads in file order, each once (`kept` may hold
/// duplicates).
///
/// **Why.** First fit fills holes from the front, but a hole only takes a payload that fits
/// it, and a commit frees about what it writes: so holes are not used up, they stay where
/// edits left them (a quarter of Puget Sound 1k after 1,000 edits, single pages between
/// live ones). Emptying the tail into them trades moved bytes for a file cut back by as
/// much. Only past the allowance, and only the tail, so that it does not churn: the moves
/// a commit makes here are the holes' worth, and the next commit that needs it is one whose
/// edits left as many new holes again.
pub fn tail_to_move(
    kept: &[PayloadRef],
    page_size: u32,
    end: u64,
    holes: u64,
    largest_hole: u64,
    page: impl Fn(u64) -> TailPage,
) -> Vec<PayloadRef> {
    let p = u64::from(page_size);
    let allowance = end * MAX_HOLES_PERCENT / 100 + GRACE_PAGES;
    if holes <= allowance {
        return Vec::new();
    }
    let budget = (holes - allowance) * p / 2;
    // The kept payloads by the last page they touch.
    let mut by_last: BTreeMap<u64, BTreeSet<(u64, u32, u32)>> = BTreeMap::new();
    for r in kept.iter().filter(|r| r.len > 0) {
        by_last
            .entry((r.end() - 1) / p)
            .or_default()
            .insert((r.offset, r.len, r.crc));
    }
    let mut chosen: BTreeSet<(u64, u32, u32)> = BTreeSet::new();
    let mut bytes = 0u64;
    let mut at = end;
    // Every page past `at` empties: each kept payload touching one ends on it or on a
    // later page, and was taken there.
    while at > 2 {
        at -= 1;
        match page(at) {
            TailPage::Leaves => continue,
            TailPage::Stays => break,
            TailPage::Kept => {}
        }
        let Some(on) = by_last.get(&at) else {
            continue; // the payloads on it end later, and were taken
        };
        let add: u64 = on.iter().map(|&(_, len, _)| u64::from(len)).sum();
        let fits = on
            .iter()
            .all(|&(_, len, _)| u64::from(len) <= largest_hole * p);
        if bytes + add > budget || !fits {
            break;
        }
        bytes += add;
        chosen.extend(on.iter().copied());
    }
    chosen
        .into_iter()
        .map(|(offset, len, crc)| PayloadRef { offset, len, crc })
        .collect()
}

/// The pages `r` touches and its bytes on each.
fn page_parts(r: &PayloadRef, page_size: u32) -> impl Iterator<Item = (u64, u64)> + '_ {
    let p = u64::from(page_size);
    r.pages(page_size).map(move |page| {
        let lo = r.offset.max(page * p);
        let hi = r.end().min((page + 1) * p);
        (page, hi - lo)
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;

    /// The waste of the pages `kept` touches (the rule in the module's docs), in bytes.
    fn waste(kept: &[PayloadRef], page_size: u32) -> u64 {
        Plan::new(kept, page_size).waste
    }

    fn at(offset: u64, len: u32) -> PayloadRef {
        PayloadRef {
            offset,
            len,
            crc: u32::try_from(offset).unwrap_or(u32::MAX),
        }
    }

    #[test]
    fn nothing_moves_within_the_allowance_then_the_emptiest_segment_goes_first() {
        // 100-byte pages, 16 to a segment. Pages 2..=47 full, then pages of 10 bytes each:
        // with ten of them, waste 900 is within 15 % of 4,700 kept bytes plus two pages
        // (905).
        let full: Vec<PayloadRef> = (2..48).map(|pg| at(100 * pg, 100)).collect();
        let sparse = |n: u64| (48..48 + n).map(|pg| at(100 * pg, 10));
        let mut kept: Vec<PayloadRef> = full.iter().copied().chain(sparse(10)).collect();
        assert_eq!(payloads_to_move(&kept, 100, u64::MAX), vec![]);
        // An eleventh: waste 990 > 15 % × 4,710 + 200 = 906. Segment 3 (pages 48..=63)
        // wastes the most per kept byte: it moves, the full segments stay.
        kept = full.iter().copied().chain(sparse(11)).collect();
        let moved = payloads_to_move(&kept, 100, u64::MAX);
        assert_eq!(moved, sparse(11).collect::<Vec<_>>());
        // Duplicates count once; empty payloads never move.
        let mut dup = kept.clone();
        dup.push(at(4800, 10));
        dup.push(at(0, 0));
        assert_eq!(payloads_to_move(&dup, 100, u64::MAX), moved);
    }

    #[test]
    fn a_budget_stops_cleaning_after_the_segment_that_reaches_it() {
        // Two sparse segments past the allowance (pages 48..=63 and 64..=79, 10 bytes
        // each, behind 46 full pages): without a budget both move; with 1 byte, the first
        // segment cleaned (the emptiest, ties by place) and no more.
        let full = (2..48).map(|pg| at(100 * pg, 100));
        let kept: Vec<PayloadRef> = full
            .chain((48..80).map(|pg| at(100 * pg, 10)))
            .collect();
        let all = payloads_to_move(&kept, 100, u64::MAX);
        assert_eq!(all, kept[46..].to_vec());
        let one = payloads_to_move(&kept, 100, 1);
        assert_eq!(one, kept[46..62].to_vec());
    }

    #[test]
    fn a_segment_whose_straddlers_would_thin_more_than_it_wins_stays() {
        // Page 15 (segment 0) is full: 50 bytes of its own and the first half of a payload
        // that ends on page 16 (segment 1), which holds nothing else. Cleaning segment 1
        // would empty page 16 (winning back 50) and thin page 15 by 50: no gain. It comes
        // first (waste 50 per 50 kept bytes, against 768 per 832 for segment 2, whose pages
        // hold 52 bytes each; in all 818 > 15 % × 2,282 + 200), and stays; segment 2 goes.
        let mut kept: Vec<PayloadRef> = (2..15).map(|pg| at(100 * pg, 100)).collect();
        kept.push(at(1500, 50));
        kept.push(at(1550, 100));
        let sparse: Vec<PayloadRef> = (32..48).map(|pg| at(100 * pg, 52)).collect();
        kept.extend(&sparse);
        assert_eq!(payloads_to_move(&kept, 100, u64::MAX), sparse);
    }

    /// Payloads end to end from page 2, of the given lengths; those with `keep` set stay.
    fn survivors(lens: &[(u32, bool)], page: u32) -> Vec<PayloadRef> {
        let mut at_byte = 2 * u64::from(page);
        let mut kept = Vec::new();
        for &(len, keep) in lens {
            if keep {
                kept.push(at(at_byte, len));
            }
            at_byte += u64::from(len);
        }
        kept
    }

    /// Checks what any cleaning must hold: each moved payload was kept and moves once;
    /// nothing moves within the allowance; the waste never grows. Returns what stays.
    fn check(kept: &[PayloadRef], page: u32) -> Result<Vec<PayloadRef>, TestCaseError> {
        let moved = payloads_to_move(kept, page, u64::MAX);
        let moved_set: BTreeSet<_> = moved.iter().map(|r| (r.offset, r.len)).collect();
        prop_assert_eq!(moved_set.len(), moved.len());
        prop_assert!(moved.iter().all(|m| kept.contains(m)));
        let stay: Vec<_> = kept
            .iter()
            .filter(|r| !moved_set.contains(&(r.offset, r.len)))
            .copied()
            .collect();
        let all: u64 = kept.iter().map(|r| u64::from(r.len)).sum();
        let before = all * MAX_WASTE_PERCENT / 100 + GRACE_PAGES * u64::from(page);
        if waste(kept, page) <= before {
            prop_assert!(moved.is_empty());
        }
        prop_assert!(waste(&stay, page) <= waste(kept, page));
        Ok(stay)
    }

    proptest! {
        /// Payloads anywhere, with gaps: the rules of `check`.
        #[test]
        fn cleaning_never_adds_waste(lens in proptest::collection::vec((0u32..300, 0u64..200), 0..60)) {
            let page = 128u32;
            let mut kept = Vec::new();
            let mut at_byte = 2 * u64::from(page);
            for (len, gap) in lens {
                at_byte += gap;
                kept.push(at(at_byte, len));
                at_byte += u64::from(len);
            }
            check(&kept, page)?;
        }

        /// A packed file some of whose payloads were replaced (the case edits make): what
        /// stays wastes at most the allowance.
        #[test]
        fn after_edits_what_stays_is_within_the_allowance(
            lens in proptest::collection::vec((1u32..600, proptest::bool::weighted(0.7)), 0..400)
        ) {
            let page = 128u32;
            let stay = check(&survivors(&lens, page), page)?;
            let held: u64 = stay.iter().map(|r| u64::from(r.len)).sum();
            let limit = held * MAX_WASTE_PERCENT / 100 + GRACE_PAGES * u64::from(page);
            prop_assert!(waste(&stay, page) <= limit, "waste {} over {}", waste(&stay, page), limit);
        }
    }

    /// The page states of a file of `end` pages whose pages in `written` this commit wrote:
    /// pages `kept` touches are kept, the rest leave.
    fn states(
        kept: &[PayloadRef],
        page: u32,
        written: &BTreeSet<u64>,
    ) -> impl Fn(u64) -> TailPage {
        let touched: BTreeSet<u64> = kept.iter().flat_map(|r| r.pages(page)).collect();
        let written = written.clone();
        move |pg| {
            if written.contains(&pg) {
                TailPage::Stays
            } else if touched.contains(&pg) {
                TailPage::Kept
            } else {
                TailPage::Leaves
            }
        }
    }

    #[test]
    fn the_tail_moves_only_past_the_hole_allowance() {
        // 100 pages of 100 bytes, a payload of 100 bytes on each from page 2.
        let kept: Vec<_> = (2..100u64).map(|pg| at(pg * 100, 100)).collect();
        let none = BTreeSet::new();
        // 8 % of 100 pages + 2: up to 10 holes are allowed.
        assert!(tail_to_move(&kept, 100, 100, 10, 10, states(&kept, 100, &none)).is_empty());
        // 30 holes: 20 past the allowance, half of their bytes move: the last 10 pages.
        let moved = tail_to_move(&kept, 100, 100, 30, 10, states(&kept, 100, &none));
        assert_eq!(moved, (90..100u64).map(|pg| at(pg * 100, 100)).collect::<Vec<_>>());
        // A payload longer than every hole stops it.
        let mut long: Vec<_> = kept.iter().filter(|r| !(9500..9700).contains(&r.offset)).copied().collect();
        long.push(at(9500, 200));
        let moved = tail_to_move(&long, 100, 100, 30, 1, states(&long, 100, &none));
        assert_eq!(moved, (97..100u64).map(|pg| at(pg * 100, 100)).collect::<Vec<_>>());
        // A page this commit wrote stops the walk.
        let written: BTreeSet<u64> = [95].into_iter().collect();
        let moved = tail_to_move(&kept, 100, 100, 30, 10, states(&kept, 100, &written));
        assert_eq!(moved, (96..100u64).map(|pg| at(pg * 100, 100)).collect::<Vec<_>>());
    }

    proptest! {
        /// Whatever the layout: what moves was kept, moves once, fits the budget, and
        /// empties a suffix of the file: past the page the walk stopped at, no payload that
        /// stays touches a page, and no page this commit wrote is passed.
        #[test]
        fn the_tail_moved_empties_a_suffix(
            lens in proptest::collection::vec((1u32..600, proptest::bool::weighted(0.7)), 0..300),
            holes in 0u64..200,
            largest in 0u64..8,
            written in proptest::collection::btree_set(2u64..400, 0..4),
        ) {
            let page = 128u32;
            let kept = survivors(&lens, page);
            let end = kept.iter().map(|r| r.end().div_ceil(u64::from(page))).max().unwrap_or(2) + 1;
            let written: BTreeSet<u64> = written.into_iter().filter(|&w| w < end).collect();
            let state = states(&kept, page, &written);
            let moved = tail_to_move(&kept, page, end, holes, largest, &state);
            let set: BTreeSet<_> = moved.iter().map(|r| (r.offset, r.len)).collect();
            prop_assert_eq!(set.len(), moved.len());
            prop_assert!(moved.iter().all(|m| kept.contains(m)));
            let allowance = end * MAX_HOLES_PERCENT / 100 + GRACE_PAGES;
            let budget = holes.saturating_sub(allowance) * u64::from(page) / 2;
            prop_assert!(moved.iter().map(|r| u64::from(r.len)).sum::<u64>() <= budget);
            prop_assert!(moved.iter().all(|r| u64::from(r.len) <= largest * u64::from(page)));
            let last_page = |r: &PayloadRef| (r.end() - 1) / u64::from(page);
            if let Some(t) = moved.iter().map(last_page).min() {
                // Every page from `t` on is left by the payloads that stay: the walk took
                // every payload ending on each page it passed.
                for r in kept.iter().filter(|r| !set.contains(&(r.offset, r.len))) {
                    prop_assert!(last_page(r) < t, "a payload that stays ends on page {} >= {}", last_page(r), t);
                }
                // And it never passed a page this commit wrote.
                for &w in &written {
                    prop_assert!(w < t, "the walk passed page {} that this commit wrote", w);
                }
            }
        }
    }
}

