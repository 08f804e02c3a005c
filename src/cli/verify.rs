//! `fmrh verify`: the validator on the command line.

use std::fs::File;
use std::path::PathBuf;
use std::process::ExitCode;

use crate::store::{verify_with_progress, CheckStatus, FileSource, VerifyMode};
use crate::Error;

#[derive(clap::Args)]
pub struct VerifyArgs {
    /// The container, or a dataset's directory.
    file: PathBuf,
    /// Also recompute every error from the physical blocks, and check every cut and
    /// adjacency list.
    #[arg(long)]
    full: bool,
    /// Print the report as JSON.
    #[arg(long)]
    pub json: bool,
    /// Quiet: no progress bar, and nothing printed when the file is valid (the exit status
    /// says so); the report is printed when it is not.
    #[arg(long, short)]
    quiet: bool,
}

/// Exit status when a writer was committing and some check could not be decided.
const EXIT_BUSY: u8 = 75;

/// Exit status when the check could not read what it checks (sysexits' `EX_IOERR`): the
/// network or the disk failed, which says nothing about the data.
pub(super) const EXIT_IO: u8 = 74;

/// Runs `fmrh verify`: exit 0 valid, 1 invalid, 2 unusable, 74 a read failed (nothing was
/// decided), 75 busy or superseded (a writer was committing: run again).
pub fn run(args: &VerifyArgs) -> Result<ExitCode, Error> {
    if super::is_dataset(&args.file)? {
        return run_dataset(args);
    }
    let path = &args.file;
    if let Some(url) = super::url_of(path) {
        #[cfg(feature = "remote")]
        return check(args, crate::store::remote::HttpSource::open(url)?);
        #[cfg(not(feature = "remote"))]
        return Err(super::no_remote(url));
    }
    let file = File::open(path).map_err(|e| Error::input(path, e.to_string()))?;
    check(args, FileSource::new(file, path)?)
}

/// Verifies the container `src` holds and reports.
fn check<S: crate::store::Source>(args: &VerifyArgs, src: S) -> Result<ExitCode, Error> {
    let path = &args.file;
    let mode = if args.full {
        VerifyMode::Full
    } else {
        VerifyMode::Fast
    };
    let report = if args.quiet || args.json {
        verify_with_progress(src, mode, &crate::progress::Silent)?
    } else {
        verify_with_progress(src, mode, &super::progress::Bar::new())?
    };
    if args.json {
        super::print_json(&report)?;
    } else if !(args.quiet && report.valid) {
        println!(
            "{}: {} ({} check, txn {})",
            path.display(),
            if report.valid {
                "valid"
            } else if report.busy
                && !report
                    .checks
                    .iter()
                    .any(|c| c.status == CheckStatus::Failed)
            {
                "BUSY: a writer is committing; run again"
            } else {
                "INVALID"
            },
            match report.mode {
                VerifyMode::Fast => "fast",
                VerifyMode::Full => "full",
            },
            report
                .txn_id
                .map_or_else(|| "none".to_string(), |t| t.to_string())
        );
        for c in &report.checks {
            print_check(c);
        }
    }
    let failed = report
        .checks
        .iter()
        .any(|c| c.status == CheckStatus::Failed);
    Ok(if report.valid {
        ExitCode::SUCCESS
    } else if report.busy && !failed {
        ExitCode::from(EXIT_BUSY)
    } else {
        ExitCode::from(1)
    })
}

/// Prints one check's line and its first failures.
fn print_check(c: &crate::store::CheckReport) {
    let status = match c.status {
        CheckStatus::Passed => "ok",
        CheckStatus::Failed => "FAILED",
        CheckStatus::Skipped => "skipped",
        CheckStatus::Busy => "busy",
    };
    println!("  {:<5} {:<26} {status}", c.id, c.name);
    for f in &c.failures {
        println!("        {f}");
    }
    if c.failure_count > c.failures.len() as u64 {
        println!(
            "        ... and {} more",
            c.failure_count - c.failures.len() as u64
        );
    }
}

/// `fmrh verify DIR`: the dataset validator. Exit 0 valid, 1 invalid.
fn run_dataset(args: &VerifyArgs) -> Result<ExitCode, Error> {
    let mode = if args.full {
        VerifyMode::Full
    } else {
        VerifyMode::Fast
    };
    let report = if args.quiet || args.json {
        crate::dataset::verify(&args.file, mode, &crate::progress::Silent)?
    } else {
        crate::dataset::verify(&args.file, mode, &super::progress::Bar::new())?
    };
    if args.json {
        super::print_json(&report)?;
    } else if !(args.quiet && report.valid) {
        println!(
            "{}: {} ({} check of the manifest and {} tiles, txn {})",
            args.file.display(),
            if report.valid {
                "valid"
            } else if report.busy
                && report
                    .checks
                    .iter()
                    .all(|c| c.status != CheckStatus::Failed)
            {
                "BUSY (a tile's writer was committing: run again)"
            } else {
                "INVALID"
            },
            match report.mode {
                VerifyMode::Fast => "fast",
                VerifyMode::Full => "full",
            },
            report.tiles,
            report
                .txn_id
                .map_or_else(|| "none".to_string(), |t| t.to_string())
        );
        for c in &report.checks {
            print_check(c);
        }
        let bad = report.tile_reports.iter().filter(|t| !t.valid).count();
        println!(
            "  tiles: {} valid, {bad} invalid",
            report.tile_reports.len() - bad
        );
        for t in report.tile_reports.iter().filter(|t| !t.valid) {
            println!("    {} ({}): {}", t.index, t.name, t.failures.join("; "));
        }
        if !report.stray_files.is_empty() {
            println!(
                "  note: files no tile record names (not part of the dataset): {}",
                report.stray_files.join(", ")
            );
        }
    }
    let failed = report
        .checks
        .iter()
        .any(|c| c.status == CheckStatus::Failed);
    Ok(if report.valid {
        ExitCode::SUCCESS
    } else if report.busy && !failed {
        ExitCode::from(EXIT_BUSY)
    } else {
        ExitCode::from(1)
    })
}
