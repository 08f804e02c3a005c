//! PMTiles version 3: one file holding a whole tile pyramid, read by web maps through HTTP
//! range requests (the `pmtiles` JavaScript protocol for MapLibre, the `pmtiles` Python
//! package, GDAL). This module writes archives ([`Writer`]) and reads them back
//! ([`Archive`]); it knows nothing of terrain, only tiles as bytes addressed by `z/x/y`.
//!
//! **The layout** (little-endian; <https://github.com/protomaps/PMTiles/blob/main/spec/v3/spec.md>):
//!
//! ```text
//!   0          127                 +root            +metadata        +leaves
//!   | header   | root directory    | JSON metadata  | leaf dirs      | tile data ...
//!   | 127 B    | gzip, < 16 KiB    | gzip           | gzip each      | clustered
//! ```
//!
//! A tile's **id** is its place on a series of Hilbert curves, one per zoom: all tiles of
//! zoom `z` come after those of every coarser zoom ([`tile_id`]). A **directory** lists
//! entries `(tile id, offset, length, run length)` in rising id order, stored column by
//! column as varints (ids as deltas, an offset as 0 when it follows the previous entry's
//! bytes) and gzipped. An entry with run length 0 points at a leaf directory instead of a
//! tile. The header and the root directory together fit the first 16,384 bytes, so a
//! client's first request gets both; past that, entries move into leaves
//! ([`Writer::finish`] doubles the leaf size until the root fits).
//!
//! **What this writer does.** Tiles come in rising id order and their bytes go to a
//! temporary file as they come, in that order (the archive is *clustered*). A tile whose
//! bytes equal an earlier one's is stored once (compared byte for byte, not by hash), and
//! consecutive ids with the same bytes share one entry (its run length). Nothing is
//! written under the archive's name here: [`Writer::finish`] writes the whole archive to a
//! `Write` the caller chose (the CLI's is a temporary file renamed into place when
//! complete).

use std::collections::HashMap;
use std::hash::{Hash, Hasher};
use std::io::{Read, Seek, SeekFrom, Write};

use serde_json::Value;

use crate::error::{Error, Result};

/// The 7-byte magic every archive starts with, then the version byte.
pub const MAGIC: &[u8; 7] = b"PMTiles";
/// The spec version written and read.
pub const VERSION: u8 = 3;
/// Bytes of the fixed header.
pub const HEADER_LEN: usize = 127;
/// The header and the root directory together stay within this many bytes.
pub const ROOT_LIMIT: usize = 16_384;
/// The deepest zoom a 64-bit tile id holds.
pub const MAX_ZOOM: u8 = 31;

/// Header field offsets.
const ROOT_OFFSET: usize = 8;
const METADATA_OFFSET: usize = 24;
const LEAVES_OFFSET: usize = 40;
const DATA_OFFSET: usize = 56;
const ADDRESSED_TILES: usize = 72;
const TILE_ENTRIES: usize = 80;
const TILE_CONTENTS: usize = 88;
const CLUSTERED: usize = 96;
const INTERNAL_COMPRESSION: usize = 97;
const TILE_COMPRESSION: usize = 98;
const TILE_TYPE: usize = 99;
const MIN_ZOOM: usize = 100;
const MAX_ZOOM_AT: usize = 101;
const BOUNDS: usize = 102;
const CENTER_ZOOM: usize = 118;
const CENTER: usize = 119;

/// How tiles (or the directories and metadata) are compressed.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Compression {
    /// Stored as they are.
    None = 1,
    /// gzip.
    Gzip = 2,
}

/// What the tiles are, as the header's tile type says.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum TileType {
    /// Anything else (quantized-mesh terrain).
    Unknown = 0,
    /// PNG images.
    Png = 2,
}

/// The tile id of `z/x/y` (`x`, `y` below `2^z`): the tiles of every coarser zoom, then the
/// tile's distance along zoom `z`'s Hilbert curve.
pub fn tile_id(z: u8, x: u32, y: u32) -> Result<u64> {
    if z > MAX_ZOOM || u64::from(x) >> z != 0 || u64::from(y) >> z != 0 {
        return Err(Error::InvalidArgument(format!(
            "tile {z}/{x}/{y} is not a PMTiles tile (zoom 0..={MAX_ZOOM}, x and y below 2^zoom)"
        )));
    }
    let (mut x, mut y) = (u64::from(x), u64::from(y));
    let mut id = ((1u64 << (2 * u32::from(z))) - 1) / 3;
    for a in (0..u32::from(z)).rev() {
        let s = 1u64 << a;
        let rx = u64::from(x & s != 0);
        let ry = u64::from(y & s != 0);
        id += ((3 * rx) ^ ry) << (2 * a);
        // Rotate the quadrant so the curve's next level runs the same way.
        x &= s - 1;
        y &= s - 1;
        if ry == 0 {
            if rx == 1 {
                x = s - 1 - x;
                y = s - 1 - y;
            }
            std::mem::swap(&mut x, &mut y);
        }
    }
    Ok(id)
}

/// The `z/x/y` of tile id `id` (the inverse of [`tile_id`]).
#[cfg(any(test, feature = "testing"))]
pub fn tile_of(id: u64) -> Result<(u8, u32, u32)> {
    let mut z = 0u8;
    let mut first = 0u64;
    loop {
        if z > MAX_ZOOM {
            return Err(Error::InvalidArgument(format!(
                "tile id {id} is past zoom {MAX_ZOOM}"
            )));
        }
        let count = 1u64 << (2 * u32::from(z));
        if id - first < count {
            break;
        }
        first += count;
        z += 1;
    }
    let mut t = id - first;
    let (mut x, mut y) = (0u64, 0u64);
    let mut s = 1u64;
    while s < 1u64 << z {
        let rx = 1 & (t / 2);
        let ry = 1 & (t ^ rx);
        if ry == 0 {
            if rx == 1 {
                x = s - 1 - x;
                y = s - 1 - y;
            }
            std::mem::swap(&mut x, &mut y);
        }
        x += s * rx;
        y += s * ry;
        t /= 4;
        s *= 2;
    }
    Ok((z, x as u32, y as u32))
}

/// One directory entry.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
struct Entry {
    tile_id: u64,
    offset: u64,
    length: u32,
    /// How many consecutive ids share the bytes; 0: `offset` and `length` name a leaf.
    run_length: u32,
}

/// What [`Writer::finish`] needs besides the tiles.
#[derive(Clone, Debug)]
pub struct ArchiveInfo {
    /// How the tiles' bytes are compressed (as given to [`Writer::put`]).
    pub tile_compression: Compression,
    /// What the tiles are.
    pub tile_type: TileType,
    /// `[west, south, east, north]`, degrees.
    pub bounds: [f64; 4],
    /// The zoom a viewer starts at.
    pub center_zoom: u8,
    /// The JSON metadata (stored gzipped).
    pub metadata: Value,
}

/// What an archive holds, as [`Writer::finish`] counted it.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct ArchiveStats {
    /// Tiles addressed (the run lengths' sum).
    pub addressed: u64,
    /// Directory entries pointing at tiles.
    pub entries: u64,
    /// Distinct tile contents stored.
    pub contents: u64,
    /// Leaf directories.
    pub leaves: u64,
    /// Bytes of the whole archive.
    pub bytes: u64,
}

/// Writes an archive: tiles in rising id order ([`Writer::put`]), then [`Writer::finish`].
pub struct Writer {
    /// The tile data section, in the order written.
    data: std::io::BufWriter<std::fs::File>,
    data_len: u64,
    entries: Vec<Entry>,
    /// Stored contents by (hash, length): their offsets (compared byte for byte on a hit).
    stored: HashMap<(u64, u32), Vec<u64>>,
    contents: u64,
    min_zoom: u8,
    max_zoom: u8,
}

impl Writer {
    /// A writer whose tile data waits in an unnamed temporary file in `dir` (removed by
    /// the system however the process ends).
    pub fn new(dir: &std::path::Path) -> Result<Writer> {
        let file = tempfile::tempfile_in(dir).map_err(|e| Error::io(dir, e))?;
        Ok(Writer {
            data: std::io::BufWriter::with_capacity(1 << 20, file),
            data_len: 0,
            entries: Vec::new(),
            stored: HashMap::new(),
            contents: 0,
            min_zoom: u8::MAX,
            max_zoom: 0,
        })
    }

    /// Adds tile `z/x/y` with `bytes` (not empty). Ids must rise from one call to the next.
    pub fn put(&mut self, z: u8, x: u32, y: u32, bytes: &[u8]) -> Result<()> {
        let id = tile_id(z, x, y)?;
        let length = u32::try_from(bytes.len())
            .ok()
            .filter(|&n| n > 0)
            .ok_or_else(|| {
                Error::InvalidArgument(format!(
                    "tile {z}/{x}/{y}: {} bytes (a PMTiles tile holds 1 to 2^32 - 1)",
                    bytes.len()
                ))
            })?;
        if let Some(last) = self.entries.last() {
            if id < last.tile_id + u64::from(last.run_length) {
                return Err(Error::InvalidArgument(format!(
                    "tile {z}/{x}/{y} (id {id}) comes after id {}: tiles must come in rising id order",
                    last.tile_id
                )));
            }
        }
        self.min_zoom = self.min_zoom.min(z);
        self.max_zoom = self.max_zoom.max(z);
        let mut h = std::collections::hash_map::DefaultHasher::new();
        bytes.hash(&mut h);
        let key = (h.finish(), length);
        let offset = match self.stored_at(key, bytes)? {
            Some(o) => o,
            None => {
                let o = self.data_len;
                self.data
                    .write_all(bytes)
                    .map_err(|e| Error::io("PMTiles tile data (temporary file)", e))?;
                self.data_len += u64::from(length);
                self.stored.entry(key).or_default().push(o);
                self.contents += 1;
                o
            }
        };
        if let Some(last) = self.entries.last_mut() {
            if last.offset == offset
                && last.length == length
                && last.tile_id + u64::from(last.run_length) == id
                && last.run_length < u32::MAX
            {
                last.run_length += 1;
                return Ok(());
            }
        }
        self.entries.push(Entry {
            tile_id: id,
            offset,
            length,
            run_length: 1,
        });
        Ok(())
    }

    /// The offset of contents already stored equal to `bytes` (whose hash and length are
    /// `key`), if any.
    fn stored_at(&mut self, key: (u64, u32), bytes: &[u8]) -> Result<Option<u64>> {
        let Some(offsets) = self.stored.get(&key) else {
            return Ok(None);
        };
        let offsets = offsets.clone();
        let io = |e| Error::io("PMTiles tile data (temporary file)", e);
        self.data.flush().map_err(io)?;
        let file = self.data.get_mut();
        let mut seen = vec![0u8; bytes.len()];
        let mut found = None;
        for o in offsets {
            file.seek(SeekFrom::Start(o)).map_err(io)?;
            file.read_exact(&mut seen).map_err(io)?;
            if seen == bytes {
                found = Some(o);
                break;
            }
        }
        file.seek(SeekFrom::End(0)).map_err(io)?;
        Ok(found)
    }

    /// Tiles put so far (the run lengths' sum).
    pub fn addressed(&self) -> u64 {
        self.entries.iter().map(|e| u64::from(e.run_length)).sum()
    }

    /// Writes the whole archive to `out`: header, root directory, metadata, leaves, tiles.
    pub fn finish(mut self, info: &ArchiveInfo, out: &mut impl Write) -> Result<ArchiveStats> {
        if self.entries.is_empty() {
            return Err(Error::InvalidArgument(
                "no tiles: a PMTiles archive holds at least one".into(),
            ));
        }
        let (root, leaves, n_leaves) = directories(&self.entries)?;
        let metadata = gzip(
            &serde_json::to_vec(&info.metadata)
                .map_err(|e| Error::InvalidArgument(format!("PMTiles metadata: {e}")))?,
        )?;
        let root_at = HEADER_LEN as u64;
        let metadata_at = root_at + root.len() as u64;
        let leaves_at = metadata_at + metadata.len() as u64;
        let data_at = leaves_at + leaves.len() as u64;
        let mut h = [0u8; HEADER_LEN];
        h[..7].copy_from_slice(MAGIC);
        h[7] = VERSION;
        let mut put64 = |at: usize, v: u64| h[at..at + 8].copy_from_slice(&v.to_le_bytes());
        put64(ROOT_OFFSET, root_at);
        put64(ROOT_OFFSET + 8, root.len() as u64);
        put64(METADATA_OFFSET, metadata_at);
        put64(METADATA_OFFSET + 8, metadata.len() as u64);
        put64(LEAVES_OFFSET, leaves_at);
        put64(LEAVES_OFFSET + 8, leaves.len() as u64);
        put64(DATA_OFFSET, data_at);
        put64(DATA_OFFSET + 8, self.data_len);
        let addressed = self.addressed();
        put64(ADDRESSED_TILES, addressed);
        put64(TILE_ENTRIES, self.entries.len() as u64);
        put64(TILE_CONTENTS, self.contents);
        h[CLUSTERED] = 1;
        h[INTERNAL_COMPRESSION] = Compression::Gzip as u8;
        h[TILE_COMPRESSION] = info.tile_compression as u8;
        h[TILE_TYPE] = info.tile_type as u8;
        h[MIN_ZOOM] = self.min_zoom;
        h[MAX_ZOOM_AT] = self.max_zoom;
        let e7 = |deg: f64| (deg * 1e7).round().clamp(f64::from(i32::MIN), f64::from(i32::MAX)) as i32;
        let [w, s, e, n] = info.bounds;
        for (i, v) in [w, s, e, n].into_iter().enumerate() {
            h[BOUNDS + 4 * i..BOUNDS + 4 * i + 4].copy_from_slice(&e7(v).to_le_bytes());
        }
        h[CENTER_ZOOM] = info.center_zoom.clamp(self.min_zoom, self.max_zoom);
        h[CENTER..CENTER + 4].copy_from_slice(&e7((w + e) / 2.0).to_le_bytes());
        h[CENTER + 4..CENTER + 8].copy_from_slice(&e7((s + n) / 2.0).to_le_bytes());
        let io = |e| Error::io("PMTiles archive", e);
        out.write_all(&h).map_err(io)?;
        out.write_all(&root).map_err(io)?;
        out.write_all(&metadata).map_err(io)?;
        out.write_all(&leaves).map_err(io)?;
        self.data.flush().map_err(io)?;
        let file = self.data.get_mut();
        file.seek(SeekFrom::Start(0)).map_err(io)?;
        let copied = std::io::copy(file, out).map_err(io)?;
        if copied != self.data_len {
            return Err(Error::io(
                "PMTiles tile data (temporary file)",
                std::io::Error::other(format!(
                    "read back {copied} of {} bytes",
                    self.data_len
                )),
            ));
        }
        Ok(ArchiveStats {
            addressed,
            entries: self.entries.len() as u64,
            contents: self.contents,
            leaves: n_leaves,
            bytes: data_at + self.data_len,
        })
    }
}

fn gzip(bytes: &[u8]) -> Result<Vec<u8>> {
    let mut enc = flate2::write::GzEncoder::new(Vec::new(), flate2::Compression::new(6));
    enc.write_all(bytes)
        .and_then(|()| enc.finish())
        .map_err(|e| Error::InvalidArgument(format!("gzip: {e}")))
}

fn put_varint(out: &mut Vec<u8>, mut v: u64) {
    while v >= 0x80 {
        out.push((v as u8 & 0x7f) | 0x80);
        v >>= 7;
    }
    out.push(v as u8);
}

/// A directory's bytes, gzipped.
fn serialize(entries: &[Entry]) -> Result<Vec<u8>> {
    let mut b = Vec::with_capacity(entries.len() * 6 + 8);
    put_varint(&mut b, entries.len() as u64);
    let mut last = 0;
    for e in entries {
        put_varint(&mut b, e.tile_id - last);
        last = e.tile_id;
    }
    for e in entries {
        put_varint(&mut b, u64::from(e.run_length));
    }
    for e in entries {
        put_varint(&mut b, u64::from(e.length));
    }
    for (i, e) in entries.iter().enumerate() {
        let follows = i > 0 && {
            let p = &entries[i - 1];
            e.offset == p.offset + u64::from(p.length)
        };
        put_varint(&mut b, if follows { 0 } else { e.offset + 1 });
    }
    gzip(&b)
}

/// The root directory, the leaf directories' section and how many leaves: all entries in
/// the root when they fit beside the header, else leaves of 4,096 entries, doubled until
/// the root of leaf pointers fits.
fn directories(entries: &[Entry]) -> Result<(Vec<u8>, Vec<u8>, u64)> {
    let limit = ROOT_LIMIT - HEADER_LEN;
    let whole = serialize(entries)?;
    if whole.len() <= limit {
        return Ok((whole, Vec::new(), 0));
    }
    let mut leaf_size = 4096usize;
    loop {
        let mut root = Vec::new();
        let mut leaves = Vec::new();
        for chunk in entries.chunks(leaf_size) {
            let leaf = serialize(chunk)?;
            root.push(Entry {
                tile_id: chunk[0].tile_id,
                offset: leaves.len() as u64,
                length: u32::try_from(leaf.len()).map_err(|_| {
                    Error::InvalidArgument("a PMTiles leaf directory past 4 GiB".into())
                })?,
                run_length: 0,
            });
            leaves.extend_from_slice(&leaf);
        }
        let root_bytes = serialize(&root)?;
        if root_bytes.len() <= limit {
            return Ok((root_bytes, leaves, root.len() as u64));
        }
        leaf_size *= 2;
    }
}

/// A tile read from an archive: `(z, x, y)` and its bytes as stored.
#[cfg(any(test, feature = "testing"))]
pub type StoredTile<'a> = ((u8, u32, u32), &'a [u8]);

/// An archive read from its bytes: header fields, metadata and tiles by address. For
/// fmrh's tests; a damaged archive is an [`Error::Input`] naming what is wrong.
#[cfg(any(test, feature = "testing"))]
pub struct Archive<'a> {
    bytes: &'a [u8],
    name: std::path::PathBuf,
    /// Where each section starts and how long it is.
    root: (u64, u64),
    leaves: (u64, u64),
    data: (u64, u64),
    metadata: (u64, u64),
    /// The header's fields.
    pub tile_compression: u8,
    /// The header's tile type.
    pub tile_type: u8,
    /// Whether the tile data is in id order.
    pub clustered: bool,
    /// The header's zooms.
    pub min_zoom: u8,
    /// The header's deepest zoom.
    pub max_zoom: u8,
    /// `[west, south, east, north]`, degrees.
    pub bounds: [f64; 4],
    /// Tiles addressed, entries and contents, as the header counts them.
    pub counts: [u64; 3],
}

#[cfg(any(test, feature = "testing"))]
impl<'a> Archive<'a> {
    /// Reads the header of the archive `bytes` (named `name` in errors).
    pub fn new(bytes: &'a [u8], name: impl Into<std::path::PathBuf>) -> Result<Archive<'a>> {
        let name = name.into();
        let h = bytes
            .get(..HEADER_LEN)
            .ok_or_else(|| Error::input(&name, "shorter than a PMTiles header (127 bytes)"))?;
        if &h[..7] != MAGIC || h[7] != VERSION {
            return Err(Error::input(&name, "not a PMTiles version 3 archive"));
        }
        let u = |at: usize| {
            let mut b = [0u8; 8];
            b.copy_from_slice(&h[at..at + 8]);
            u64::from_le_bytes(b)
        };
        let deg = |at: usize| {
            let mut b = [0u8; 4];
            b.copy_from_slice(&h[at..at + 4]);
            f64::from(i32::from_le_bytes(b)) / 1e7
        };
        if h[INTERNAL_COMPRESSION] != Compression::Gzip as u8
            && h[INTERNAL_COMPRESSION] != Compression::None as u8
        {
            return Err(Error::unsupported(
                &name,
                format!("internal compression {}", h[INTERNAL_COMPRESSION]),
            ));
        }
        Ok(Archive {
            bytes,
            root: (u(ROOT_OFFSET), u(ROOT_OFFSET + 8)),
            metadata: (u(METADATA_OFFSET), u(METADATA_OFFSET + 8)),
            leaves: (u(LEAVES_OFFSET), u(LEAVES_OFFSET + 8)),
            data: (u(DATA_OFFSET), u(DATA_OFFSET + 8)),
            tile_compression: h[TILE_COMPRESSION],
            tile_type: h[TILE_TYPE],
            clustered: h[CLUSTERED] == 1,
            min_zoom: h[MIN_ZOOM],
            max_zoom: h[MAX_ZOOM_AT],
            bounds: [deg(BOUNDS), deg(BOUNDS + 4), deg(BOUNDS + 8), deg(BOUNDS + 12)],
            counts: [u(ADDRESSED_TILES), u(TILE_ENTRIES), u(TILE_CONTENTS)],
            name,
        })
    }

    fn section(&self, (at, len): (u64, u64), what: &str) -> Result<&'a [u8]> {
        let end = at.checked_add(len);
        end.and_then(|end| {
            self.bytes
                .get(usize::try_from(at).ok()?..usize::try_from(end).ok()?)
        })
        .ok_or_else(|| Error::input(&self.name, format!("{what} lies past the end of the file")))
    }

    fn inflate(&self, bytes: &[u8], what: &str) -> Result<Vec<u8>> {
        let mut out = Vec::new();
        let mut dec = flate2::read::GzDecoder::new(bytes);
        // A directory or the metadata is small; a bomb is cut off rather than followed.
        (&mut dec)
            .take(1 << 28)
            .read_to_end(&mut out)
            .map_err(|e| Error::input(&self.name, format!("{what}: {e}")))?;
        Ok(out)
    }

    /// The JSON metadata.
    pub fn metadata(&self) -> Result<Value> {
        let raw = self.inflate(self.section(self.metadata, "the metadata")?, "the metadata")?;
        serde_json::from_slice(&raw)
            .map_err(|e| Error::input(&self.name, format!("the metadata is not JSON: {e}")))
    }

    fn directory(&self, bytes: &[u8]) -> Result<Vec<Entry>> {
        let raw = self.inflate(bytes, "a directory")?;
        let bad = || Error::input(&self.name, "a directory is truncated or malformed");
        let mut at = 0usize;
        let mut next = || -> Result<u64> {
            let mut v = 0u64;
            for shift in (0..64).step_by(7) {
                let b = *raw.get(at).ok_or_else(bad)?;
                at += 1;
                v |= u64::from(b & 0x7f) << shift;
                if b & 0x80 == 0 {
                    return Ok(v);
                }
            }
            Err(bad())
        };
        let n = usize::try_from(next()?).map_err(|_| bad())?;
        if n > raw.len() {
            return Err(bad());
        }
        let mut entries = vec![
            Entry {
                tile_id: 0,
                offset: 0,
                length: 0,
                run_length: 0
            };
            n
        ];
        let mut id = 0u64;
        for e in entries.iter_mut() {
            id = id.checked_add(next()?).ok_or_else(bad)?;
            e.tile_id = id;
        }
        for e in entries.iter_mut() {
            e.run_length = u32::try_from(next()?).map_err(|_| bad())?;
        }
        for e in entries.iter_mut() {
            e.length = u32::try_from(next()?).map_err(|_| bad())?;
        }
        for i in 0..n {
            let v = next()?;
            entries[i].offset = if v == 0 && i > 0 {
                entries[i - 1].offset + u64::from(entries[i - 1].length)
            } else {
                v.checked_sub(1).ok_or_else(bad)?
            };
        }
        Ok(entries)
    }

    /// Every tile: `(z, x, y)` and its bytes as stored, in id order.
    pub fn tiles(&self) -> Result<Vec<StoredTile<'a>>> {
        let mut out = Vec::new();
        self.walk(self.section(self.root, "the root directory")?, 0, &mut out)?;
        Ok(out)
    }

    fn walk(
        &self,
        dir: &[u8],
        depth: u32,
        out: &mut Vec<StoredTile<'a>>,
    ) -> Result<()> {
        if depth > 3 {
            return Err(Error::input(&self.name, "directories nest deeper than 3"));
        }
        for e in self.directory(dir)? {
            if e.run_length == 0 {
                let at = self.leaves.0.checked_add(e.offset);
                let leaf = at
                    .filter(|_| e.offset + u64::from(e.length) <= self.leaves.1)
                    .ok_or_else(|| Error::input(&self.name, "a leaf lies outside its section"))?;
                self.walk(self.section((leaf, u64::from(e.length)), "a leaf")?, depth + 1, out)?;
                continue;
            }
            if e.offset + u64::from(e.length) > self.data.1 {
                return Err(Error::input(&self.name, "a tile lies outside the tile data"));
            }
            let bytes = self.section((self.data.0 + e.offset, u64::from(e.length)), "a tile")?;
            for k in 0..u64::from(e.run_length) {
                out.push((tile_of(e.tile_id + k)?, bytes));
            }
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;

    #[test]
    fn tile_ids_follow_the_spec_examples() {
        // The spec's ids: zoom 0 is id 0, zoom 1 starts at 1, zoom 2 at 5; the Hilbert
        // curve at zoom 1 runs (0,0), (0,1), (1,1), (1,0).
        assert_eq!(tile_id(0, 0, 0).ok(), Some(0));
        assert_eq!(tile_id(1, 0, 0).ok(), Some(1));
        assert_eq!(tile_id(1, 0, 1).ok(), Some(2));
        assert_eq!(tile_id(1, 1, 1).ok(), Some(3));
        assert_eq!(tile_id(1, 1, 0).ok(), Some(4));
        assert_eq!(tile_id(2, 0, 0).ok(), Some(5));
        assert_eq!(tile_id(12, 3423, 1763).ok(), Some(19_078_479));
        assert!(tile_id(1, 2, 0).is_err());
        assert!(tile_id(32, 0, 0).is_err());
    }

    proptest! {
        #[test]
        fn tile_ids_invert(z in 0u8..=31, fx in 0.0f64..1.0, fy in 0.0f64..1.0) {
            let n = (1u64 << z) as f64;
            let (x, y) = ((fx * n) as u32, (fy * n) as u32);
            let id = tile_id(z, x, y).unwrap();
            prop_assert_eq!(tile_of(id).unwrap(), (z, x, y));
        }

        /// Any tiles put in rising order read back byte for byte, whatever the repeats and
        /// however many leaves the directories need.
        #[test]
        fn archives_read_back(
            tiles in proptest::collection::btree_map((0u8..=9, 0u32..512, 0u32..512), 0u8..6, 1..400),
            spread in any::<bool>(),
        ) {
            let mut ts: Vec<((u8, u32, u32), Vec<u8>)> = tiles
                .into_iter()
                .map(|((z, x, y), v)| {
                    let n = 1u32 << z;
                    let bytes = if spread { vec![v; 1 + (x as usize % 7)] } else { vec![v] };
                    ((z, x % n, y % n), bytes)
                })
                .collect();
            ts.sort_by_key(|((z, x, y), _)| tile_id(*z, *x, *y).unwrap());
            ts.dedup_by_key(|(t, _)| *t);
            let dir = tempfile::tempdir().unwrap();
            let mut w = Writer::new(dir.path()).unwrap();
            for ((z, x, y), b) in &ts {
                w.put(*z, *x, *y, b).unwrap();
            }
            let info = ArchiveInfo {
                tile_compression: Compression::None,
                tile_type: TileType::Unknown,
                bounds: [-1.0, -2.0, 3.0, 4.0],
                center_zoom: 0,
                metadata: serde_json::json!({"name": "t"}),
            };
            let mut out = Vec::new();
            let stats = w.finish(&info, &mut out).unwrap();
            prop_assert_eq!(stats.bytes, out.len() as u64);
            let a = Archive::new(&out, "t.pmtiles").unwrap();
            prop_assert!(a.clustered);
            prop_assert_eq!(a.counts[0], ts.len() as u64);
            let meta = a.metadata().unwrap();
            prop_assert_eq!(meta["name"].as_str(), Some("t"));
            let back: Vec<((u8, u32, u32), Vec<u8>)> =
                a.tiles().unwrap().into_iter().map(|(t, b)| (t, b.to_vec())).collect();
            prop_assert_eq!(back, ts);
        }
    }

    /// Enough distinct tiles that the root cannot hold them: leaves are written, the
    /// header and root stay within 16 KiB, and every tile reads back.
    #[test]
    fn large_archives_use_leaves() {
        let dir = tempfile::tempdir().unwrap();
        let mut w = Writer::new(dir.path()).unwrap();
        let z = 8u8;
        // Irregular gaps and lengths, so the directory does not gzip to nothing.
        let mut seed = 0x9e37_79b9_7f4a_7c15u64;
        let mut next = move || {
            seed ^= seed << 13;
            seed ^= seed >> 7;
            seed ^= seed << 17;
            seed
        };
        let mut ts: Vec<(u32, u32)> = (0..256)
            .flat_map(|x| (0..256).map(move |y| (x, y)))
            .filter(|_| next() % 3 != 0)
            .collect();
        ts.sort_by_key(|&(x, y)| tile_id(z, x, y).unwrap());
        let bytes = |x: u32, y: u32| {
            let b = (x * 1000 + y).to_le_bytes();
            b.repeat(1 + ((x * 7 + y * 13) % 5) as usize)
        };
        for &(x, y) in &ts {
            w.put(z, x, y, &bytes(x, y)).unwrap();
        }
        let info = ArchiveInfo {
            tile_compression: Compression::None,
            tile_type: TileType::Png,
            bounds: [-180.0, -85.0, 180.0, 85.0],
            center_zoom: 3,
            metadata: serde_json::json!({}),
        };
        let mut out = Vec::new();
        let stats = w.finish(&info, &mut out).unwrap();
        assert!(stats.leaves > 1, "{stats:?}");
        let a = Archive::new(&out, "t").unwrap();
        assert!(a.root.0 + a.root.1 <= ROOT_LIMIT as u64);
        let back = a.tiles().unwrap();
        assert_eq!(back.len(), ts.len());
        for ((z2, x, y), b) in back {
            assert_eq!(z2, z);
            assert_eq!(b, bytes(x, y).as_slice());
        }
    }

    #[test]
    fn out_of_order_and_empty_tiles_are_refused() {
        let dir = tempfile::tempdir().unwrap();
        let mut w = Writer::new(dir.path()).unwrap();
        w.put(1, 1, 1, b"a").unwrap();
        assert!(w.put(1, 0, 1, b"b").is_err());
        assert!(w.put(1, 1, 0, b"").is_err());
        let empty = Writer::new(dir.path()).unwrap();
        let info = ArchiveInfo {
            tile_compression: Compression::None,
            tile_type: TileType::Png,
            bounds: [0.0; 4],
            center_zoom: 0,
            metadata: serde_json::json!({}),
        };
        assert!(empty.finish(&info, &mut Vec::new()).is_err());
    }
}
