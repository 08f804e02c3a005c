//! Writing a whole pyramid once, for static hosting: every tile of a zoom range (within a
//! longitude and latitude box, if given) cut on every core and written, in PMTiles id
//! order, to a directory of `z/x/y.ext` files or to one PMTiles archive
//! (`crate::export::pmtiles`).
//!
//! **What is written.** Exactly the tiles `fmrh serve` answers with `200` for the same
//! state and options, with the bytes it sends: a directory holds them as sent without a
//! content encoding (quantized-mesh with the `octvertexnormals` and `metadata`
//! extensions, PNGs), with the server's `layer.json` (quantized-mesh) or `tilejson.json`
//! (terrain-RGB) beside them; an archive holds quantized-mesh tiles gzipped as the server
//! sends them to a client that accepts gzip (its header says gzip, so a client inflates
//! them or passes `Content-Encoding: gzip` on) and PNGs as they are, with that JSON as its
//! metadata. A geodetic level `z` is kept at the archive's zoom `z + 1`
//! ([`TileAddress::pmtiles_zxy`]).
//!
//! **Atomic.** Output appears under its name only when complete (a temporary file or
//! directory beside it, renamed into place; `crate::store::write`); an existing one is
//! replaced only when the caller says so. An interrupted export leaves nothing behind but
//! the temporary (removed on a signal, or by the next export's clean-up of files nobody
//! holds).

use std::path::{Path, PathBuf};

use rayon::prelude::*;
use serde_json::Value;

use super::{Pyramid, TileAddress};
use crate::export::pmtiles::{self, ArchiveInfo, ArchiveStats, Compression, TileType};
use crate::progress::{Phase, Progress, Unit};
use crate::{Error, Result};

/// Which tiles to write.
#[derive(Clone, Debug)]
pub struct Selection {
    /// The zooms, inclusive (clipped to the pyramid's).
    pub zooms: std::ops::RangeInclusive<u8>,
    /// `[west, south, east, north]`, degrees: only tiles meeting it.
    pub bbox: Option<[f64; 4]>,
}

/// Where the pyramid goes.
#[derive(Clone, Debug, PartialEq, Eq)]
pub enum Destination {
    /// A directory of `z/x/y.ext` files and the JSON description.
    Directory(PathBuf),
    /// One PMTiles v3 archive.
    Pmtiles(PathBuf),
}

impl Destination {
    /// An archive when `path` ends in `.pmtiles`, else a directory.
    pub fn of(path: &Path) -> Destination {
        if path
            .extension()
            .is_some_and(|e| e.eq_ignore_ascii_case("pmtiles"))
        {
            Destination::Pmtiles(path.to_path_buf())
        } else {
            Destination::Directory(path.to_path_buf())
        }
    }
}

/// What an export wrote.
#[derive(Clone, Debug, Default)]
pub struct Exported {
    /// Tiles written, per zoom (the pyramid's zooms, not the archive's).
    pub per_zoom: Vec<(u8, u64)>,
    /// Bytes of the tiles as written, counted once per address (an archive stores
    /// repeated contents once).
    pub tile_bytes: u64,
    /// Bytes of the archive, or of every file in the directory.
    pub bytes: u64,
    /// The archive's counts, for an archive.
    pub archive: Option<ArchiveStats>,
}

impl Exported {
    /// Tiles written.
    pub fn tiles(&self) -> u64 {
        self.per_zoom.iter().map(|(_, n)| n).sum()
    }
}

/// The tiles `selection` picks from `pyramid`, in the order they are written (rising
/// PMTiles id: zoom by zoom, each along its Hilbert curve).
pub fn plan(pyramid: &Pyramid, selection: &Selection) -> Result<Vec<TileAddress>> {
    let (lo, hi) = (*selection.zooms.start(), *selection.zooms.end());
    if lo > hi {
        return Err(Error::InvalidArgument(format!(
            "zooms {lo}..={hi}: the first is past the last"
        )));
    }
    if lo > pyramid.maxzoom() {
        return Err(Error::InvalidArgument(format!(
            "zooms {lo}..={hi}: the pyramid's deepest zoom is {}",
            pyramid.maxzoom()
        )));
    }
    if let Some([w, s, e, n]) = selection.bbox {
        if !(w < e && s < n && w >= -180.0 && e <= 180.0 && s >= -90.0 && n <= 90.0) {
            return Err(Error::InvalidArgument(format!(
                "bbox {w},{s},{e},{n}: expected WEST,SOUTH,EAST,NORTH in degrees, west < east, \
                 south < north"
            )));
        }
    }
    let mut tiles: Vec<(u64, TileAddress)> = Vec::new();
    for z in lo..=hi.min(pyramid.maxzoom()) {
        for t in pyramid.tiles(z, selection.bbox) {
            let (pz, px, py) = t.pmtiles_zxy();
            tiles.push((pmtiles::tile_id(pz, px, py)?, t));
        }
    }
    tiles.sort_by_key(|(id, _)| *id);
    Ok(tiles.into_iter().map(|(_, t)| t).collect())
}

/// The description written beside `tiles` (or as an archive's metadata): the pyramid's
/// `layer.json` or TileJSON (`name`, `version`, tile addresses `template`), narrowed to
/// what `selection` keeps when it keeps less than the whole pyramid (the zooms exported,
/// each zoom's rectangle of tiles in `available`, the box), so that a client asks only for
/// tiles that are there. A narrowed `layer.json` drops `metadataAvailability`: the tiles'
/// own metadata lists the whole pyramid, as the server's do. An archive's has no `tiles`
/// (its client makes its own addresses) and says where Cesium's levels are kept.
pub fn describe(
    pyramid: &Pyramid,
    name: &str,
    version: &str,
    template: Option<&str>,
    selection: &Selection,
    tiles: &[TileAddress],
    destination: &Destination,
) -> Value {
    let mut d = pyramid.tilejson(name, version, template);
    let mesh = pyramid.extension() == "terrain";
    let whole = selection.bbox.is_none()
        && *selection.zooms.start() == 0
        && *selection.zooms.end() >= pyramid.maxzoom();
    if !whole {
        let mut rects: std::collections::BTreeMap<u8, (u32, u32, u32, u32)> = Default::default();
        for t in tiles {
            let (z, x, y) = t.zxy();
            let r = rects.entry(z).or_insert((x, y, x, y));
            *r = (r.0.min(x), r.1.min(y), r.2.max(x), r.3.max(y));
        }
        let lo = rects.keys().next().copied().unwrap_or(0);
        let hi = rects.keys().last().copied().unwrap_or(0);
        d["minzoom"] = lo.into();
        d["maxzoom"] = hi.into();
        if let Some([w, s, e, n]) = selection.bbox {
            if let Some(b) = d["bounds"].as_array().cloned() {
                let b: Vec<f64> = b.iter().filter_map(Value::as_f64).collect();
                if let [bw, bs, be, bn] = b.as_slice() {
                    d["bounds"] = serde_json::json!([bw.max(w), bs.max(s), be.min(e), bn.min(n)]);
                }
            }
        }
        if mesh {
            d["available"] = (0..=hi)
                .map(|z| match rects.get(&z) {
                    Some(&(x0, y0, x1, y1)) => {
                        serde_json::json!([{ "startX": x0, "startY": y0, "endX": x1, "endY": y1 }])
                    }
                    None => serde_json::json!([]),
                })
                .collect();
            if let Some(o) = d.as_object_mut() {
                o.remove("metadataAvailability");
            }
        }
        d["fmrh"]["exported"] = serde_json::json!({
            "zooms": [lo, hi],
            "bbox": selection.bbox,
            "note": "a part of the pyramid: only these tiles are here",
        });
    }
    if let Destination::Pmtiles(_) = destination {
        if let Some(o) = d.as_object_mut() {
            o.remove("tiles");
        }
        if mesh {
            d["fmrh"]["pmtiles_zoom"] = "Cesium level z is kept at PMTiles zoom z + 1, with \
                Cesium's x and y (TMS: y from the south); tiles are gzipped"
                .into();
        }
    }
    d
}

/// Cuts `tiles` (in [`plan`]'s order) on every core and writes them to `destination`, with
/// `description` (the pyramid's `layer.json` or TileJSON) beside them or as the archive's
/// metadata; `overwrite` replaces an existing destination. Progress counts tiles.
pub fn export(
    pyramid: &Pyramid,
    tiles: &[TileAddress],
    description: &Value,
    destination: &Destination,
    overwrite: bool,
    progress: &dyn Progress,
) -> Result<Exported> {
    if tiles.is_empty() {
        return Err(Error::InvalidArgument(
            "no tiles to write: the zooms and box select none of the data's".into(),
        ));
    }
    let mesh = pyramid.extension() == "terrain";
    match destination {
        Destination::Directory(path) => crate::store::write::write_dir_atomically(path, overwrite, |dir| {
            let name = if mesh { "layer.json" } else { "tilejson.json" };
            let json = serde_json::to_vec_pretty(description)
                .map_err(|e| Error::InvalidArgument(format!("{name}: {e}")))?;
            let at = dir.join(name);
            std::fs::write(&at, &json).map_err(|e| Error::io(&at, e))?;
            let ext = pyramid.extension();
            let mut out = cut_all(pyramid, tiles, progress, |t, bytes| {
                let (z, x, y) = t.zxy();
                let column = dir.join(z.to_string()).join(x.to_string());
                std::fs::create_dir_all(&column).map_err(|e| Error::io(&column, e))?;
                let file = column.join(format!("{y}.{ext}"));
                std::fs::write(&file, &bytes).map_err(|e| Error::io(&file, e))?;
                Ok(bytes.len() as u64)
            })?;
            out.bytes = out.tile_bytes + json.len() as u64;
            Ok(out)
        }),
        Destination::Pmtiles(path) => {
            let dir = match path.parent() {
                Some(d) if !d.as_os_str().is_empty() => d,
                _ => Path::new("."),
            };
            let mut writer = pmtiles::Writer::new(dir)?;
            let mut out = cut_all(pyramid, tiles, progress, |t, bytes| {
                let (z, x, y) = t.pmtiles_zxy();
                let stored = if mesh { super::gzip(&bytes)? } else { bytes };
                writer.put(z, x, y, &stored)?;
                Ok(stored.len() as u64)
            })?;
            let info = ArchiveInfo {
                tile_compression: if mesh {
                    Compression::Gzip
                } else {
                    Compression::None
                },
                tile_type: if mesh { TileType::Unknown } else { TileType::Png },
                bounds: pyramid.bounds(),
                center_zoom: tiles
                    .iter()
                    .map(|t| t.pmtiles_zxy().0)
                    .min()
                    .unwrap_or(0),
                metadata: description.clone(),
            };
            let stats = crate::store::write::write_atomically(path, overwrite, |w| {
                writer.finish(&info, w)
            })?;
            out.bytes = stats.bytes;
            out.archive = Some(stats);
            Ok(out)
        }
    }
}

/// Cuts `tiles` in order, a batch at a time on every core, handing each tile's bytes to
/// `put` in order; counts what `put` says it stored.
fn cut_all(
    pyramid: &Pyramid,
    tiles: &[TileAddress],
    progress: &dyn Progress,
    mut put: impl FnMut(TileAddress, Vec<u8>) -> Result<u64>,
) -> Result<Exported> {
    let phase = Phase::start(progress, "cutting tiles", tiles.len() as u64, Unit::Steps);
    // Enough tiles a batch to keep every core busy past one slow tile, few enough that the
    // batch's bytes stay small.
    let batch = 8 * rayon::current_num_threads().max(1);
    let mut out = Exported::default();
    for chunk in tiles.chunks(batch) {
        let cut: Vec<Result<Vec<u8>>> = chunk.par_iter().map(|&t| pyramid.tile(t)).collect();
        for (&t, bytes) in chunk.iter().zip(cut) {
            let bytes = bytes?;
            out.tile_bytes += put(t, bytes)?;
            let z = t.zxy().0;
            match out.per_zoom.last_mut() {
                Some((lz, n)) if *lz == z => *n += 1,
                _ => out.per_zoom.push((z, 1)),
            }
        }
        progress.advance(chunk.len() as u64);
    }
    drop(phase);
    Ok(out)
}
