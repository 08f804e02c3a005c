//! `fmrh compact`: a container's current state rewritten as a fresh build of it would be
//! (`crate::store::compact`): the pages edits left behind are gone, every sample and every
//! scene's answer stays.

use std::path::PathBuf;
use std::process::ExitCode;

use crate::store::{compact, CompactOptions};
use crate::Error;

#[derive(clap::Args)]
pub struct CompactArgs {
    /// The container.
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
        return Err(Error::InvalidArgument(format!(
            "{}: a dataset's tiles are compacted one by one, each as a container of its own, \
             only through a dataset change (not yet: compact a container)",
            args.file.display()
        )));
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
