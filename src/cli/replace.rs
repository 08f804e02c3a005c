//! `fmrh replace`: put new full-resolution samples into a container, atomically, through one
//! write transaction (`format-spec/container.md` §11). Either every sample of the patch is
//! stored, with every affected block, node error, cluster cut and table brought up to date,
//! or the file keeps its previous state; a crash at any instant leaves one or the other.

use std::path::PathBuf;
use std::process::ExitCode;
use std::time::Instant;

use serde::Serialize;

use crate::ingest;
use crate::store::{CommitSummary, Container, Recovery};
use crate::Error;

#[derive(clap::Args)]
pub struct ReplaceArgs {
    /// The container to change, or a dataset's directory (COL,ROW are then dataset samples,
    /// and every tile the patch meets changes in one atomic dataset commit).
    file: PathBuf,
    /// Where the patch's north-west sample goes: COL,ROW of the full-resolution data.
    #[arg(long)]
    at: String,
    /// The new samples (any format `fmrh build` reads); voids become voids.
    patch: PathBuf,
    /// Print the report as JSON.
    #[arg(long)]
    pub json: bool,
    #[command(flatten)]
    ingest: super::args::IngestArgs,
}

#[derive(Serialize)]
struct ReplaceReport {
    file: String,
    patch: String,
    at: [u64; 2],
    width: u32,
    height: u32,
    /// What opening the file had to recover first (from an earlier interrupted writer).
    recovery: Recovery,
    #[serde(flatten)]
    summary: CommitSummary,
    /// The txn id after the clean close, which records the committed state again without the
    /// recovery mark: the file's txn id from then on (what `fmrh info` shows).
    closed_txn: u64,
    /// From the start of the transaction to the durable commit: reading the model, measuring
    /// the changed bands, writing, and both syncs.
    commit_time_ms: f64,
}

/// Parses `COL,ROW`.
fn parse_at(text: &str) -> Result<[u64; 2], Error> {
    let parts: Option<Vec<u64>> = text.split(',').map(|p| p.trim().parse().ok()).collect();
    match parts {
        Some(v) if v.len() == 2 => Ok([v[0], v[1]]),
        _ => Err(Error::InvalidArgument(format!(
            "--at `{text}`: expected two non-negative integers COL,ROW"
        ))),
    }
}

/// Runs `fmrh replace`.
pub fn run(args: &ReplaceArgs) -> Result<ExitCode, Error> {
    let [col0, row0] = parse_at(&args.at)?;
    let patch = ingest::load(&args.patch, &args.ingest.options())?;
    // A patch whose file says what its heights are above must say what the terrain's are
    // above: EGM96 heights written over ellipsoidal ones would be tens of metres off. A
    // patch that says nothing (a raw grid) is taken as the terrain's.
    let theirs = patch.metadata.vertical_datum;
    if theirs != crate::geoid::VerticalDatum::Unknown {
        let ours = crate::terrain::Terrain::open(&args.file)?
            .info()?
            .vertical_datum;
        if ours != theirs {
            return Err(Error::input(
                &args.patch,
                format!(
                    "its heights are above {}, {}'s above {} (--vertical-datum says what \
                     the patch's are)",
                    theirs.name(),
                    args.file.display(),
                    ours.name()
                ),
            ));
        }
    }
    if super::is_dataset(&args.file)? {
        let started = Instant::now();
        let r =
            crate::dataset::replace(&crate::dataset::Dir(args.file.clone()), col0, row0, &patch)?;
        let ms = started.elapsed().as_secs_f64() * 1e3;
        if args.json {
            #[derive(Serialize)]
            struct Report<'a> {
                dataset: String,
                patch: String,
                at: [u64; 2],
                width: u32,
                height: u32,
                #[serde(flatten)]
                commit: &'a crate::dataset::DatasetCommit,
                commit_time_ms: f64,
            }
            super::print_json(&Report {
                dataset: args.file.display().to_string(),
                patch: args.patch.display().to_string(),
                at: [col0, row0],
                width: patch.width(),
                height: patch.height(),
                commit: &r,
                commit_time_ms: ms,
            })?;
        } else {
            println!(
                "replaced {} x {} samples at dataset column {col0}, row {row0} of {}: {} tiles, \
                 one manifest commit (txn {}) in {ms:.2} ms",
                patch.width(),
                patch.height(),
                args.file.display(),
                r.tiles.len(),
                r.txn_id
            );
            for t in &r.tiles {
                println!(
                    "  tile {:>5} {:<28} txn {}: {} blocks, {} grids rewritten{}",
                    t.index,
                    t.name,
                    t.summary.txn_id,
                    t.summary.blocks,
                    t.summary.grids,
                    if t.republished {
                        " (its pinned state republished first)"
                    } else {
                        ""
                    }
                );
            }
        }
        return Ok(ExitCode::SUCCESS);
    }
    let (container, recovery) = Container::open_recovering(&args.file)?;
    let units = container.read()?.header().metadata.units.clone();
    if let (Some(file), Some(patch_units)) = (&units, &patch.metadata.units) {
        if file != patch_units {
            return Err(Error::InvalidArgument(format!(
                "the patch is in {patch_units} but the container stores {file}"
            )));
        }
    }
    let started = Instant::now();
    let mut txn = container.begin_write()?;
    txn.replace_region(col0, row0, &patch)?;
    let summary = txn.commit()?;
    let commit_time_ms = started.elapsed().as_secs_f64() * 1e3;
    let closed_txn = container.close()?;
    let report = ReplaceReport {
        file: args.file.display().to_string(),
        patch: args.patch.display().to_string(),
        at: [col0, row0],
        width: patch.width(),
        height: patch.height(),
        recovery,
        summary,
        closed_txn,
        commit_time_ms,
    };
    if args.json {
        super::print_json(&report)?;
    } else {
        print_text(&report);
    }
    Ok(ExitCode::SUCCESS)
}

fn print_text(r: &ReplaceReport) {
    let s = &r.summary;
    if r.recovery.marked || r.recovery.truncated > 0 || r.recovery.slot_cleared {
        println!(
            "recovered first: an earlier writer stopped mid-transaction ({} bytes cut, torn slot \
             cleared: {})",
            r.recovery.truncated, r.recovery.slot_cleared
        );
    }
    println!(
        "replaced {} x {} samples at column {}, row {} of {}",
        r.width, r.height, r.at[0], r.at[1], r.file
    );
    // One number for one commit: the txn the file holds after the clean close (what
    // `fmrh info` shows); the JSON report keeps both.
    println!(
        "committed as txn {} in {:.2} ms (reading and measuring the model included)",
        r.closed_txn, r.commit_time_ms
    );
    println!("  blocks rewritten   {}", s.blocks);
    println!("  grids rewritten    {}", s.grids);
    println!(
        "  nodes              {} -> {} ({} added, {} removed, {} with new errors or heights)",
        s.nodes_before, s.nodes_after, s.nodes_added, s.nodes_removed, s.nodes_changed
    );
    let clusters: Vec<String> = s.clusters_changed.iter().map(|c| c.to_string()).collect();
    println!(
        "  clusters changed   {}",
        if clusters.is_empty() {
            "none".to_string()
        } else {
            clusters.join(", ")
        }
    );
    println!(
        "  pages              {} written ({} reused), {} freed",
        s.pages_written, s.pages_reused, s.pages_freed
    );
    if s.payloads_moved > 0 {
        println!(
            "  moved              {} payloads ({} bytes) off sparse pages",
            s.payloads_moved, s.bytes_moved
        );
    }
    println!("  file length        {} bytes", s.file_length);
}
