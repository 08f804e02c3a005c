//! A dataset opened for reading: its manifest's state, the tiles a window meets, and the
//! tiles' containers opened at their pinned states as they are needed (`format-spec/dataset.md`
//! §4). Opening reads the manifest's slots and head and no tile; a window reads the tile
//! pages whose rectangles it meets and opens only the tiles it meets.

use std::path::{Path, PathBuf};
use std::sync::{Arc, Mutex};

use super::manifest::{pages_meeting, ManifestState, MANIFEST_NAME};
use crate::error::{Error, Result};
use crate::geoid::VerticalDatum;
use crate::format::manifest::{StatePin, TileRecord};
use crate::heightfield::{Georeference, Heightfield, Metadata};
use crate::model::SampleRect;
use crate::store::{is_url, AnySource, Counted, ReadStats, Source, Store};

/// Tile containers a dataset keeps open at once; the least recently used is closed first.
pub const OPEN_TILES: usize = 64;

/// The bytes of decoded ancestors each open tile keeps (a container alone keeps
/// [`crate::store::ANCESTOR_CACHE_BYTES`]): 4 MiB, so [`OPEN_TILES`] tiles hold at most
/// 256 MiB of them, about 240 grids of 65² a tile.
pub const TILE_ANCESTOR_BYTES: u64 = 4 << 20;

/// Tiles a remote dataset works on at once (opening, scheduling, loading), each over its
/// own connections, so that their network rounds overlap. Local tiles go one at a time.
pub const TILE_WORKERS: usize = 64;

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
    src: Counted<AnySource>,
    state: ManifestState,
    open_reads: ReadStats,
    tiles: Mutex<Vec<(u64, Arc<Store<AnySource>>)>>,
    tiles_opened: std::sync::atomic::AtomicU64,
}

/// Whether `path` is a dataset: a directory holding a `MANIFEST`, or a URL that ends with
/// `/` or `/MANIFEST` (a remote dataset: its tiles lie beside the manifest).
pub fn is_dataset(path: &Path) -> bool {
    match path.to_str().filter(|t| is_url(t)) {
        Some(url) => url.ends_with('/') || url.ends_with(&format!("/{MANIFEST_NAME}")),
        None => path.is_dir() && path.join(MANIFEST_NAME).is_file(),
    }
}

/// The directory part of a dataset URL: without `/MANIFEST` or the trailing `/`.
fn dataset_base(url: &str) -> &str {
    let url = url.strip_suffix(MANIFEST_NAME).unwrap_or(url);
    url.trim_end_matches('/')
}

impl Dataset {
    /// Opens the dataset in directory `dir`: reads its manifest's slots and head. `dir` may
    /// be a URL (`http://`, `https://`, `s3://`, with the `remote` feature): the manifest is
    /// `DIR/MANIFEST` and each tile `DIR/NAME`, read with range requests; the manifest pins
    /// each tile's state, so a tile replaced on the server fails its pin.
    pub fn open(dir: &Path) -> Result<Dataset> {
        let (dir, path) = match dir.to_str().filter(|t| is_url(t)) {
            Some(url) => {
                let base = dataset_base(url);
                (
                    PathBuf::from(base),
                    PathBuf::from(format!("{base}/{MANIFEST_NAME}")),
                )
            }
            None => {
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
                (dir.to_path_buf(), path)
            }
        };
        let src = Counted::new(AnySource::open(&path)?);
        let state = ManifestState::read(&src)?;
        let open_reads = src.stats();
        Ok(Dataset {
            dir,
            src,
            state,
            open_reads,
            tiles: Mutex::new(Vec::new()),
            tiles_opened: 0.into(),
        })
    }

    /// The manifest, as this dataset reads it.
    pub(crate) fn manifest_source(&self) -> &Counted<AnySource> {
        &self.src
    }

    /// Bytes in the manifest file.
    pub fn manifest_len(&self) -> u64 {
        self.src.len()
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

    /// Its first tile in manifest order, reading one tile page; `None` for a dataset of no
    /// tiles.
    pub fn first_tile(&self) -> Result<Option<Tile>> {
        if self.state.head.pages.is_empty() {
            return Ok(None);
        }
        Ok(self.state.page(&self.src, 0)?.first().map(|record| Tile {
            index: u64::from(self.state.head.pages[0].first_tile.get()),
            record: *record,
        }))
    }

    /// What the heights are above: as the manifest records it, or (a manifest before 1.1)
    /// its first tile's datum, opening that tile (`dataset build` and `add` keep a
    /// dataset's tiles to one); unknown for a dataset of no tiles.
    pub fn vertical_datum(&self) -> Result<VerticalDatum> {
        if let Some(datum) = self.state.vertical_datum() {
            return Ok(datum);
        }
        match self.first_tile()? {
            Some(tile) => Ok(self.open_tile(&tile)?.header().metadata.vertical_datum),
            None => Ok(VerticalDatum::Unknown),
        }
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
        let pages = pages_meeting(&self.state.head, rect);
        self.state.fetch_pages(&self.src, &pages)?;
        for p in pages {
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
        let pages: Vec<usize> = (0..self.state.head.pages.len()).collect();
        self.state.fetch_pages(&self.src, &pages)?;
        for p in pages {
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

    /// The path of a tile's file (its URL, for a remote dataset).
    pub fn tile_path(&self, tile: &Tile) -> PathBuf {
        match self.dir.to_str().filter(|t| is_url(t)) {
            Some(base) => PathBuf::from(format!("{base}/{}", tile.name())),
            None => self.dir.join(tile.name()),
        }
    }

    /// Whether the dataset is read from a URL.
    pub fn is_remote(&self) -> bool {
        self.src.inner().is_remote()
    }

    /// What the dataset has asked its servers for, when it is remote: the manifest's
    /// requests and those of every tile opened so far (tiles closed since are not counted).
    /// Tiles work [`TILE_WORKERS`] at a time, so the rounds are the manifest's plus, for
    /// each wave of that many tiles, the most any tile took: a bound on the critical path.
    pub fn request_stats(&self) -> Option<crate::store::RequestStats> {
        let manifest = self.src.request_stats()?;
        let mut sum = crate::store::RequestStats::default();
        let mut slowest = 0;
        let mut count = 0;
        if let Ok(open) = self.tiles.lock() {
            for (_, store) in open.iter() {
                if let Some(r) = store.source().request_stats() {
                    sum = sum.plus(&r);
                    slowest = slowest.max(r.rounds);
                    count += 1;
                }
            }
        }
        sum.rounds = slowest * (count as u64).div_ceil(TILE_WORKERS as u64);
        Some(manifest.plus(&sum))
    }

    /// `job` for each of `tiles`, in order: one after another when the dataset is local,
    /// [`TILE_WORKERS`] at a time when it is remote.
    pub(crate) fn for_tiles<T: Send>(
        &self,
        tiles: &[Tile],
        job: impl Fn(&Tile) -> Result<T> + Sync,
    ) -> Result<Vec<T>> {
        if !self.is_remote() || tiles.len() < 2 {
            return tiles.iter().map(job).collect();
        }
        crate::store::workers::run_bounded(tiles, TILE_WORKERS, job)
            .ok_or_else(|| Error::Internal("a tile job did not run".into()))?
            .into_iter()
            .collect()
    }

    /// The tile's container at its pinned state, opened on first use and kept among the
    /// [`OPEN_TILES`] most recently used.
    pub fn open_tile(&self, tile: &Tile) -> Result<Arc<Store<AnySource>>> {
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
        let store = self.open_tile_uncached(tile)?;
        // Its share of the decoded ancestors a dataset keeps: the budget of one container
        // over the tiles it may keep open, so that they hold at most that many bytes.
        store.set_ancestor_budget(TILE_ANCESTOR_BYTES);
        let store = Arc::new(store);
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
    pub fn open_tile_uncached(&self, tile: &Tile) -> Result<Store<AnySource>> {
        let path = self.tile_path(tile);
        let opened = AnySource::open_tile(&path, Some(self.manifest_source().inner()))
            .and_then(|src| Store::open_pinned_source(src, tile.pin()));
        let remote = self.is_remote();
        let store = match opened {
            Ok(s) => s,
            Err(e @ Error::Corrupt { .. }) => return Err(self.moved_on(e)),
            // A tile replaced by a newer dataset state has its file removed.
            Err(e @ Error::Io { .. }) if !remote && !path.exists() => return Err(self.moved_on(e)),
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

    /// `e`, or `Superseded` when a newer dataset state has been published since this one,
    /// or `Changed` when the manifest no longer publishes this state and no newer one took
    /// its place (the dataset was replaced underneath: a re-upload, a copy over it).
    pub(crate) fn moved_on(&self, e: Error) -> Error {
        use crate::store::slots::SlotsNow;
        match super::manifest::slots_now(&self.src, &self.state.record) {
            // A remote manifest replaced on the server: the reader's version is gone.
            Err(changed @ (Error::Io { .. } | Error::Changed { .. })) if self.is_remote() => {
                changed
            }
            Ok(SlotsNow::Latest { txn: latest, .. }) if latest > self.txn_id() => {
                Error::Superseded {
                    path: self.dir.clone(),
                    txn: self.txn_id(),
                    latest,
                    detail: format!("a tile moved on with the newer dataset state: {e}"),
                }
            }
            Ok(SlotsNow::Latest {
                still_published: false,
                ..
            }) => Error::Changed {
                path: self.dir.clone(),
                detail: format!(
                    "the manifest no longer publishes the state this reader opened (txn {}), \
                     and no newer state does; then: {e}",
                    self.txn_id()
                ),
            },
            _ => e,
        }
    }

    /// The samples of `window` (dataset coordinates, inclusive), bit for bit as the tiles
    /// store them; `NaN` where no tile lies (a hole) and where the tiles hold voids. The
    /// metadata carries the window's georeference and the dataset's spacing.
    pub fn read_window(&self, window: SampleRect) -> Result<Heightfield> {
        let grid = self.grid();
        window.check_inside(&grid, "dataset")?;
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
            vertical_datum: self.vertical_datum()?,
        };
        Ok(Heightfield::new(w as u32, h as u32, samples)?.with_metadata(metadata))
    }
}
