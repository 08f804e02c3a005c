//! `fmrh compact`: a container's current state rewritten as a fresh build of it would be
//! (`crate::store::compact`), or every tile of a dataset's (`crate::dataset::compact`, one
//! manifest commit): the pages edits left behind are gone, every sample and every scene's
//! answer stays.

use std::path::PathBuf;
use std::process::ExitCode;

use crate::store::{compact, CompactOptions};
use crate::Error;

#[derive(clap::Args)]
pub struct CompactArgs {
    /// The container, or a dataset's directory (every tile is rewritten, then published by
    /// one manifest commit).
    file: PathBuf,
    /// Code every payload alone, as `build --payloads-alone` (by default, against the parent's
    /// grid where that is smaller, as a default build).
    #[arg(long)]
    payloads_alone: bool,
    /// Print the report as JSON.
    #[arg(long)]
    pub json: bool,
}

/// Runs `fmrh compact`.
pub fn run(args: &CompactArgs) -> Result<ExitCode, Error> {
    if super::is_dataset(&args.file)? {
        return compact_dataset(args);
    }
    let done = compact(
        &args.file,
        &CompactOptions {
            payloads_alone: args.payloads_alone,
        },
    )?;
    if args.json {
        super::print_json(&done)?;
    } else {
        println!(
            "{}: compacted txn {}: {} bytes -> {} bytes ({:.2}x; {} free pages dropped)",
            args.file.display(),
            done.txn_before,
            done.bytes_before,
            done.bytes_after,
            done.bytes_after as f64 / done.bytes_before.max(1) as f64,
            done.free_pages_before
        );
    }
    Ok(ExitCode::SUCCESS)
}

fn compact_dataset(args: &CompactArgs) -> Result<ExitCode, Error> {
    let options = CompactOptions {
        payloads_alone: args.payloads_alone,
    };
    let done = crate::dataset::compact(&args.file, &options, &mut |_, _, _| {})?;
    if args.json {
        super::print_json(&done)?;
    } else {
        println!(
            "{}: compacted {} tiles as txn {}: {} bytes -> {} bytes ({:.2}x)",
            args.file.display(),
            done.tiles.len(),
            done.txn_id,
            done.bytes_before,
            done.bytes_after,
            done.bytes_after as f64 / done.bytes_before.max(1) as f64,
        );
        for t in &done.tiles {
            println!(
                "  {:<28} {:>10} -> {:>10} bytes  {}",
                t.name_before, t.bytes_before, t.bytes_after, t.name_after
            );
        }
    }
    Ok(ExitCode::SUCCESS)
}
