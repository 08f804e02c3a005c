//! `fmrh recover`: open a container for writing and close it again, which is what recovery
//! after an interrupted writer needs (`format-spec/container.md` §11.4): pages past the
//! committed length are cut, a torn record in the unused commit slot is cleared, and the
//! recovery mark is taken off. A file that needs none of this is left as it is.

use std::path::PathBuf;
use std::process::ExitCode;

use crate::store::Container;
use crate::Error;

#[derive(clap::Args)]
pub struct RecoverArgs {
    /// The container, or a dataset's directory (every tile an interrupted change moved on
    /// gets its pinned state back; every tile is recovered as a container).
    file: PathBuf,
    /// Print the report as JSON.
    #[arg(long)]
    pub json: bool,
}

/// Runs `fmrh recover`.
pub fn run(args: &RecoverArgs) -> Result<ExitCode, Error> {
    if super::is_dataset(&args.file)? {
        let r = crate::dataset::recover(&crate::dataset::Dir(args.file.clone()))?;
        if args.json {
            super::print_json(&r)?;
        } else if r.republished.is_empty() && r.recovered.is_empty() {
            println!(
                "{}: nothing to recover (txn {})",
                args.file.display(),
                r.txn_id
            );
        } else {
            println!(
                "{}: recovered at txn {}: pinned states republished in [{}]; tiles recovered \
                 as containers: [{}]",
                args.file.display(),
                r.txn_id,
                r.republished.join(", "),
                r.recovered.join(", ")
            );
        }
        return Ok(ExitCode::SUCCESS);
    }
    let (container, recovery) = Container::open_recovering(&args.file)?;
    container.close()?;
    if args.json {
        super::print_json(&recovery)?;
    } else if recovery.marked || recovery.truncated > 0 || recovery.slot_cleared {
        println!(
            "{}: recovered (an interrupted writer had it open): {} bytes cut, torn commit slot \
             cleared: {}",
            args.file.display(),
            recovery.truncated,
            recovery.slot_cleared
        );
    } else {
        println!("{}: nothing to recover", args.file.display());
    }
    Ok(ExitCode::SUCCESS)
}
