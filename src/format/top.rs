//! The top of the tree (6.2, blob, tag `FMTP`): a copy of the node records of the tree's
//! coarsest levels, so that a reader holds every node a coarse scene starts from after
//! opening, without reading a page of the node table.
//!
//! Why a copy: the node table is in Hilbert pre-order, so the few nodes of the top levels
//! lie one or two in each of its pages (Puget Sound 4k: the 85 nodes of levels 0 to 3 on
//! 64 of its 111 leaves). A remote reader that needs them pays a round trip per tree level,
//! or fetches the whole table. With the top, a scene's first round after opening fetches
//! only the subtrees below it that the view refines into (each a contiguous run of the
//! table), and a scene whose cut lies in the top fetches no node page at all.
//!
//! ```text
//!  0       4        5        8                 8 + 84·count
//!  | count | levels | rsvd=0 | TopEntry × count |
//!  TopEntry: | ordinal: u32 | node record (80 bytes, §6.1) |
//! ```
//!
//! The entries are every node of the table whose level is below `levels`, ascending by
//! ordinal, each record byte for byte the table's (I-10).

use zerocopy::byteorder::little_endian::U32;
use zerocopy::{FromBytes, IntoBytes};

use super::records::{NodeRecord, StoredNode};
use super::{Invariant, Violation};

on_disk! {
    /// The top's fixed prefix.
    pub struct TopPrefix {
        /// Entries that follow.
        pub count: U32,
        /// The top holds every node of level below this (1 ..= 64).
        pub levels: u8,
        /// Zero.
        pub reserved: [u8; 3],
    }
}

on_disk! {
    /// One node of the top: its ordinal in the node table, and its record.
    pub struct TopEntry {
        /// Ordinal in the node table.
        pub ordinal: U32,
        /// The node table's record at that ordinal.
        pub record: NodeRecord,
    }
}

/// Bytes of the prefix.
pub const TOP_PREFIX_LEN: usize = size_of::<TopPrefix>();
/// Bytes of an entry.
pub const TOP_ENTRY_LEN: usize = size_of::<TopEntry>();

const _: () = {
    assert!(TOP_PREFIX_LEN == 8);
    assert!(TOP_ENTRY_LEN == 84);
};

/// The levels a writer puts in the top: 0 to 3, at most 85 nodes (7 KB), so that the top
/// fits in the suffix a remote reader fetches at open beside the header, the directory
/// and the tables' roots, and each subtree below it is at most 4^(L-3) blocks deep.
pub const TOP_LEVELS: u8 = 4;

/// Most entries a top may hold: every node of levels 0 to 7 (the blob is then at most
/// 1.8 MB). A longer one is refused before it is read.
pub const MAX_TOP_ENTRIES: u32 = 21_845;

/// Longest top blob, in bytes.
pub const MAX_TOP_LEN: u64 = TOP_PREFIX_LEN as u64 + MAX_TOP_ENTRIES as u64 * TOP_ENTRY_LEN as u64;

/// The top: the nodes of the coarsest levels, by ordinal.
#[derive(Clone, Debug, PartialEq)]
pub struct Top {
    /// Every node of level below this is here.
    pub levels: u8,
    /// `(ordinal, node)`, ascending by ordinal.
    pub nodes: Vec<(u32, StoredNode)>,
    /// The records as stored, in the same order (what a validator compares with the
    /// table's, byte for byte).
    pub records: Vec<NodeRecord>,
}

impl Top {
    /// The node at `ordinal`, if the top holds it.
    #[inline]
    pub fn get(&self, ordinal: u32) -> Option<&StoredNode> {
        self.nodes
            .binary_search_by_key(&ordinal, |&(o, _)| o)
            .ok()
            .map(|i| &self.nodes[i].1)
    }

    /// Whether the top holds every node of `level`.
    pub fn holds_level(&self, level: u8) -> bool {
        level < self.levels
    }
}

/// The top's bytes: `levels`, then each `(ordinal, record)` in ascending ordinal order.
pub fn encode<'a>(levels: u8, entries: impl IntoIterator<Item = (u32, &'a NodeRecord)>) -> Vec<u8> {
    let mut body = Vec::new();
    let mut count = 0u32;
    for (ordinal, record) in entries {
        let e = TopEntry {
            ordinal: U32::new(ordinal),
            record: *record,
        };
        body.extend_from_slice(e.as_bytes());
        count += 1;
    }
    let prefix = TopPrefix {
        count: U32::new(count),
        levels,
        reserved: [0; 3],
    };
    let mut out = prefix.as_bytes().to_vec();
    out.extend_from_slice(&body);
    out
}

/// Decodes and checks a top (I-10 for what can be told without the table: shape, order,
/// levels; the validator compares each record with the table's).
pub fn decode(bytes: &[u8]) -> Result<Top, Violation> {
    let bad = |detail: String| Violation::new(Invariant::NodeTable, "top", detail);
    let (prefix, rest) = TopPrefix::read_from_prefix(bytes)
        .map_err(|_| bad(format!("{} bytes, shorter than its prefix", bytes.len())))?;
    let count = prefix.count.get();
    if count > MAX_TOP_ENTRIES {
        return Err(bad(format!("{count} entries, more than {MAX_TOP_ENTRIES}")));
    }
    if rest.len() != count as usize * TOP_ENTRY_LEN {
        return Err(bad(format!(
            "{} bytes after the prefix, expected {count} entries of {TOP_ENTRY_LEN}",
            rest.len()
        )));
    }
    if prefix.reserved != [0; 3] {
        return Err(bad("reserved bytes are not zero".into()));
    }
    if prefix.levels == 0 || count == 0 {
        return Err(bad(format!(
            "{count} entries of levels below {}: a top holds at least the root",
            prefix.levels
        )));
    }
    let mut nodes = Vec::with_capacity(count as usize);
    let mut records = Vec::with_capacity(count as usize);
    for chunk in rest.chunks_exact(TOP_ENTRY_LEN) {
        let e = TopEntry::read_from_bytes(chunk)
            .map_err(|_| bad("an entry is not 84 bytes".into()))?;
        let (ordinal, node) = (e.ordinal.get(), e.record.decode());
        if nodes.last().is_some_and(|&(o, _)| o >= ordinal) {
            return Err(bad(format!("ordinal {ordinal} is not after the one before")));
        }
        if node.level >= prefix.levels {
            return Err(bad(format!(
                "node {ordinal} is at level {}, not below {}",
                node.level, prefix.levels
            )));
        }
        nodes.push((ordinal, node));
        records.push(e.record);
    }
    if nodes[0].0 != 0 || nodes[0].1.level != 0 {
        return Err(bad("the first entry is not the root, node 0".into()));
    }
    Ok(Top {
        levels: prefix.levels,
        nodes,
        records,
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use zerocopy::FromZeros;

    fn record(level: u8) -> NodeRecord {
        let mut r = NodeRecord::new_zeroed();
        r.level = level;
        r
    }

    #[test]
    fn a_top_round_trips_and_bad_ones_are_refused() {
        let (root, child) = (record(0), record(1));
        let bytes = encode(2, [(0, &root), (1, &child)]);
        assert_eq!(bytes.len(), TOP_PREFIX_LEN + 2 * TOP_ENTRY_LEN);
        let top = decode(&bytes).unwrap();
        assert_eq!(top.levels, 2);
        assert_eq!(top.get(1).map(|n| n.level), Some(1));
        assert!(top.get(2).is_none());
        // Out of order, a level too deep, no root, a cut blob, reserved bytes.
        assert!(decode(&encode(2, [(1, &child), (0, &root)])).is_err());
        assert!(decode(&encode(1, [(0, &root), (1, &child)])).is_err());
        assert!(decode(&encode(2, [(1, &child)])).is_err());
        assert!(decode(&bytes[..bytes.len() - 1]).is_err());
        let mut reserved = bytes.clone();
        reserved[5] = 1;
        assert!(decode(&reserved).is_err());
        assert!(decode(&encode(0, [])).is_err());
    }

    proptest::proptest! {
        /// Any bytes decode to a top or to an I-10 violation, never a panic; a top that
        /// decodes holds the root first and ordinals ascending.
        #[test]
        fn any_bytes_decode_or_are_refused(
            mut bytes in proptest::collection::vec(proptest::prelude::any::<u8>(), 0..600),
            count in 0u32..8,
        ) {
            if bytes.len() >= 4 {
                // A count that matches the length half of the time, so entries get read.
                let fit = u32::try_from(bytes.len().saturating_sub(TOP_PREFIX_LEN) / TOP_ENTRY_LEN).unwrap_or(0);
                let c = if count % 2 == 0 { fit } else { count };
                bytes[..4].copy_from_slice(&c.to_le_bytes());
            }
            if let Ok(top) = decode(&bytes) {
                proptest::prop_assert_eq!(top.nodes[0].0, 0);
                proptest::prop_assert!(top.nodes.windows(2).all(|w| w[0].0 < w[1].0));
                proptest::prop_assert_eq!(top.nodes.len(), top.records.len());
            }
        }
    }
}
