//! Reading ahead: a reader that knows which lookups it is about to make names them in an
//! [`Ahead`], and the store fetches the pages those lookups will read together, level by
//! level, before they are made (issue 17).
//!
//! On a local file this is never planned ([`Store::prefetches`] is false: a page read is a
//! memory access). On a remote object each page a lookup reaches first costs a round trip,
//! and a scene's lookups (a range scan of a cluster index, then the node of every entry,
//! then the children of those it refines) would cost one round per page in turn. Named
//! together, they cost one round per tree level: the roots of every tree named, then the
//! pages below them that the named keys and ordinals reach, down to the leaves.
//!
//! Reading ahead changes no answer: the lookups that follow read and check their pages as
//! always, and one that reaches a page not fetched ahead reads it then.

use super::btree::{self, Span};
use super::source::Source;
use super::Store;
use crate::error::Result;
use crate::format::{tables, StoredNode, TreeRef, TreeSpec};

/// Lookups about to be made, to fetch ahead together ([`Store::fetch_ahead`]).
#[derive(Clone, Debug, Default)]
pub struct Ahead {
    /// Per cluster, the key spans of its index that range scans will read.
    index: Vec<(usize, Vec<Span>)>,
    /// Ordinal spans of the node table that node lookups will read.
    nodes: Vec<Span>,
    /// Physical blocks (column, row) whose block table records lookups will read.
    blocks: Vec<(u32, u32)>,
}

impl Ahead {
    /// Nothing named yet.
    pub fn new() -> Ahead {
        Ahead::default()
    }

    /// A range scan of `cluster`'s index over the keys `lo ..= hi`
    /// ([`Store::scan_hilbert`]).
    pub fn scan(&mut self, cluster: usize, lo: u64, hi: u64) -> &mut Ahead {
        let span = Span::Keys(lo, hi.max(lo));
        match self.index.iter_mut().find(|(c, _)| *c == cluster) {
            Some((_, spans)) => spans.push(span),
            None => self.index.push((cluster, vec![span])),
        }
        self
    }

    /// Lookups of the nodes `first ..= last` ([`Store::node`]).
    pub fn nodes(&mut self, first: u32, last: u32) -> &mut Ahead {
        self.nodes
            .push(Span::Ordinals(u64::from(first), u64::from(last.max(first))));
        self
    }

    /// Lookups of the ancestors of `node` (node `index`, in a tree whose finest level is
    /// `finest`) above its parent, which is named exactly (`node.parent`): where they lie
    /// if every subtree above is complete. In the node table's pre-order a child `k`
    /// (in curve order, the `k`-th base-4 digit of its Hilbert key) lies after its parent
    /// and the `k` complete subtrees before it, so the parent of a node at level `l`
    /// lies `1 + k * S(l)` before it, `S(l) = (4^(finest - l + 1) - 1) / 3`. Where the tree
    /// is not complete (a domain not a power of two a side, pruned subtrees) a guess misses
    /// and its lookup reads the page when it is made.
    pub fn ancestors(&mut self, node: &StoredNode, finest: u8) -> &mut Ahead {
        self.ancestors_below(node, finest, 0)
    }

    /// [`Ahead::ancestors`] at levels `held` and finer only: the reader holds every node of
    /// the levels above (the top of the tree, format 6.2). A guess there would be pointless
    /// where it hits and, where it misses, would name a node below the top whose pages the
    /// load never reads.
    pub fn ancestors_below(&mut self, node: &StoredNode, finest: u8, held: u8) -> &mut Ahead {
        let Some(mut at) = node.parent else {
            return self;
        };
        // The parent is at the level above the node; walk up from it.
        let mut level = node.level.saturating_sub(1);
        if level < held {
            return self;
        }
        self.nodes(at, at);
        let key = node.key.0;
        while level > held {
            let shift = 2 * u32::from(finest - level.min(finest));
            let digit = key.checked_shr(shift).map_or(0, |k| k & 3);
            let Some(subtree) = complete_subtree(finest, level) else {
                break;
            };
            let Some(back) = digit.checked_mul(subtree).and_then(|b| b.checked_add(1)) else {
                break;
            };
            let Some(up) = u64::from(at)
                .checked_sub(back)
                .and_then(|u| u32::try_from(u).ok())
            else {
                break;
            };
            self.nodes(up, up);
            at = up;
            level -= 1;
        }
        self
    }

    /// A lookup of physical block `(x, y)`'s record ([`Store::stored_block`]).
    pub fn block(&mut self, x: u32, y: u32) -> &mut Ahead {
        self.blocks.push((x, y));
        self
    }

    /// Whether nothing is named.
    pub fn is_empty(&self) -> bool {
        self.index.is_empty() && self.nodes.is_empty() && self.blocks.is_empty()
    }
}

impl<S: Source> Store<S> {
    /// Whether reading ahead is worth planning: the source fetches ahead
    /// ([`Source::prefetches`], a remote object). A caller skips naming its lookups ahead
    /// when not.
    pub fn prefetches(&self) -> bool {
        self.src.prefetches()
    }

    /// The top of the tree (format 6.2), when the state has one and the store holds it:
    /// the nodes of its coarsest levels, read at open by a store whose source fetches ahead
    /// (a remote object) and by the validator. A local reader reads them from the table.
    pub fn top(&self) -> Option<&crate::format::top::Top> {
        self.top.as_deref()
    }

    /// Fetches the pages the lookups `ahead` names will read, one round per tree level on a
    /// remote source, so that the lookups then find them at hand. Nothing on a source that
    /// does not fetch ahead. A cluster that does not exist is left out (its scan reports
    /// it).
    pub fn fetch_ahead(&self, ahead: &Ahead) -> Result<()> {
        if ahead.is_empty() || !self.prefetches() {
            return Ok(());
        }
        let mut wants: Vec<(TreeRef, TreeSpec, Vec<Span>)> = ahead
            .index
            .iter()
            .filter_map(|(c, spans)| {
                let info = self.clusters().get(*c)?;
                Some((*info.index(), tables::INDEX, spans.clone()))
            })
            .collect();
        // A node the top holds (format 6.2) is never looked up in the table.
        let nodes: Vec<Span> = ahead
            .nodes
            .iter()
            .filter(|s| match (**s, self.top.as_deref()) {
                (Span::Ordinals(a, b), Some(top)) if a == b => {
                    u32::try_from(a).map_or(true, |a| top.get(a).is_none())
                }
                _ => true,
            })
            .copied()
            .collect();
        if !nodes.is_empty() {
            wants.push((
                self.commit.roots.node_table,
                tables::NODES,
                merged(&nodes),
            ));
        }
        // A block outside the domain is left out: its lookup reports it.
        let blocks: Vec<Span> = ahead
            .blocks
            .iter()
            .filter_map(|&(x, y)| self.block_ordinal(x, y).ok())
            .map(|o| Span::Ordinals(o, o))
            .collect();
        if !blocks.is_empty() {
            wants.push((
                self.commit.roots.block_table,
                tables::BLOCKS,
                merged(&blocks),
            ));
        }
        btree::prefetch(&self.pages(), &wants)
    }
}

/// Nodes in a complete subtree under a node at `level` of a tree whose finest level is
/// `finest`: `(4^(finest - level + 1) - 1) / 3`, `None` past a `u64`.
fn complete_subtree(finest: u8, level: u8) -> Option<u64> {
    let below = u32::from(finest.checked_sub(level)?) + 1;
    Some(4u64.checked_pow(below)? / 3)
}

/// `spans` sorted and with overlapping or touching ones joined (fewer to clip per page).
fn merged(spans: &[Span]) -> Vec<Span> {
    let mut sorted: Vec<(u64, u64)> = spans
        .iter()
        .map(|s| match *s {
            Span::Keys(a, b) | Span::Ordinals(a, b) => (a, b),
        })
        .collect();
    sorted.sort_unstable();
    let mut out: Vec<(u64, u64)> = Vec::with_capacity(sorted.len());
    for (a, b) in sorted {
        match out.last_mut() {
            Some(last) if a <= last.1.saturating_add(1) => last.1 = last.1.max(b),
            _ => out.push((a, b)),
        }
    }
    out.into_iter().map(|(a, b)| Span::Ordinals(a, b)).collect()
}
