//! The `fmrh` command line (inside the library, so that it uses the library's rooms and the
//! public API stays small; `src/main.rs` only calls [`main`]): build containers from DEMs, inspect, verify, scan and extract them,
//! schedule scenes, and replace samples transactionally.
//!
//! Exit status: 0 on success; 2 when the input or the arguments are unusable (malformed,
//! corrupt or unsupported file, bad option value, size beyond limits); 1 when the system fails
//! (I/O); 75 when a concurrent writer got in the way of a read and it should be run again.
//! `fmrh verify` has its own: 0 valid, 1 invalid, 2 unusable, 75 a writer is committing.

pub mod args;
pub mod build;
pub mod compact;
pub mod dataset;
pub mod export;
pub mod extract;
pub mod fly;
pub mod info;
pub mod mesh;
pub mod progress;
pub mod recover;
pub mod render;
pub mod replace;
pub mod scan;
pub mod scene;
pub mod serve;
pub mod sidecar;
pub mod verify;

use std::path::Path;
use std::process::ExitCode;

use clap::{Parser, Subcommand};
use serde::Serialize;

use crate::error::Error;
use crate::store::{FileSource, Store};

/// Prints `value` as pretty JSON.
pub fn print_json<T: Serialize>(value: &T) -> Result<(), Error> {
    let text = serde_json::to_string_pretty(value)
        .map_err(|e| Error::InvalidArgument(format!("cannot format the report: {e}")))?;
    println!("{text}");
    Ok(())
}

/// Opens a container for the read-only commands: positioned reads, the state registered
/// against reuse by writers in other processes (see `Store::open`).
pub fn open(path: &Path) -> Result<Store<FileSource>, Error> {
    Store::open(path)
}

/// The URL `path` names, when it is one (`http://`, `https://`, `s3://`): a remote
/// container or dataset.
pub fn url_of(path: &Path) -> Option<&str> {
    path.to_str().filter(|t| crate::store::is_url(t))
}

/// The error for a URL in a build without the `remote` feature.
#[cfg(not(feature = "remote"))]
pub fn no_remote(url: &str) -> Error {
    Error::InvalidArgument(format!(
        "{url}: this fmrh was built without the `remote` feature (HTTP range reads)"
    ))
}

/// Refuses an existing `output` unless `force` (`-`, standard output, always goes).
pub fn check_output(output: &Path, force: bool) -> Result<(), Error> {
    if output != Path::new("-") && !force && output.exists() {
        return Err(Error::InvalidArgument(format!(
            "{} exists; pass --force to replace it",
            output.display()
        )));
    }
    Ok(())
}

/// Writes `bytes` to `output`: standard output for `-`, else atomically (an existing file
/// stays whole until the new one replaces it, and only with `force`).
pub fn write_output(output: &Path, force: bool, bytes: &[u8]) -> Result<(), Error> {
    use std::io::Write;
    if output == Path::new("-") {
        let mut out = std::io::stdout().lock();
        return out
            .write_all(bytes)
            .and_then(|()| out.flush())
            .map_err(|e| Error::io("<stdout>", e));
    }
    crate::store::write_atomically(output, force, |w| {
        w.write_all(bytes).map_err(|e| Error::io(output, e))
    })
}

/// Whether `path` names a dataset (a directory with a MANIFEST) rather than a container; a
/// directory without one is an error, not a file to open.
pub fn is_dataset(path: &Path) -> Result<bool, Error> {
    crate::terrain::names_dataset(path)
}

#[derive(Parser)]
#[command(
    name = "fmrh",
    version,
    about = "An embedded storage engine for multiresolution terrain",
    long_about = "fmrh turns a DEM (a grid of heights) into an FMRH: a quadtree of blocks, \
each with a measured error, grouped into error clusters in Hilbert order, so that a view \
becomes a few range scans. It stores the lot in one checksummed .fmrh container.\n\n\
Exit status (docs/containers.md, Exit status):\n  \
0    success (verify: VALID)\n  \
1    a system error: a disk or network failure, out of space (verify: INVALID)\n  \
2    unusable input or arguments: a missing, unreadable or malformed file, a bad option\n  \
74   verify only: a read failed, nothing was decided\n  \
75   a concurrent writer got in the way: run again\n  \
129  SIGHUP, 130 SIGINT, 143 SIGTERM: stopped, no temporary file left"
)]
struct Cli {
    #[command(subcommand)]
    command: Command,
}

#[derive(Subcommand)]
enum Command {
    /// Build a container from a DEM: blocks, FMRH with measured errors, error clusters.
    ///
    /// Reads INPUT in any supported format (.f32+.json, .hgt[.gz], GeoTIFF, PNG, JPEG, .asc,
    /// USGS .dem), cuts it into blocks, measures every node's error, builds one cluster per
    /// threshold and writes it all to OUT (-o). The file appears only when complete: it is
    /// written beside OUT under a temporary name, synced, and renamed. With --dry-run
    /// nothing is written and a summary is printed (--json for machine-readable output).
    Build(self::build::BuildArgs),
    /// Describe a container: dataset, levels, clusters, bytes per section.
    Info(self::info::InfoArgs),
    /// Check a container against every numbered invariant of the format spec.
    ///
    /// Fast mode checks commit records, every page's checksum, every table's structure,
    /// page ownership and every payload's checksum. --full also recomputes every error
    /// from the physical blocks and checks every cluster's cover, bound and minimality and
    /// the adjacency lists. Exit status: 0 valid, 1 invalid (each failed check named and
    /// located), 2 not a usable container, 74 a read failed (a network or disk error: nothing
    /// was decided), 75 busy or superseded (a writer was committing: run again).
    Verify(self::verify::VerifyArgs),
    /// Write full-resolution samples of a window exactly as stored (.f32 + .json sidecar).
    Extract(self::extract::ExtractArgs),
    /// Write a whole web tile pyramid for static hosting: Cesium's quantized-mesh terrain or
    /// terrain-RGB for web maps (MapLibre), to a directory or one PMTiles archive.
    ///
    /// Every tile of the zooms (--zoom) meeting the box (--bbox) is cut on every core, with
    /// the bytes `fmrh serve` answers for it, and written to a directory (`z/x/y.terrain`
    /// or `z/x/y.png`, with `layer.json` or `tilejson.json`) or, for an output ending in
    /// `.pmtiles`, to a PMTiles v3 archive (clustered, deduplicated, the JSON as its
    /// metadata). The output appears only when complete; an existing one is replaced only
    /// with --force.
    Export(self::export::ExportArgs),
    /// Range-scan one cluster by Hilbert keys or by ordinal position.
    Scan(self::scan::ScanArgs),
    /// The blocks one view needs: a camera and a tolerance in pixels in, blocks out.
    ///
    /// Uniform mode turns the tolerance into one static bound from the nearest terrain
    /// distance and scans one cluster; view mode gives every block the coarsest level that
    /// meets the tolerance where it is seen. Prints each block (level, samples, error,
    /// neighbour levels) and the cost; --reconstruct writes the window as the blocks draw it.
    Scene(self::scene::SceneArgs),
    /// Replay a camera path: per frame, blocks loaded, evicted and resident, and the cost.
    ///
    /// Each frame loads only what its scene needs and is not already resident (seed 000
    /// Algorithm 3). --memory-radius keeps blocks that left the view; --prefetch with
    /// --cache-radius warms the blocks of the extrapolated next camera on a second thread.
    Fly(self::fly::FlyArgs),
    /// Draw a scene as a PNG, on the CPU: the surface its blocks draw through the camera,
    /// hillshaded, tinted by each block's level and outlined; or, with --top, an overhead
    /// map of the blocks the camera selected with its view drawn on the ground.
    Render(self::render::RenderArgs),
    /// Mesh a scene as one glTF 2.0 binary (.glb): a node per block, crack-free.
    ///
    /// By default a block meeting a coarser one takes the coarser one's vertices along the
    /// shared edge (no crack, no T-junction); --cracks skirts hangs curtains instead. Each
    /// node's extras give the block's level, error, key and footprint; the scene's extras
    /// give the origin and the axes (X east, Y up, Z south, metres).
    Mesh(self::mesh::MeshArgs),
    /// Serve containers and datasets over HTTP, with a WebGL page to fly over them.
    ///
    /// `/files/NAME` gives each file's bytes with range requests and an ETag (so `fmrh
    /// scene http://HOST:PORT/files/NAME` reads it remotely; a dataset is
    /// `/files/NAME/`); `/` is a viewer that asks for scenes as its camera moves, with a
    /// tolerance slider and the scene's stats; `/api/scene` and `/api/mesh` answer a
    /// camera given in the query (JSON, and a glTF binary). Read-only; answers this
    /// machine only unless --bind says otherwise.
    Serve(self::serve::ServeArgs),
    /// Replace full-resolution samples, atomically: new blocks, errors, clusters, one commit.
    ///
    /// Reads PATCH in any format `build` reads and writes its samples at --at COL,ROW (the
    /// patch must fit inside the data; NaN or nodata samples become voids). Every affected
    /// block, node error, cluster cut and table is rewritten copy-on-write and published by
    /// one commit record: a crash at any instant leaves the old state or the new one, and
    /// the next open recovers. Prints what changed (--json for machine-readable output).
    Replace(self::replace::ReplaceArgs),
    /// Recover a file an interrupted writer left: cut uncommitted pages, clear a torn slot.
    ///
    /// A crash can never lose a committed state, but it can leave pages past the committed
    /// length and a torn record in the unused commit slot, which `verify` reports (I-3, I-4).
    /// Any writer's open recovers the file; this command does only that, then closes it.
    Recover(self::recover::RecoverArgs),
    /// Rewrite a container's current state as a fresh build of it would be: the pages edits
    /// left behind are gone; every sample and every scene stays the same. Atomic (a new file
    /// renamed over the old one, under the writer's lock); readers of the old file are not
    /// disturbed.
    Compact(self::compact::CompactArgs),
    /// Datasets of many tiles: build one, add a tile. Every other command takes a dataset's
    /// directory where it takes a container.
    #[command(subcommand)]
    Dataset(self::dataset::DatasetCommand),
    /// Print a shell completion script (bash, zsh, fish, elvish, powershell) to standard output.
    ///
    /// e.g. `fmrh completions bash > ~/.local/share/bash-completion/completions/fmrh`.
    Completions {
        /// The shell.
        shell: clap_complete::Shell,
    },
    /// Print the manual page (roff) to standard output: `fmrh man | man -l -`.
    Man,
}

impl Command {
    /// Whether the command was asked for JSON output.
    fn json(&self) -> bool {
        match self {
            Command::Build(a) => a.json,
            Command::Info(a) => a.json,
            Command::Verify(a) => a.json,
            Command::Scan(a) => a.json,
            Command::Scene(a) => a.json,
            Command::Fly(a) => a.json,
            Command::Replace(a) => a.json,
            Command::Recover(a) => a.json,
            Command::Compact(a) => a.json,
            Command::Dataset(c) => c.json(),
            Command::Extract(_)
            | Command::Export(_)
            | Command::Render(_)
            | Command::Mesh(_)
            | Command::Serve(_)
            | Command::Completions { .. }
            | Command::Man => false,
        }
    }
}

/// Exit status of a read that met a writer it could not read past: the file is fine, run the
/// command again (BSD `EX_TEMPFAIL`).
const EXIT_RETRY: u8 = 75;

/// Runs the `fmrh` command line on this process's arguments: what the binary's `main` does.
pub fn main() -> ExitCode {
    // A closed output pipe (`fmrh info F | head -1`) ends the process quietly, as it does `cat`
    // or `gdalinfo`, instead of a panic in `println!`.
    #[cfg(unix)]
    // SAFETY: `signal` with `SIG_DFL` only restores the default action; it runs first thing in
    // main, before any other thread exists.
    unsafe {
        libc::signal(libc::SIGPIPE, libc::SIG_DFL);
    }
    // A signal during a write removes the temporary file it was writing, and the process
    // exits as a shell reports that signal: 128 + its number (SIGINT 130, SIGTERM 143).
    #[cfg(unix)]
    {
        use signal_hook::consts::{SIGHUP, SIGINT, SIGTERM};
        if let Ok(mut signals) = signal_hook::iterator::Signals::new([SIGINT, SIGTERM, SIGHUP]) {
            std::thread::spawn(move || {
                if let Some(signal) = signals.forever().next() {
                    crate::store::write::remove_temporary_files();
                    std::process::exit(128 + signal);
                }
            });
        }
    }
    #[cfg(not(unix))]
    let _ = ctrlc::set_handler(|| {
        crate::store::write::remove_temporary_files();
        std::process::exit(130);
    });
    let cli = Cli::parse();
    let result = match &cli.command {
        Command::Build(args) => self::build::run(args),
        Command::Info(args) => self::info::run(args),
        Command::Verify(args) => self::verify::run(args),
        Command::Extract(args) => self::extract::run(args),
        Command::Export(args) => self::export::run(args),
        Command::Scan(args) => self::scan::run(args),
        Command::Scene(args) => self::scene::run(args),
        Command::Fly(args) => self::fly::run(args),
        Command::Render(args) => self::render::run(args),
        Command::Mesh(args) => self::mesh::run(args),
        Command::Serve(args) => self::serve::run(args),
        Command::Replace(args) => self::replace::run(args),
        Command::Recover(args) => self::recover::run(args),
        Command::Compact(args) => self::compact::run(args),
        Command::Dataset(command) => self::dataset::run(command),
        Command::Completions { shell } => {
            let mut command = <Cli as clap::CommandFactory>::command();
            clap_complete::generate(*shell, &mut command, "fmrh", &mut std::io::stdout());
            Ok(ExitCode::SUCCESS)
        }
        Command::Man => {
            let command = <Cli as clap::CommandFactory>::command();
            clap_mangen::Man::new(command)
                .render(&mut std::io::stdout())
                .map(|()| ExitCode::SUCCESS)
                .map_err(|e| Error::io("<stdout>", e))
        }
    };
    match result {
        Ok(code) => code,
        Err(e) => {
            eprintln!("fmrh: error: {e}");
            // A file that is not there, or that fmrh may not read, is the caller's to fix:
            // an unusable input (exit 2), not a failure of the system (exit 1).
            let unusable = matches!(
                &e,
                Error::Io { source, .. } if matches!(
                    source.kind(),
                    std::io::ErrorKind::NotFound | std::io::ErrorKind::PermissionDenied
                )
            );
            if cli.command.json() {
                // --json promises JSON on stdout, failures included.
                let kind = if unusable { "input" } else { e.kind() };
                let out = serde_json::json!({ "error": e.to_string(), "kind": kind });
                println!("{out}");
            }
            if unusable {
                return ExitCode::from(2);
            }
            match e {
                // `verify` exits 1 for INVALID: a failed read (a network gone, a disk error)
                // must not look like a finding about the data.
                Error::Io { .. } if matches!(cli.command, Command::Verify(_)) => {
                    ExitCode::from(self::verify::EXIT_IO)
                }
                Error::Io { .. } | Error::Poisoned { .. } => ExitCode::from(1),
                Error::Superseded { .. } | Error::Changed { .. } => ExitCode::from(EXIT_RETRY),
                _ => ExitCode::from(2),
            }
        }
    }
}

#[cfg(test)]
mod tests {
    /// Every command's arguments are well formed as clap checks them (unique ids, valid
    /// defaults and conflicts). Release builds skip these checks when parsing, so a clash
    /// would otherwise pass `cargo test --release` and panic only in a debug build: one did,
    /// `dataset add`'s positional `tile` against `--tile` (regression).
    #[test]
    fn every_command_is_well_formed() {
        use clap::CommandFactory;
        super::Cli::command().debug_assert();
    }
}
