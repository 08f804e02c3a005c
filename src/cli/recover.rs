//! `fmrh recover`: open a container for writing and close it again, which is what recovery
//! after an interrupted writer needs (`format-spec/container.md` §11.4): pages past the
//! committed length are cut, a torn record in the unused commit slot is cleared, and the
//! recovery mark is taken off. A file that needs none of this is left as it is.

use std::path::PathBuf;
use std::process::ExitCode;

use fmrh::store::Container;
use fmrh::Error;

#[derive(clap::Args)]
pub struct RecoverArgs {
    /// The container.
    file: PathBuf,
    /// Print the report as JSON.
    #[arg(long)]
    pub json: bool,
}

/// Runs `fmrh recover`.
pub fn run(args: &RecoverArgs) -> Result<ExitCode, Error> {
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
