//! `fmrh scan`: one cluster's range scan, by Hilbert keys or by ordinal codes.

use std::path::PathBuf;
use std::process::ExitCode;

use serde::Serialize;

use crate::Error;

#[derive(clap::Args)]
#[command(group(clap::ArgGroup::new("range").required(true).args(["hilbert", "codes"])))]
pub struct ScanArgs {
    /// The container.
    file: PathBuf,
    /// The cluster, by position (0 is the finest threshold; see `fmrh info`).
    #[arg(long)]
    cluster: usize,
    /// Hilbert keys of finest-level blocks: `LO..HI` (HI excluded) or `LO..=HI`. Yields the
    /// nodes whose footprint meets the range.
    #[arg(long)]
    hilbert: Option<String>,
    /// Ordinal positions in the cluster (the paper's codes): `A..B` (B excluded) or `A..=B`.
    #[arg(long)]
    codes: Option<String>,
    /// Print JSON.
    #[arg(long)]
    pub json: bool,
}

#[derive(Serialize)]
struct Entry {
    node: u32,
    key: u64,
    level: u8,
    x: u32,
    y: u32,
    col0: u64,
    row0: u64,
    col1: u64,
    row1: u64,
    error: f64,
    monotone_error: f64,
}

#[derive(Serialize)]
struct ScanReport {
    cluster: usize,
    threshold: f64,
    entries: Vec<Entry>,
}

/// Runs `fmrh scan`.
pub fn run(args: &ScanArgs) -> Result<ExitCode, Error> {
    let store = super::open(&args.file)?;
    let info = *store.clusters().get(args.cluster).ok_or_else(|| {
        Error::InvalidArgument(format!(
            "cluster {}: the container has {} clusters",
            args.cluster,
            store.clusters().len()
        ))
    })?;
    let found: Vec<_> = match (&args.hilbert, &args.codes) {
        (Some(h), _) => {
            let (lo, hi) = super::args::parse_range(h, "--hilbert")?;
            store.scan_hilbert(args.cluster, lo..=hi)?.collect()
        }
        (None, Some(c)) => {
            let (a, b) = super::args::parse_range(c, "--codes")?;
            store
                .scan_codes(args.cluster, a..b.saturating_add(1))?
                .collect()
        }
        (None, None) => unreachable!("clap requires --hilbert or --codes"),
    };
    let d = *store.domain();
    let mut entries = Vec::with_capacity(found.len());
    for e in found {
        let e = e?;
        let n = store.node_of(args.cluster, &e)?;
        let fp = d.footprint(n.level, n.x, n.y);
        entries.push(Entry {
            node: e.node,
            key: e.key.0,
            level: e.level,
            x: n.x,
            y: n.y,
            col0: fp.col0,
            row0: fp.row0,
            col1: fp.col1,
            row1: fp.row1,
            error: n.static_error,
            monotone_error: n.monotone_error,
        });
    }
    let report = ScanReport {
        cluster: args.cluster,
        threshold: info.threshold,
        entries,
    };
    if args.json {
        super::print_json(&report)?;
    } else {
        println!(
            "cluster {} (threshold {}): {} nodes",
            report.cluster,
            report.threshold,
            report.entries.len()
        );
        println!(
            "        node          key  level      x      y   samples (c0,r0 .. c1,r1)        e*"
        );
        for e in &report.entries {
            println!(
                "  {:>10} {:>12} {:>6} {:>6} {:>6}   {},{} .. {},{}  {:>12.6}",
                e.node, e.key, e.level, e.x, e.y, e.col0, e.row0, e.col1, e.row1, e.monotone_error
            );
        }
    }
    Ok(ExitCode::SUCCESS)
}
