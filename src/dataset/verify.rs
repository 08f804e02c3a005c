//! The dataset validator (`format-spec/dataset.md` §6): the manifest's own invariants
//! (D-1 to D-3), then every tile: its file holds the pinned state, of the size and heights the
//! record says, valid by the container validator in the same mode (D-4), and neighbours hold
//! the same samples on their shared edges. Corruption is reported, located, as failures;
//! only an unusable directory or an I/O error is an `Err`.

use serde::Serialize;

use super::adjacency::{borders_of, tables_of, TileEdges};
use super::manifest::{read_slots, slots_now, MANIFEST_NAME};
use super::placement::check_tiling;
use super::reader::{Dataset, Tile};
use crate::error::{Error, Result};
use crate::format::manifest::ManifestSlot;
use crate::format::Invariant;
use crate::model::SampleRect;
use crate::store::slots::SlotsNow;
use crate::store::verify::Checks;
use crate::store::{verify_pinned, AnySource, CheckReport, CheckStatus, VerifyMode};

/// One tile's result.
#[derive(Clone, Debug, Serialize)]
pub struct TileReport {
    /// Its index in the manifest.
    pub index: u64,
    /// Its file.
    pub name: String,
    /// Its samples in dataset coordinates.
    pub rect: SampleRect,
    /// Whether its pinned state passed the container validator.
    pub valid: bool,
    /// The container checks that failed, each `I-n: message`.
    pub failures: Vec<String>,
}

/// The result of the dataset validator (`fmrh verify DIR`, `Terrain::verify`).
#[derive(Clone, Debug, Serialize)]
pub struct DatasetReport {
    /// Fast or full (the mode each tile was verified in).
    pub mode: VerifyMode,
    /// Whether every check passed.
    pub valid: bool,
    /// A tile's writer was committing while it was checked, and what it had written so far
    /// around the pinned state (pages past its length, the other slot) could not be told
    /// from damage; nothing failed besides. Run again.
    pub busy: bool,
    /// The manifest state checked.
    pub txn_id: Option<u64>,
    /// Tiles.
    pub tiles: u64,
    /// The dataset invariants, D-1 to D-4.
    pub checks: Vec<CheckReport>,
    /// Each tile's container check.
    pub tile_reports: Vec<TileReport>,
    /// Files of the directory that no tile record names (left by an interrupted `dataset
    /// add`, or by hand): not part of the dataset, and not a failure.
    pub stray_files: Vec<String>,
}

/// A corruption of a dataset invariant becomes its failure; of a container invariant (a
/// tile's), a D-4 failure located at `what`; anything else stops the check.
fn absorb<T>(checks: &mut Checks, what: &str, result: Result<T>) -> Result<Option<T>> {
    match result {
        Err(Error::Corrupt {
            invariant,
            location,
            detail,
            ..
        }) if !checks.knows(invariant) => {
            checks.fail(
                Invariant::TilePins,
                format!("{what}{invariant} at {location}: {detail}"),
            );
            Ok(None)
        }
        other => checks.absorb(other),
    }
}

/// Verifies the dataset in `dir`. `Err` only for a directory that is not a dataset, a
/// manifest of a newer major version, or a failed read.
pub fn verify(
    dir: &std::path::Path,
    mode: VerifyMode,
    progress: &dyn crate::progress::Progress,
) -> Result<DatasetReport> {
    let mut checks = Checks::of(&Invariant::DATASET);
    let mut report = DatasetReport {
        mode,
        valid: false,
        busy: false,
        txn_id: None,
        tiles: 0,
        checks: Vec::new(),
        tile_reports: Vec::new(),
        stray_files: Vec::new(),
    };
    // D-1 and D-2: the state a reader takes, and its head. The other slot must be empty,
    // an older valid record, or (after a crash while it was written) torn: a torn inactive
    // slot is what a crash leaves, and the next commit overwrites it.
    let dataset = match absorb(&mut checks, "", Dataset::open(dir))? {
        Some(d) => d,
        None => {
            report.checks = checks.into_reports();
            return Ok(report);
        }
    };
    checks.pass(Invariant::ManifestRecord);
    let checked = check_state(dir, &dataset, mode, progress, checks, &mut report);
    // A finding, or an error, about a state the manifest has moved on from since it was
    // opened is no finding about the dataset: a writer's next commit may reuse what the
    // state pinned (a tile overwrites the slot of the state before the one the manifest
    // pins now). The reader's state was superseded: say so (exit 75, try again), as a
    // container's reader does; a retry checks the new state and finds any real damage.
    if let Err(e) = checked {
        return Err(dataset.moved_on(e));
    }
    if !report.valid {
        let first = report
            .checks
            .iter()
            .find(|c| c.status == CheckStatus::Failed)
            .and_then(|c| c.failures.first().map(|f| format!("{}: {f}", c.id)))
            .unwrap_or_default();
        let txn = dataset.txn_id();
        match slots_now(dataset.manifest_source(), &dataset.state().record)? {
            SlotsNow::Latest { txn: latest, .. } if latest > txn => {
                return Err(Error::Superseded {
                    path: dir.to_path_buf(),
                    txn,
                    latest,
                    detail: format!("the check found {first} while a writer committed"),
                })
            }
            SlotsNow::Latest {
                still_published: false,
                ..
            } => {
                return Err(Error::Changed {
                    path: dir.to_path_buf(),
                    detail: format!(
                        "the manifest no longer publishes the state checked (txn {txn}), and \
                         no newer state does; the check found {first}"
                    ),
                })
            }
            _ => {}
        }
    }
    Ok(report)
}

/// Every check of the state `dataset` opened, into `report`.
fn check_state(
    dir: &std::path::Path,
    dataset: &Dataset,
    mode: VerifyMode,
    progress: &dyn crate::progress::Progress,
    mut checks: Checks,
    report: &mut DatasetReport,
) -> Result<()> {
    let slots = read_slots(dataset.manifest_source())?;
    let txn = dataset.txn_id();
    report.txn_id = Some(txn);
    report.tiles = dataset.tile_count();
    let other = &slots[usize::from(1 - dataset.state().slot)];
    if let ManifestSlot::Valid(r) = other {
        if r.txn_id.get() >= txn {
            checks.fail(
                Invariant::ManifestRecord,
                format!(
                    "manifest slot {}: txn {} is not older than the active state's {txn}",
                    1 - dataset.state().slot,
                    r.txn_id.get()
                ),
            );
        }
    }
    checks.pass(Invariant::ManifestPages);
    // Every tile page (D-2), then the records as a whole (D-3).
    let Some(tiles) = absorb(&mut checks, "", dataset.tiles())? else {
        report.checks = checks.into_reports();
        return Ok(());
    };
    check_records(dataset, &tiles, &mut checks);
    // D-4: every tile at its pin.
    let mut open: Vec<Option<std::sync::Arc<crate::store::Store<AnySource>>>> =
        Vec::with_capacity(tiles.len());
    for tile in &tiles {
        let at = format!("tile {} ({}): ", tile.index, tile.name());
        let file = dataset.tile_path(tile);
        let mut tr = TileReport {
            index: tile.index,
            name: tile.name().to_string(),
            rect: tile.rect(),
            valid: false,
            failures: Vec::new(),
        };
        let opened = match AnySource::open_tile(&file, Some(dataset.manifest_source().inner())) {
            Ok(src) => absorb(
                &mut checks,
                &at,
                verify_pinned(src, tile.pin(), mode, progress),
            )?,
            // A network failure is not the dataset's fault: an error, not a finding.
            Err(e @ Error::Io { .. })
                if dataset.is_remote()
                    && !matches!(&e, Error::Io { source, .. }
                        if source.kind() == std::io::ErrorKind::NotFound) =>
            {
                return Err(e)
            }
            Err(e) => {
                checks.fail(
                    Invariant::TilePins,
                    format!("{at}cannot open {}: {e}", file.display()),
                );
                None
            }
        };
        if let Some(r) = opened {
            tr.valid = r.valid;
            for c in r.checks.iter().filter(|c| c.status == CheckStatus::Failed) {
                for f in &c.failures {
                    tr.failures.push(format!("{}: {f}", c.id));
                }
            }
            if !r.valid && r.busy && !r.checks.iter().any(|c| c.status == CheckStatus::Failed) {
                // A commit in progress in the tile (the checks around its state): not a
                // finding about the pinned state.
                report.busy = true;
                tr.valid = true;
            } else if !r.valid {
                checks.fail(
                    Invariant::TilePins,
                    format!(
                        "{at}its pinned state is invalid: {}",
                        tr.failures.join("; ")
                    ),
                );
            }
        }
        let store = if tr.valid {
            absorb(&mut checks, &at, dataset.open_tile(tile))?
        } else {
            None
        };
        if let Some(s) = &store {
            // The head's datum, when recorded (manifest 1.1), is every tile's.
            let theirs = s.header().metadata.vertical_datum;
            if let Some(ours) = dataset.state().vertical_datum().filter(|d| *d != theirs) {
                checks.fail(
                    Invariant::TilePins,
                    format!(
                        "{at}heights above {}, where the manifest says {}",
                        theirs.name(),
                        ours.name()
                    ),
                );
            }
            match s.node(0) {
                Ok(root) => {
                    let (lo, hi) = (tile.record.min_height.get(), tile.record.max_height.get());
                    if root.min_height.to_bits() != lo.to_bits()
                        || root.max_height.to_bits() != hi.to_bits()
                    {
                        checks.fail(
                            Invariant::TilePins,
                            format!(
                                "{at}heights {} .. {}, where the record says {lo} .. {hi}",
                                root.min_height, root.max_height
                            ),
                        );
                    }
                }
                Err(e) => {
                    absorb::<()>(&mut checks, &at, Err(e))?;
                }
            }
        }
        open.push(store);
        report.tile_reports.push(tr);
    }
    // Shared edges: the same samples on both sides.
    let rects: Vec<SampleRect> = tiles.iter().map(Tile::rect).collect();
    if let Ok(shared) = check_tiling(&rects) {
        for (a, b, o) in shared {
            let (Some(sa), Some(sb)) = (&open[a], &open[b]) else {
                continue;
            };
            let local = |t: &Tile| SampleRect {
                col0: o.col0 - t.rect().col0,
                row0: o.row0 - t.rect().row0,
                col1: o.col1 - t.rect().col0,
                row1: o.row1 - t.rect().row0,
            };
            let va = absorb(&mut checks, "", sa.read_window(local(&tiles[a])))?;
            let vb = absorb(&mut checks, "", sb.read_window(local(&tiles[b])))?;
            if let (Some(va), Some(vb)) = (va, vb) {
                let w = o.col1 - o.col0 + 1;
                if let Some(i) =
                    va.samples().iter().zip(vb.samples()).position(|(x, y)| {
                        x.to_bits() != y.to_bits() && !(x.is_nan() && y.is_nan())
                    })
                {
                    let (col, row) = (o.col0 + i as u64 % w, o.row0 + i as u64 / w);
                    checks.fail(
                        Invariant::TilePins,
                        format!(
                            "tiles {} and {} disagree on their shared edge at dataset column {col}, row {row}: {} and {}",
                            tiles[a].name(),
                            tiles[b].name(),
                            va.samples()[i],
                            vb.samples()[i]
                        ),
                    );
                }
            }
        }
    }
    checks.pass(Invariant::TilePins);
    // D-5: every tile's tables, decoded, and equal to their recomputation from the pinned
    // states' edge lists (when every tile they need opened).
    let mut edges: Vec<Option<std::sync::Arc<TileEdges>>> = Vec::with_capacity(tiles.len());
    for (t, store) in tiles.iter().zip(&open) {
        edges.push(match store {
            Some(s) => {
                absorb(&mut checks, "", TileEdges::read(s, &t.record))?.map(std::sync::Arc::new)
            }
            None => None,
        });
    }
    for (k, t) in tiles.iter().enumerate() {
        let at = format!("tile {} ({})", t.index, t.name());
        let Some(stored) = absorb(&mut checks, "", dataset.borders(t))? else {
            continue;
        };
        let mut lookup = |j: usize| -> crate::error::Result<std::sync::Arc<TileEdges>> {
            edges[j]
                .clone()
                .ok_or_else(|| Error::Internal("a tile that did not open".into()))
        };
        let needed = borders_of(&rects[k], &rects);
        if edges[k].is_none() || needed.iter().any(|b| edges[b.0].is_none()) {
            continue;
        }
        let expect = super::adjacency::decode(&tables_of(k, &rects, &mut lookup)?)
            .map_err(Error::Internal)?;
        if stored != expect {
            let first = stored
                .iter()
                .zip(&expect)
                .position(|(a, b)| a != b)
                .unwrap_or(stored.len().min(expect.len()));
            checks.fail(
                Invariant::AdjacentClusters,
                format!(
                    "{at}: {} borders stored, {} expected; border {first} differs from the \
                     merge of the edge lists",
                    stored.len(),
                    expect.len()
                ),
            );
        }
    }
    checks.pass(Invariant::AdjacentClusters);
    report.stray_files = stray_files(dir, &tiles);
    report.checks = checks.into_reports();
    report.valid = !report.busy
        && report
            .checks
            .iter()
            .all(|c| c.status == CheckStatus::Passed);
    Ok(())
}

/// D-3 over all records: unique names, the manifest's order, the grid's extent, the tiling.
fn check_records(dataset: &Dataset, tiles: &[Tile], checks: &mut Checks) {
    let mut names = std::collections::HashSet::new();
    for t in tiles {
        if !names.insert(t.name().to_ascii_lowercase()) {
            checks.fail(
                Invariant::TileRecords,
                format!(
                    "tile {}: file name {} is used twice (case ignored)",
                    t.index,
                    t.name()
                ),
            );
        }
    }
    for w in tiles.windows(2) {
        if super::manifest::tile_order(&w[0].record) >= super::manifest::tile_order(&w[1].record) {
            checks.fail(
                Invariant::TileRecords,
                format!(
                    "tiles {} and {}: not in Hilbert order of their first samples",
                    w[0].index, w[1].index
                ),
            );
        }
    }
    let grid = dataset.grid();
    let cols = tiles.iter().map(|t| t.rect().col1).max();
    let rows = tiles.iter().map(|t| t.rect().row1).max();
    if !tiles.is_empty() && (cols != Some(grid.col1) || rows != Some(grid.row1)) {
        checks.fail(
            Invariant::TileRecords,
            format!(
                "the grid is {} x {}, the tiles end at column {cols:?}, row {rows:?}",
                grid.col1 + 1,
                grid.row1 + 1
            ),
        );
    }
    let rects: Vec<SampleRect> = tiles.iter().map(Tile::rect).collect();
    if let Err(e) = check_tiling(&rects) {
        checks.fail(Invariant::TileRecords, e.to_string());
    }
    checks.pass(Invariant::TileRecords);
}

/// Files in `dir` that are neither the manifest nor a tile.
fn stray_files(dir: &std::path::Path, tiles: &[Tile]) -> Vec<String> {
    let known: std::collections::HashSet<&str> = tiles
        .iter()
        .map(Tile::name)
        .chain([MANIFEST_NAME])
        .collect();
    let mut out: Vec<String> = std::fs::read_dir(dir)
        .map(|rd| {
            rd.filter_map(|e| e.ok())
                .filter_map(|e| e.file_name().to_str().map(str::to_string))
                .filter(|n| !known.contains(n.as_str()))
                .collect()
        })
        .unwrap_or_default();
    out.sort();
    out
}
