//! Reading and writing a dataset's `MANIFEST` (`format-spec/dataset.md` §2–§3): the two
//! commit slots, the head read at open, tile pages read when a window first meets them, and
//! the commit that writes a new body where the active one is not, syncs, then publishes its
//! record in the other slot. The bytes are [`crate::format::manifest`]'s; this file decides
//! what to read and write and in which order.

use std::sync::{Arc, OnceLock};

use crate::curve::hilbert::hilbert_encode;
use crate::error::{Error, Result};
use crate::format::manifest::{
    choose, decode_tile_page, head_len_for, Head, HeadFixed, ManifestRecord, ManifestSlot,
    NoManifest, PageEntry, TileRecord, CRS_LEN, HEAD_FIXED_LEN, HEAD_HAS_GEOREFERENCE, HEAD_MAGIC,
    MANIFEST_MAJOR, MANIFEST_PAGE, MANIFEST_RECORD_LEN, MAX_ADJACENCY_LEN, MAX_TILES,
    TILES_PER_PAGE,
};
use crate::format::{crc32, Invariant, Violation};
use crate::heightfield::Georeference;
use crate::geoid::VerticalDatum;
use crate::model::SampleRect;
use crate::store::io::Io;
use crate::store::slots::SlotsNow;
use crate::store::Source;

/// The manifest's file name inside a dataset's directory.
pub const MANIFEST_NAME: &str = "MANIFEST";

/// The byte offset of slot `i`.
fn slot_offset(i: u8) -> u64 {
    u64::from(i) * u64::from(MANIFEST_PAGE)
}

/// Reads and classifies both slots.
pub fn read_slots<S: Source + ?Sized>(src: &S) -> Result<[ManifestSlot; 2]> {
    read_slots_from(src, false)
}

/// [`read_slots`], reading past what the source keeps in memory when `fresh`.
fn read_slots_from<S: Source + ?Sized>(src: &S, fresh: bool) -> Result<[ManifestSlot; 2]> {
    let one = |i: u8| -> Result<ManifestSlot> {
        let at = slot_offset(i);
        let len = src.len().saturating_sub(at).min(MANIFEST_RECORD_LEN as u64) as usize;
        if len == 0 {
            return Ok(ManifestSlot::Empty);
        }
        let read = if fresh {
            src.read_fresh(at, len)
        } else {
            src.read_at(at, len)
        };
        let bytes = read.map_err(|e| Error::io(src.name(), e))?;
        Ok(ManifestRecord::classify(&bytes, i))
    };
    Ok([one(0)?, one(1)?])
}

/// The state a reader takes, or why there is none.
pub fn choose_state<S: Source + ?Sized>(src: &S) -> Result<(u8, ManifestRecord)> {
    choose(&read_slots(src)?).map_err(|why| match why {
        NoManifest::NotAManifest => Error::input(
            src.name(),
            "not an fmrh dataset manifest (no record with the FMDS magic)",
        ),
        NoManifest::Unsupported(major) => Error::unsupported(
            src.name(),
            format!("manifest major version {major}; this reader reads {MANIFEST_MAJOR}"),
        ),
        NoManifest::Corrupt(v) => v.in_file(src.name()),
    })
}

/// Bytes of `src` that should hold what the state `held` says and do not (`v`): superseded
/// when a newer state was published since (its body may lie there now), changed underneath
/// when no slot publishes `held` any more and none newer does, else corruption (the
/// containers' triage, [`crate::store::slots::triage`], with the manifest's slots).
fn superseded_or_corrupt<S: Source + ?Sized>(
    src: &S,
    held: &ManifestRecord,
    v: Violation,
) -> Error {
    let now = slots_now(src, held).unwrap_or(SlotsNow::Unknown);
    crate::store::slots::triage(src.name(), held.txn_id.get(), now, v)
}

/// What the manifest's slots say now about the state `held`: the latest state's id, and
/// whether a slot still publishes `held`. `Err` only when the slots cannot be read.
pub(crate) fn slots_now<S: Source + ?Sized>(src: &S, held: &ManifestRecord) -> Result<SlotsNow> {
    let slots = read_slots_from(src, true)?;
    Ok(match choose(&slots) {
        Ok((_, latest)) => SlotsNow::Latest {
            txn: latest.txn_id.get(),
            still_published: slots.iter().any(|s| {
                matches!(s, ManifestSlot::Valid(r)
                    if r.txn_id.get() == held.txn_id.get() && r.crc.get() == held.crc.get())
            }),
        },
        Err(_) => SlotsNow::Unknown,
    })
}

/// Reads `len` bytes at `offset` that the state `txn` names, checking their CRC.
fn read_checked<S: Source + ?Sized>(
    src: &S,
    held: &ManifestRecord,
    offset: u64,
    len: u64,
    crc: u32,
    invariant: Invariant,
    what: &str,
) -> Result<Vec<u8>> {
    let bad =
        |detail: String| superseded_or_corrupt(src, held, Violation::new(invariant, what, detail));
    if offset.checked_add(len).is_none_or(|end| end > src.len()) {
        return Err(bad(format!(
            "{len} bytes at {offset}: past the end of the file"
        )));
    }
    let n = usize::try_from(len).map_err(|_| bad(format!("{len} bytes")))?;
    let bytes = src
        .read_at(offset, n)
        .map_err(|e| Error::io(src.name(), e))?
        .into_owned();
    if crc32(&bytes) != crc {
        return Err(bad("CRC mismatch".into()));
    }
    Ok(bytes)
}

/// A dataset state as a reader holds it: its record, its head, and its tile pages as they
/// are read.
pub struct ManifestState {
    /// The slot its record is in.
    pub slot: u8,
    /// Its record.
    pub record: ManifestRecord,
    /// Its head.
    pub head: Head,
    pages: Vec<OnceLock<Arc<Vec<TileRecord>>>>,
}

impl ManifestState {
    /// Reads the state a reader takes: the slots and the head, nothing else.
    pub fn read<S: Source + ?Sized>(src: &S) -> Result<ManifestState> {
        let (slot, record) = choose_state(src)?;
        // The state may be newer than the length the source saw when it was opened: a
        // writer grows the file before it publishes a record (as `store::open` does for a
        // container). Only a length still short after a fresh look is a fault.
        if record.file_length.get() > src.len()
            && record.file_length.get() > src.refresh_len().map_err(|e| Error::io(src.name(), e))?
        {
            return Err(superseded_or_corrupt(
                src,
                &record,
                Violation::new(
                    Invariant::ManifestRecord,
                    format!("manifest slot {slot}"),
                    format!(
                        "the state needs {} bytes, the file has {}",
                        record.file_length.get(),
                        src.len()
                    ),
                ),
            ));
        }
        let bytes = read_checked(
            src,
            &record,
            record.head_offset.get(),
            u64::from(record.head_len.get()),
            record.head_crc.get(),
            Invariant::ManifestPages,
            "manifest head",
        )?;
        let head = Head::decode(&bytes, &record).map_err(|v| v.in_file(src.name()))?;
        let pages = head.pages.iter().map(|_| OnceLock::new()).collect();
        Ok(ManifestState {
            slot,
            record,
            head,
            pages,
        })
    }

    /// Fetches tile pages `pages` not read yet together, ahead of [`ManifestState::page`]
    /// reading them, on a source where each read costs a round trip (a remote manifest):
    /// one round for all, not one each. Nothing on a local source.
    pub fn fetch_pages<S: Source + ?Sized>(&self, src: &S, pages: &[usize]) -> Result<()> {
        if !src.prefetches() {
            return Ok(());
        }
        let ranges: Vec<(u64, usize)> = pages
            .iter()
            .filter(|&&i| self.pages.get(i).is_some_and(|p| p.get().is_none()))
            .filter_map(|&i| self.head.pages.get(i))
            .map(|e| (e.offset.get(), e.length.get() as usize))
            .collect();
        if ranges.is_empty() {
            return Ok(());
        }
        src.prefetch(&ranges).map_err(|e| Error::io(src.name(), e))
    }

    /// The records of tile page `i`, read and checked the first time they are asked for.
    pub fn page<S: Source + ?Sized>(&self, src: &S, i: usize) -> Result<Arc<Vec<TileRecord>>> {
        if let Some(p) = self.pages[i].get() {
            return Ok(p.clone());
        }
        let e = &self.head.pages[i];
        let bytes = read_checked(
            src,
            &self.record,
            e.offset.get(),
            u64::from(e.length.get()),
            e.crc.get(),
            Invariant::ManifestPages,
            &format!("manifest tile page {i}"),
        )?;
        let records = decode_tile_page(&bytes, e, &self.record)
            .map_err(|v| superseded_or_corrupt(src, &self.record, v))?;
        Ok(self.pages[i].get_or_init(|| Arc::new(records)).clone())
    }

    /// The adjacent-cluster tables of `tile` (a record of this state), read and checked;
    /// empty when it has none.
    pub fn adjacency<S: Source + ?Sized>(&self, src: &S, tile: &TileRecord) -> Result<Vec<u8>> {
        let len = u64::from(tile.adjacency_len.get());
        if len == 0 {
            return Ok(Vec::new());
        }
        read_checked(
            src,
            &self.record,
            self.record.adjacency_area().start + tile.adjacency_offset.get(),
            len,
            tile.adjacency_crc.get(),
            Invariant::AdjacentClusters,
            &format!("adjacent-cluster tables of {}", tile.name()),
        )
    }

    /// Tile pages read so far.
    #[cfg(any(test, feature = "testing"))]
    pub fn pages_read(&self) -> usize {
        self.pages.iter().filter(|p| p.get().is_some()).count()
    }

    /// The georeference of the dataset grid, if any.
    pub fn georeference(&self) -> Option<Georeference> {
        let f = &self.head.fixed;
        (f.flags.get() & HEAD_HAS_GEOREFERENCE != 0).then(|| Georeference {
            crs: crate::format::manifest::crs_name(f).flatten(),
            origin: f.origin.map(|v| v.get()),
            step: f.step.map(|v| v.get()),
        })
    }

    /// What every tile's heights are above, when the head records it (manifest 1.1).
    pub fn vertical_datum(&self) -> Option<VerticalDatum> {
        VerticalDatum::from_code(self.head.fixed.vertical_datum)
    }
}

/// What a dataset state holds, before it is written.
#[derive(Clone, Debug, PartialEq)]
pub struct Contents {
    /// The tiles, in any order ([`write_state`] sorts them).
    pub tiles: Vec<TileRecord>,
    /// Metres between samples, when known.
    pub spacing_m: Option<[f64; 2]>,
    /// The georeference of dataset sample (0, 0), when known.
    pub georeference: Option<Georeference>,
    /// The seam policy (`SEAM_*`).
    pub seam: u8,
    /// What every tile's heights are above; `None`: not recorded (a dataset written before
    /// manifest 1.1, whose readers ask its first tile).
    pub vertical_datum: Option<VerticalDatum>,
    /// Each tile's adjacent-cluster tables (`format-spec/dataset.md` §3.5), by file name;
    /// a tile with none has no entry.
    pub adjacency: std::collections::HashMap<String, Vec<u8>>,
}

/// The order of tiles in a manifest: the Hilbert key of their first sample on a 2^32 grid,
/// then row and column (tiles never share a first sample, but the order is total anyway).
pub fn tile_order(t: &TileRecord) -> (u64, u64, u64) {
    let (c, r) = (t.col0.get(), t.row0.get());
    let key = hilbert_encode(
        32,
        c.min(u64::from(u32::MAX)) as u32,
        r.min(u64::from(u32::MAX)) as u32,
    );
    (key, r, c)
}

/// Writes `contents` as the state after `active` (none: a new manifest, txn 1): the body
/// where the active state's is not, a sync, the record in the other slot, a sync. Returns the
/// new state's slot and record. A crash at any point leaves the active state, or the new one.
pub fn write_state(
    io: &dyn Io,
    active: Option<(u8, &ManifestRecord)>,
    contents: &Contents,
) -> Result<(u8, ManifestRecord)> {
    let name = io.name().to_path_buf();
    let mut tiles = contents.tiles.clone();
    tiles.sort_by_key(tile_order);
    let count = tiles.len() as u64;
    if count > MAX_TILES {
        return Err(Error::TooLarge {
            what: "dataset".into(),
            detail: format!("{count} tiles; a manifest holds at most {MAX_TILES}"),
        });
    }
    let columns = tiles.iter().map(|t| t.rect().col1 + 1).max().unwrap_or(0);
    let rows = tiles.iter().map(|t| t.rect().row1 + 1).max().unwrap_or(0);
    let page = u64::from(MANIFEST_PAGE);
    // The adjacency area: each tile's tables back to back, 8-byte aligned, in tile order.
    let mut area = Vec::new();
    for t in &mut tiles {
        let blob = contents.adjacency.get(t.name()).filter(|b| !b.is_empty());
        let (at, len, crc) = match blob {
            Some(b) => {
                area.resize(area.len().next_multiple_of(8), 0);
                let at = area.len() as u64;
                area.extend_from_slice(b);
                (at, b.len(), crc32(b))
            }
            None => (0, 0, 0),
        };
        t.adjacency_offset = at.into();
        t.adjacency_len = u32::try_from(len)
            .map_err(|_| Error::TooLarge {
                what: "adjacent-cluster tables".into(),
                detail: format!("{len} bytes for tile {}", t.name()),
            })?
            .into();
        t.adjacency_crc = crc.into();
    }
    let area_len = (area.len() as u64).next_multiple_of(page);
    if area_len > MAX_ADJACENCY_LEN {
        return Err(Error::TooLarge {
            what: "adjacent-cluster tables".into(),
            detail: format!("{area_len} bytes; a manifest holds at most {MAX_ADJACENCY_LEN}"),
        });
    }
    let page_count = count.div_ceil(TILES_PER_PAGE as u64);
    let head_len = head_len_for(page_count);
    let body_len = page_count * page + area_len + head_len;
    let start = match active {
        None => 2 * page,
        Some((_, r)) => {
            let body = r.body();
            if 2 * page + body_len <= body.start {
                2 * page
            } else {
                body.end.div_ceil(page) * page
            }
        }
    };
    let mut entries = Vec::with_capacity(tiles.len().div_ceil(TILES_PER_PAGE));
    for (i, chunk) in tiles.chunks(TILES_PER_PAGE).enumerate() {
        let bytes: Vec<u8> = chunk
            .iter()
            .flat_map(|t| zerocopy::IntoBytes::as_bytes(t).to_vec())
            .collect();
        let mut bounds = chunk[0].rect();
        for t in chunk {
            let r = t.rect();
            bounds.col0 = bounds.col0.min(r.col0);
            bounds.row0 = bounds.row0.min(r.row0);
            bounds.col1 = bounds.col1.max(r.col1);
            bounds.row1 = bounds.row1.max(r.row1);
        }
        let offset = start + i as u64 * page;
        io.write_at(offset, &bytes)
            .map_err(|e| Error::io(&name, e))?;
        entries.push(PageEntry {
            offset: offset.into(),
            length: (bytes.len() as u32).into(),
            crc: crc32(&bytes).into(),
            first_tile: ((i * TILES_PER_PAGE) as u32).into(),
            count: (chunk.len() as u32).into(),
            bounds: [bounds.col0, bounds.row0, bounds.col1, bounds.row1].map(Into::into),
            min_height: chunk
                .iter()
                .map(|t| t.min_height.get())
                .fold(f32::INFINITY, f32::min)
                .into(),
            max_height: chunk
                .iter()
                .map(|t| t.max_height.get())
                .fold(f32::NEG_INFINITY, f32::max)
                .into(),
        });
    }
    let mut crs = [0u8; CRS_LEN];
    let g = contents.georeference.as_ref();
    if let Some(name_text) = g.and_then(|g| g.crs.as_deref()) {
        if name_text.len() > CRS_LEN || name_text.as_bytes().contains(&0) {
            return Err(Error::InvalidArgument(format!(
                "CRS name {name_text:?}: a dataset records at most {CRS_LEN} bytes"
            )));
        }
        crs[..name_text.len()].copy_from_slice(name_text.as_bytes());
    }
    let head = Head {
        fixed: HeadFixed {
            magic: HEAD_MAGIC,
            page_count: (page_count as u32).into(),
            tile_count: count.into(),
            flags: (if g.is_some() {
                HEAD_HAS_GEOREFERENCE
            } else {
                0
            })
            .into(),
            vertical_datum: contents.vertical_datum.map_or(0, |d| d.code()),
            reserved0: [0; 3],
            origin: g.map_or([0.0; 2], |g| g.origin).map(Into::into),
            step: g.map_or([0.0; 2], |g| g.step).map(Into::into),
            crs,
            reserved: [0; 72],
        },
        pages: entries,
    };
    let head_bytes = head.encode();
    debug_assert_eq!(head_bytes.len() as u64, head_len);
    debug_assert_eq!(HEAD_FIXED_LEN, 256);
    if !area.is_empty() {
        io.write_at(start + page_count * page, &area)
            .map_err(|e| Error::io(&name, e))?;
    }
    let head_offset = start + page_count * page + area_len;
    io.write_at(head_offset, &head_bytes)
        .map_err(|e| Error::io(&name, e))?;
    io.sync().map_err(|e| Error::io(&name, e))?;
    let txn = active.map_or(1, |(_, r)| r.txn_id.get() + 1);
    let record = ManifestRecord::new(
        txn,
        head_offset + head_len,
        (head_offset, head_len as u32, crc32(&head_bytes)),
        area_len,
        count,
        columns,
        rows,
        contents.spacing_m,
        contents.seam,
    );
    let slot = active.map_or(0, |(s, _)| 1 - s);
    // The slot pages are whole pages, so a torn record write cannot reach the other slot.
    let mut page_bytes = vec![0u8; MANIFEST_PAGE as usize];
    page_bytes[..MANIFEST_RECORD_LEN].copy_from_slice(zerocopy::IntoBytes::as_bytes(&record));
    io.write_at(slot_offset(slot), &page_bytes)
        .map_err(|e| Error::io(&name, e))?;
    io.sync().map_err(|e| Error::io(&name, e))?;
    Ok((slot, record))
}

/// The rectangle's tiles' pages: those whose bounds meet `rect`.
pub fn pages_meeting(head: &Head, rect: &SampleRect) -> Vec<usize> {
    head.pages
        .iter()
        .enumerate()
        .filter(|(_, p)| p.rect().intersect(rect).is_some())
        .map(|(i, _)| i)
        .collect()
}
