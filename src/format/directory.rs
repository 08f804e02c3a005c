//! The cluster directory (blob, tag `FMCD`): per cluster, its threshold, its largest error,
//! the root of its index, and where its four edge lists lie in the adjacency table.
//!
//! ```text
//!  0       4        8                    8 + 104·count
//!  | count | rsvd=0 | ClusterRecord × count |
//! ```
//!
//! An [`EdgeRange`]'s `first` and `count` count *records* (4-byte [`super::AdjacencyEntry`]s)
//! of the adjacency table, not bytes. The runs tile the table in cluster order, then edge
//! order north, east, south, west.

use zerocopy::byteorder::little_endian::{F64, U32, U64};
use zerocopy::{FromBytes, IntoBytes};

use super::tree::TreeRef;
use super::{DatasetHeader, Invariant, Violation};
use crate::model::MAX_CLUSTERS;

on_disk! {
    /// The directory's fixed prefix.
    pub struct DirectoryPrefix {
        /// Clusters that follow (equal to the dataset header's `cluster_count`).
        pub count: U32,
        /// Zero.
        pub reserved: U32,
    }
}

on_disk! {
    /// One cluster in the cluster directory.
    pub struct ClusterRecord {
        /// δ.
        pub threshold: F64,
        /// The largest `e*` in the cut.
        pub max_error: F64,
        /// The index: [`super::IndexEntry`]s keyed by Hilbert key.
        pub index: TreeRef,
        /// Where this cluster's north, east, south and west edge lists lie in the adjacency
        /// table.
        pub adjacency: [EdgeRange; 4],
    }
}

on_disk! {
    /// A run of the adjacency table: records `first .. first + count`.
    #[derive(Default, Eq)]
    pub struct EdgeRange {
        /// Ordinal of the first record (a record count, not a byte offset).
        pub first: U64,
        /// Records in the run.
        pub count: U64,
    }
}

/// Bytes of the directory's prefix.
pub const DIRECTORY_PREFIX_LEN: usize = size_of::<DirectoryPrefix>();

const _: () = {
    assert!(DIRECTORY_PREFIX_LEN == 8);
    assert!(size_of::<ClusterRecord>() == 104);
    assert!(size_of::<EdgeRange>() == 16);
};

/// The largest directory a reader accepts.
pub const MAX_DIRECTORY_LEN: u64 =
    (DIRECTORY_PREFIX_LEN + MAX_CLUSTERS * size_of::<ClusterRecord>()) as u64;

/// One cluster as the directory describes it.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ClusterInfo {
    /// δ: every node of the cut has `e* <= δ`.
    pub threshold: f64,
    /// The largest `e*` in the cut.
    pub max_error: f64,
    pub(crate) index: TreeRef,
    pub(crate) adjacency: [EdgeRange; 4],
}

impl ClusterInfo {
    /// A cluster whose cut is indexed by `index` and whose edge lists are the runs
    /// `adjacency` (north, east, south, west) of the adjacency table.
    pub fn new(threshold: f64, max_error: f64, index: TreeRef, adjacency: [EdgeRange; 4]) -> Self {
        ClusterInfo {
            threshold,
            max_error,
            index,
            adjacency,
        }
    }

    /// Nodes in the cut.
    pub fn nodes(&self) -> u64 {
        self.index.records.get()
    }

    /// Page levels of its index.
    pub fn index_depth(&self) -> u16 {
        self.index.depth.get()
    }

    /// The root of its index.
    pub(crate) fn index(&self) -> &TreeRef {
        &self.index
    }

    /// Nodes in its edge list along `edge` (0 north, 1 east, 2 south, 3 west).
    pub fn edge_nodes(&self, edge: usize) -> Option<u64> {
        self.adjacency.get(edge).map(|r| r.count.get())
    }
}

/// The directory blob of `clusters`.
pub fn encode(clusters: &[ClusterInfo]) -> Vec<u8> {
    let prefix = DirectoryPrefix {
        count: U32::new(u32::try_from(clusters.len()).unwrap_or(u32::MAX)),
        reserved: U32::new(0),
    };
    let mut out =
        Vec::with_capacity(DIRECTORY_PREFIX_LEN + clusters.len() * size_of::<ClusterRecord>());
    out.extend_from_slice(prefix.as_bytes());
    for c in clusters {
        let record = ClusterRecord {
            threshold: F64::new(c.threshold),
            max_error: F64::new(c.max_error),
            index: c.index,
            adjacency: c.adjacency,
        };
        out.extend_from_slice(record.as_bytes());
    }
    out
}

/// Parses and checks a directory blob (I-12) against the dataset header and the adjacency
/// table's record count.
pub fn decode(
    bytes: &[u8],
    header: &DatasetHeader,
    adjacency_records: u64,
) -> Result<Vec<ClusterInfo>, Violation> {
    let bad = |d: String| Violation::new(Invariant::ClusterDirectory, "cluster directory", d);
    let (prefix, body) =
        DirectoryPrefix::read_from_prefix(bytes).map_err(|_| bad("too short".into()))?;
    if prefix.reserved.get() != 0 {
        return Err(bad("reserved field is not zero".into()));
    }
    let count = prefix.count.get();
    if count != header.cluster_count {
        return Err(bad(format!(
            "{count} clusters; the dataset header says {}",
            header.cluster_count
        )));
    }
    let records = <[ClusterRecord]>::ref_from_bytes(body)
        .ok()
        .filter(|r| r.len() as u64 == u64::from(count))
        .ok_or_else(|| bad(format!("{} bytes for {count} clusters", bytes.len())))?;
    let mut out: Vec<ClusterInfo> = Vec::with_capacity(records.len());
    let mut next_edge = 0u64;
    for (i, r) in records.iter().enumerate() {
        let (t, m) = (r.threshold.get(), r.max_error.get());
        if !(t.is_finite() && t >= 0.0 && m.is_finite() && (0.0..=t).contains(&m)) {
            return Err(bad(format!("cluster {i}: threshold {t}, max error {m}")));
        }
        match out.last() {
            Some(prev) if t <= prev.threshold => {
                return Err(bad(format!(
                    "cluster {i}: threshold {t} after {}",
                    prev.threshold
                )));
            }
            None if t != header.delta_min => {
                return Err(bad(format!(
                    "the lowest threshold {t} is not delta_min {}",
                    header.delta_min
                )));
            }
            _ => {}
        }
        for (e, range) in r.adjacency.iter().enumerate() {
            if range.first.get() != next_edge || range.count.get() == 0 {
                return Err(bad(format!(
                    "cluster {i} edge {e}: adjacency run {}+{}, expected to start at record \
                     {next_edge} and hold a node",
                    range.first.get(),
                    range.count.get()
                )));
            }
            next_edge = next_edge.saturating_add(range.count.get());
        }
        out.push(ClusterInfo::new(t, m, r.index, r.adjacency));
    }
    if next_edge != adjacency_records {
        return Err(bad(format!(
            "the edge lists hold {next_edge} records, the adjacency table {adjacency_records}"
        )));
    }
    if out.iter().any(|c| c.nodes() == 0) {
        return Err(Violation::new(
            Invariant::ClusterIndex,
            "cluster directory",
            "a cluster with no nodes",
        ));
    }
    Ok(out)
}
