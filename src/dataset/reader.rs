//! A dataset opened for reading: its manifest's state, the tiles a window meets, and the
//! tiles' containers opened at their pinned states as they are needed (`format-spec/dataset.md`
//! §4). Opening reads the manifest's slots and head and no tile; a window reads the tile
//! pages whose rectangles it meets and opens only the tiles it meets.

use std::path::{Path, PathBuf};
use std::sync::{Arc, Mutex};

use super::manifest::{pages_meeting, ManifestState, MANIFEST_NAME};
use crate::error::{Error, Result};
use crate::format::manifest::{StatePin, TileRecord};
use crate::heightfield::{Georeference, Heightfield, Metadata};
use crate::model::SampleRect;
use crate::store::{Counted, FileSource, ReadStats, Source, Store};

/// Tile containers a dataset keeps open at once; the least recently used is closed first.
pub const OPEN_TILES: usize = 64;

/// One tile as the manifest records it, with its index in the manifest's order.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Tile {
    /// Index in the manifest (Hilbert order of the tiles' first samples).
    pub index: u64,
    /// Its record.
    pub record: TileRecord,
}

impl Tile {
    /// Its samples, in dataset coordinates.
    pub fn rect(&self) -> SampleRect {
        self.record.rect()
    }

    /// Its file name in the dataset's directory.
    pub fn name(&self) -> &str {
        self.record.name()
    }

    /// Its pinned state.
    pub fn pin(&self) -> StatePin {
        self.record.pin()
    }
}

/// A dataset opened for reading.
pub struct Dataset {
    dir: PathBuf,
    src: Counted<FileSource>,
    state: ManifestState,
    open_reads: ReadStats,
    tiles: Mutex<Vec<(u64, Arc<Store<FileSource>>)>>,
    tiles_opened: std::sync::atomic::AtomicU64,
}

/// Whether `path` is a dataset: a directory holding a `MANIFEST`.
pub fn is_dataset(path: &Path) -> bool {
    path.is_dir() && path.join(MANIFEST_NAME).is_file()
}

impl Dataset {
    /// Opens the dataset in directory `dir`: reads its manifest's slots and head.
    pub fn open(dir: &Path) -> Result<Dataset> {
        if !dir.is_dir() {
            return Err(Error::input(
                dir,
                "not a directory (a dataset is a directory with a MANIFEST)",
            ));
        }
        let path = dir.join(MANIFEST_NAME);
        if !path.is_file() {
            return Err(Error::input(
                dir,
                "no MANIFEST in this directory: not an fmrh dataset",
            ));
        }
        let src = Counted::new(FileSource::open(&path)?);
        let state = ManifestState::read(&src)?;
        let open_reads = src.stats();
        Ok(Dataset {
            dir: dir.to_path_buf(),
            src,
            state,
            open_reads,
            tiles: Mutex::new(Vec::new()),
            tiles_opened: 0.into(),
        })
    }

    /// The manifest, as this dataset reads it.
    pub(crate) fn manifest_source(&self) -> &Counted<FileSource> {
        &self.src
    }

    /// The directory.
    pub fn dir(&self) -> &Path {
        &self.dir
    }

    /// The manifest state this dataset reads.
    pub fn state(&self) -> &ManifestState {
        &self.state
    }

    /// Its transaction id.
    pub fn txn_id(&self) -> u64 {
        self.state.record.txn_id.get()
    }

    /// Tiles.
    pub fn tile_count(&self) -> u64 {
        self.state.record.tile_count.get()
    }

    /// The dataset grid: every tile lies inside `0,0 .. columns-1,rows-1`.
    pub fn grid(&self) -> SampleRect {
        let r = &self.state.record;
        SampleRect {
            col0: 0,
            row0: 0,
            col1: r.columns.get().saturating_sub(1),
            row1: r.rows.get().saturating_sub(1),
        }
    }

    /// Metres between samples, when known.
    pub fn spacing_m(&self) -> Option<[f64; 2]> {
        self.state.record.spacing_m()
    }

    /// The georeference of dataset sample (0, 0), when known.
    pub fn georeference(&self) -> Option<Georeference> {
        self.state.georeference()
    }

    /// What opening read from the manifest.
    pub fn open_reads(&self) -> ReadStats {
        self.open_reads
    }

    /// What the manifest reads cost since opening (tile pages).
    pub fn manifest_reads(&self) -> ReadStats {
        self.src.stats().since(&self.open_reads)
    }

    /// Tile containers opened so far.
    pub fn tiles_opened(&self) -> u64 {
        self.tiles_opened.load(std::sync::atomic::Ordering::Relaxed)
    }

    /// The tiles whose rectangles meet `rect`, in manifest order: reads only the tile pages
    /// whose bounds meet it.
    pub fn tiles_meeting(&self, rect: &SampleRect) -> Result<Vec<Tile>> {
        let mut out = Vec::new();
        for p in pages_meeting(&self.state.head, rect) {
            let first = u64::from(self.state.head.pages[p].first_tile.get());
            for (i, t) in self.state.page(&self.src, p)?.iter().enumerate() {
                if t.rect().intersect(rect).is_some() {
                    out.push(Tile {
                        index: first + i as u64,
                        record: *t,
                    });
                }
            }
        }
        Ok(out)
    }

    /// Tile `index`: reads the tile page that holds it.
    pub fn tile(&self, index: u64) -> Result<Tile> {
        let per = crate::format::manifest::TILES_PER_PAGE as u64;
        let p = usize::try_from(index / per).unwrap_or(usize::MAX);
        if index >= self.tile_count() || p >= self.state.head.pages.len() {
            return Err(Error::InvalidArgument(format!(
                "tile {index}: the dataset has {} tiles",
                self.tile_count()
            )));
        }
        let records = self.state.page(&self.src, p)?;
        let record = *records
            .get((index % per) as usize)
            .ok_or_else(|| Error::Internal(format!("tile page {p} lacks tile {index}")))?;
        Ok(Tile { index, record })
    }

    /// The adjacent-cluster tables `tile` stores: its borders with the tiles east and south of
    /// it (`format-spec/dataset.md` §3.5), read and checked the first time.
    pub fn borders(&self, tile: &Tile) -> Result<Vec<super::adjacency::Border>> {
        let bytes = self.state.adjacency(&self.src, &tile.record)?;
        super::adjacency::decode(&bytes).map_err(|detail| {
            crate::format::Violation::new(
                crate::format::Invariant::AdjacentClusters,
                format!(
                    "adjacent-cluster tables of tile {} ({})",
                    tile.index,
                    tile.name()
                ),
                detail,
            )
            .in_file(self.src.name())
        })
    }

    /// Every tile, in manifest order (reads every tile page).
    pub fn tiles(&self) -> Result<Vec<Tile>> {
        let mut out = Vec::with_capacity(usize::try_from(self.tile_count()).unwrap_or(0));
        for p in 0..self.state.head.pages.len() {
            let first = u64::from(self.state.head.pages[p].first_tile.get());
            for (i, t) in self.state.page(&self.src, p)?.iter().enumerate() {
                out.push(Tile {
                    index: first + i as u64,
                    record: *t,
                });
            }
        }
        Ok(out)
    }

    /// The path of a tile's file.
    pub fn tile_path(&self, tile: &Tile) -> PathBuf {
        self.dir.join(tile.name())
    }

    /// The tile's container at its pinned state, opened on first use and kept among the
    /// [`OPEN_TILES`] most recently used.
    pub fn open_tile(&self, tile: &Tile) -> Result<Arc<Store<FileSource>>> {
        let mut open = self
            .tiles
            .lock()
            .map_err(|_| Error::Internal("tile cache poisoned".into()))?;
        if let Some(i) = open.iter().position(|(k, _)| *k == tile.index) {
            let entry = open.remove(i);
            let store = entry.1.clone();
            open.push(entry);
            return Ok(store);
        }
        drop(open);
        let store = Arc::new(self.open_tile_uncached(tile)?);
        self.tiles_opened
            .fetch_add(1, std::sync::atomic::Ordering::Relaxed);
        let mut open = self
            .tiles
            .lock()
            .map_err(|_| Error::Internal("tile cache poisoned".into()))?;
        if open.len() >= OPEN_TILES {
            open.remove(0);
        }
        open.push((tile.index, store.clone()));
        Ok(store)
    }

    /// Opens a tile's container at its pinned state, checking that it is the size its
    /// record says. A tile whose file no longer holds the pinned state was superseded when
    /// the manifest has moved on since this dataset was opened, and is corrupt otherwise.
    pub fn open_tile_uncached(&self, tile: &Tile) -> Result<Store<FileSource>> {
        let path = self.tile_path(tile);
        let store = match Store::open_pinned(&path, tile.pin()) {
            Ok(s) => s,
            Err(e @ Error::Corrupt { .. }) => return Err(self.moved_on(e)),
            // A tile replaced by a newer dataset state has its file removed.
            Err(e @ Error::Io { .. }) if !path.exists() => return Err(self.moved_on(e)),
            Err(e) => return Err(e),
        };
        let d = store.domain();
        let r = &tile.record;
        if d.width() != r.width.get() || d.height() != r.height.get() {
            return Err(crate::format::Violation::new(
                crate::format::Invariant::TilePins,
                format!("tile {} ({})", tile.index, tile.name()),
                format!(
                    "the file holds {} x {} samples, the manifest says {} x {}",
                    d.width(),
                    d.height(),
                    r.width.get(),
                    r.height.get()
                ),
            )
            .in_file(self.src.name()));
        }
        Ok(store)
    }

    /// `e`, or `Superseded` when a newer dataset state has been published since this one.
    fn moved_on(&self, e: Error) -> Error {
        match super::manifest::latest_txn(&self.src) {
            Ok(Some(latest)) if latest > self.txn_id() => Error::Superseded {
                path: self.dir.clone(),
                txn: self.txn_id(),
                latest,
                detail: format!("a tile moved on with the newer dataset state: {e}"),
            },
            _ => e,
        }
    }

    /// The samples of `window` (dataset coordinates, inclusive), bit for bit as the tiles
    /// store them; `NaN` where no tile lies (a hole) and where the tiles hold voids. The
    /// metadata carries the window's georeference and the dataset's spacing.
    pub fn read_window(&self, window: SampleRect) -> Result<Heightfield> {
        let grid = self.grid();
        if window.col0 > window.col1
            || window.row0 > window.row1
            || window.intersect(&grid) != Some(window)
        {
            return Err(Error::InvalidArgument(format!(
                "window {},{},{},{} is not inside the dataset 0,0,{},{}",
                window.col0, window.row0, window.col1, window.row1, grid.col1, grid.row1
            )));
        }
        let (w, h) = (window.col1 - window.col0 + 1, window.row1 - window.row0 + 1);
        crate::heightfield::check_dimensions(w, h)?;
        let mut samples = vec![f32::NAN; (w * h) as usize];
        for tile in self.tiles_meeting(&window)? {
            let Some(part) = tile.rect().intersect(&window) else {
                continue;
            };
            let store = self.open_tile(&tile)?;
            let t = tile.rect();
            let local = SampleRect {
                col0: part.col0 - t.col0,
                row0: part.row0 - t.row0,
                col1: part.col1 - t.col0,
                row1: part.row1 - t.row0,
            };
            let hf = store.read_window(local)?;
            let pw = (part.col1 - part.col0 + 1) as usize;
            for (y, row) in hf.samples().chunks_exact(pw).enumerate() {
                let dy = (part.row0 - window.row0) as usize + y;
                let dx = (part.col0 - window.col0) as usize;
                let at = dy * w as usize + dx;
                samples[at..at + pw].copy_from_slice(row);
            }
        }
        let metadata = Metadata {
            spacing_m: self.spacing_m(),
            georeference: self.georeference().map(|g| Georeference {
                crs: g.crs,
                origin: [
                    g.origin[0] + window.col0 as f64 * g.step[0],
                    g.origin[1] + window.row0 as f64 * g.step[1],
                ],
                step: g.step,
            }),
            units: None,
            source_format: "fmrh-dataset".into(),
        };
        Ok(Heightfield::new(w as u32, h as u32, samples)?.with_metadata(metadata))
    }
}
