//! The list of a state's tables: every B+-tree a commit record reaches, with its spec.
//!
//! Opening walks this list to check every table page, `fmrh info` counts its pages, and a
//! commit frees them. A new table is one more [`TreeSpec`] here and one more entry in
//! [`state_trees`] (plus its record in [`super::records`] and its section in the spec).

use super::commit::StateRoots;
use super::directory::ClusterInfo;
use super::page::tag;
use super::records::{AdjacencyEntry, BlockRecord, FreeEntry, IndexEntry, NodeRecord};
use super::tree::{TreeRef, TreeSpec};

/// The node table: [`NodeRecord`]s in Hilbert pre-order, keyed by ordinal.
pub const NODES: TreeSpec = TreeSpec {
    tag: tag::NODE_TABLE,
    record_size: size_of::<NodeRecord>(),
    keyed: false,
    name: "node table",
};

/// The block table: [`BlockRecord`]s row-major, keyed by ordinal.
pub const BLOCKS: TreeSpec = TreeSpec {
    tag: tag::BLOCK_TABLE,
    record_size: size_of::<BlockRecord>(),
    keyed: false,
    name: "block table",
};

/// The free list: [`FreeEntry`]s keyed by page.
pub const FREE: TreeSpec = TreeSpec {
    tag: tag::FREE_LIST,
    record_size: size_of::<FreeEntry>(),
    keyed: true,
    name: "free list",
};

/// A cluster index: [`IndexEntry`]s keyed by Hilbert key.
pub const INDEX: TreeSpec = TreeSpec {
    tag: tag::CLUSTER_INDEX,
    record_size: size_of::<IndexEntry>(),
    keyed: true,
    name: "cluster index",
};

/// The adjacency table: [`AdjacencyEntry`]s keyed by ordinal.
pub const ADJACENCY: TreeSpec = TreeSpec {
    tag: tag::ADJACENCY,
    record_size: size_of::<AdjacencyEntry>(),
    keyed: false,
    name: "adjacency list",
};

/// Every tree of a state, in the order opening checks them: the node table, the block table,
/// the free list, each cluster's index, the adjacency table.
pub fn state_trees(roots: &StateRoots, clusters: &[ClusterInfo]) -> Vec<(TreeSpec, TreeRef)> {
    let mut trees = vec![
        (NODES, roots.node_table),
        (BLOCKS, roots.block_table),
        (FREE, roots.free_list),
    ];
    trees.extend(clusters.iter().map(|c| (INDEX, *c.index())));
    trees.push((ADJACENCY, roots.adjacency));
    trees
}
