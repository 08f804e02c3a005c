//! The dataset header: what the terrain is (size, blocks, georeference, units) and how the
//! model was cut (levels, padding, δ_min), as one blob.
//!
//! The blob is a fixed 160-byte part followed by three UTF-8 strings (CRS, units, source
//! format) whose lengths the fixed part gives. `format-spec/container.md` §5 tabulates it.

use zerocopy::byteorder::little_endian::{F64, U16, U32, U64};
use zerocopy::{FromBytes, IntoBytes};

use super::{Invariant, Violation, MAX_STRING_LEN, VOID_BITS};
use crate::geoid::VerticalDatum;
use crate::heightfield::{Georeference, Metadata};
use crate::model::{Domain, Model, Precision};

/// Bytes of the fixed part of the dataset header.
pub const DATASET_FIXED_LEN: usize = 160;

/// The longest dataset header blob: the fixed part and three strings of the longest length.
pub const MAX_DATASET_HEADER_LEN: u64 = DATASET_FIXED_LEN as u64 + 3 * MAX_STRING_LEN as u64;

/// Flag: `spacing_m` is known.
pub const HAS_SPACING: u16 = 1;
/// Flag: the georeference (origin, step) is known.
pub const HAS_GEOREFERENCE: u16 = 2;
/// Flag: the CRS string is present (only with [`HAS_GEOREFERENCE`]).
pub const HAS_CRS: u16 = 4;
/// Flag: the units string is present.
pub const HAS_UNITS: u16 = 8;
/// Flag (format 6): the nodes are thinned by area ([`crate::model::thinning`]) by the
/// spacing of the georeference, which is geographic; an editor thins by the same rule.
pub const THINNED_BY_AREA: u16 = 16;
const KNOWN_FLAGS: u16 = HAS_SPACING | HAS_GEOREFERENCE | HAS_CRS | HAS_UNITS | THINNED_BY_AREA;

on_disk! {
    struct Fixed {
        width: U32,
        height: U32,
        block_size: U32,
        finest_level: u8,
        levels: u8,
        flags: U16,
        padded_side: U64,
        padding_samples: U64,
        valid_samples: U64,
        void_samples: U64,
        spacing: [F64; 2],
        origin: [F64; 2],
        step: [F64; 2],
        delta_min: F64,
        max_error: F64,
        node_count: U64,
        block_count: U64,
        cluster_count: U32,
        void_bits: U32,
        crs_len: U32,
        units_len: U32,
        source_format_len: U32,
        precision: F64,
        vertical_datum: u8,
        reserved: [u8; 3],
    }
}

const _: () = assert!(size_of::<Fixed>() == DATASET_FIXED_LEN);

/// The dataset header, parsed.
#[derive(Clone, Debug, PartialEq)]
pub struct DatasetHeader {
    /// The block geometry (data size, block size, levels).
    pub domain: Domain,
    /// Valid samples in the data rectangle.
    pub valid_samples: u64,
    /// Void samples in the data rectangle.
    pub void_samples: u64,
    /// The subdivision threshold the tree was pruned with (the lowest cluster threshold).
    pub delta_min: f64,
    /// The root's `e*`.
    pub max_error: f64,
    /// Nodes in the node table.
    pub node_count: u64,
    /// Physical blocks in the block table.
    pub block_count: u64,
    /// Clusters in the cluster directory.
    pub cluster_count: u32,
    /// The storage precision heights were kept to (format 2.1; `None`: bit for bit).
    pub precision: Option<Precision>,
    /// Spacing, georeference, units and provenance.
    pub metadata: Metadata,
    /// Whether nodes are thinned by area by the georeference's spacing (format 6).
    pub thinned_by_area: bool,
}

impl DatasetHeader {
    /// How far a stored height may be from its source: the precision's bound (2.1), or 0
    /// when heights are stored bit for bit.
    pub fn storage_error(&self) -> f64 {
        self.precision.map_or(0.0, Precision::bound)
    }

    /// The spacing nodes are thinned by area with, if they are (format 6).
    pub fn thinning(&self) -> Option<crate::model::LatLonSpacing> {
        self.metadata
            .georeference
            .as_ref()
            .and_then(crate::model::LatLonSpacing::of_georeference)
            .filter(|_| self.thinned_by_area)
    }

    /// The header describing `model`, built from a heightfield with `metadata`.
    pub fn of_model(model: &Model, metadata: &Metadata) -> DatasetHeader {
        let d = *model.domain();
        let (cols, rows) = d.nodes_across(d.finest_level());
        DatasetHeader {
            domain: d,
            valid_samples: model.raster().valid_count(),
            void_samples: model.raster().void_count(),
            delta_min: model.tree().delta_min(),
            max_error: model.max_error(),
            node_count: model.tree().nodes().len() as u64,
            block_count: u64::from(cols) * u64::from(rows),
            // A model holds at most MAX_CLUSTERS clusters.
            cluster_count: u32::try_from(model.clusters().len()).unwrap_or(u32::MAX),
            precision: model.precision(),
            metadata: metadata.clone(),
            thinned_by_area: model.thinning().is_some(),
        }
    }

    /// The blob bytes.
    pub fn encode(&self) -> Vec<u8> {
        let m = &self.metadata;
        let d = &self.domain;
        let max = MAX_STRING_LEN as usize;
        let crs = m
            .georeference
            .as_ref()
            .and_then(|g| g.crs.as_deref())
            .map_or("", |s| truncate_utf8(s, max));
        let units = m.units.as_deref().map_or("", |s| truncate_utf8(s, max));
        let source_format = truncate_utf8(&m.source_format, max);
        let mut flags = 0u16;
        if m.spacing_m.is_some() {
            flags |= HAS_SPACING;
        }
        if let Some(g) = &m.georeference {
            flags |= HAS_GEOREFERENCE;
            if g.crs.is_some() {
                flags |= HAS_CRS;
            }
        }
        if m.units.is_some() {
            flags |= HAS_UNITS;
        }
        if self.thinned_by_area {
            flags |= THINNED_BY_AREA;
        }
        let g = m.georeference.as_ref();
        let pair = |v: [f64; 2]| [F64::new(v[0]), F64::new(v[1])];
        let fixed = Fixed {
            width: U32::new(d.width()),
            height: U32::new(d.height()),
            block_size: U32::new(d.block_size()),
            finest_level: d.finest_level(),
            levels: d.levels(),
            flags: U16::new(flags),
            padded_side: U64::new(d.side()),
            padding_samples: U64::new(d.padding_samples()),
            valid_samples: U64::new(self.valid_samples),
            void_samples: U64::new(self.void_samples),
            spacing: pair(m.spacing_m.unwrap_or([0.0; 2])),
            origin: pair(g.map_or([0.0; 2], |g| g.origin)),
            step: pair(g.map_or([0.0; 2], |g| g.step)),
            delta_min: F64::new(self.delta_min),
            max_error: F64::new(self.max_error),
            node_count: U64::new(self.node_count),
            block_count: U64::new(self.block_count),
            cluster_count: U32::new(self.cluster_count),
            void_bits: U32::new(VOID_BITS),
            // Each string was cut to MAX_STRING_LEN bytes above.
            crs_len: U32::new(string_len(crs)),
            units_len: U32::new(string_len(units)),
            source_format_len: U32::new(string_len(source_format)),
            precision: F64::new(self.precision.map_or(0.0, Precision::step)),
            vertical_datum: m.vertical_datum.code(),
            reserved: [0; 3],
        };
        let mut out = fixed.as_bytes().to_vec();
        for s in [crs, units, source_format] {
            out.extend_from_slice(s.as_bytes());
        }
        out
    }

    /// Parses and checks a blob (invariant I-6) of a file of format `version` (its commit
    /// record's major and minor). Byte 156, the vertical datum, is reserved before 6.1. A
    /// minor newer than this reader's may hold what it does not know in reserved bytes, and
    /// a vertical datum code it does not know (read as unknown); any other must not.
    pub fn decode(bytes: &[u8], version: (u16, u16)) -> Result<DatasetHeader, Violation> {
        let newer_minor = super::commit::is_newer_minor(version.0, version.1);
        let bad =
            |detail: String| Violation::new(Invariant::DatasetHeader, "dataset header", detail);
        let (f, rest) = Fixed::read_from_prefix(bytes).map_err(|_| {
            bad(format!(
                "{} bytes, shorter than the fixed part",
                bytes.len()
            ))
        })?;
        let flags = f.flags.get();
        if flags & !KNOWN_FLAGS != 0 {
            return Err(bad(format!("unknown flags {flags:#x}")));
        }
        if f.void_bits.get() != VOID_BITS {
            return Err(bad(format!("void marker {:#x}", f.void_bits.get())));
        }
        let domain = Domain::new(f.width.get(), f.height.get(), f.block_size.get())
            .map_err(|e| bad(e.to_string()))?;
        let (cols, rows) = domain.nodes_across(domain.finest_level());
        let samples = u64::from(domain.width()) * u64::from(domain.height());
        let checks: [(&str, u64, u64); 6] = [
            (
                "finest level",
                u64::from(f.finest_level),
                u64::from(domain.finest_level()),
            ),
            ("levels", u64::from(f.levels), u64::from(domain.levels())),
            ("padded side", f.padded_side.get(), domain.side()),
            (
                "padding samples",
                f.padding_samples.get(),
                domain.padding_samples(),
            ),
            (
                "block count",
                f.block_count.get(),
                u64::from(cols) * u64::from(rows),
            ),
            (
                "valid + void samples",
                f.valid_samples.get().saturating_add(f.void_samples.get()),
                samples,
            ),
        ];
        for (what, stored, implied) in checks {
            if stored != implied {
                return Err(bad(format!(
                    "{what} is {stored}, the geometry implies {implied}"
                )));
            }
        }
        let (delta_min, max_error) = (f.delta_min.get(), f.max_error.get());
        if !(delta_min.is_finite() && delta_min >= 0.0 && max_error.is_finite() && max_error >= 0.0)
        {
            return Err(bad(format!("delta_min {delta_min}, max error {max_error}")));
        }
        let precision = match f.precision.get() {
            0.0 => None,
            step => Some(Precision::new(step).map_err(|e| bad(e.to_string()))?),
        };
        let cluster_count = f.cluster_count.get();
        if cluster_count == 0 || cluster_count as usize > crate::model::MAX_CLUSTERS {
            return Err(bad(format!("{cluster_count} clusters")));
        }
        if f.node_count.get() == 0 {
            return Err(bad("no nodes".into()));
        }
        let lens = [
            f.crs_len.get(),
            f.units_len.get(),
            f.source_format_len.get(),
        ];
        if lens.iter().any(|&l| l > MAX_STRING_LEN) {
            return Err(bad(format!(
                "string lengths {lens:?} exceed {MAX_STRING_LEN}"
            )));
        }
        let total: usize = lens.iter().map(|&l| l as usize).sum();
        if rest.len() != total {
            return Err(bad(format!(
                "{} string bytes, the lengths say {total}",
                rest.len()
            )));
        }
        let mut strings = Vec::with_capacity(3);
        let mut at = 0usize;
        for (name, len) in ["crs", "units", "source format"].iter().zip(lens) {
            let raw = &rest[at..at + len as usize];
            at += len as usize;
            let s = std::str::from_utf8(raw).map_err(|_| bad(format!("{name} is not UTF-8")))?;
            strings.push(s.to_owned());
        }
        let source_format = strings.pop().unwrap_or_default();
        let units = strings.pop().unwrap_or_default();
        let crs = strings.pop().unwrap_or_default();
        if flags & HAS_CRS == 0 && !crs.is_empty() || flags & HAS_UNITS == 0 && !units.is_empty() {
            return Err(bad("a string is present but its flag is clear".into()));
        }
        if flags & HAS_CRS != 0 && flags & HAS_GEOREFERENCE == 0 {
            return Err(bad("a CRS without a georeference".into()));
        }
        let pair = |v: [F64; 2]| [v[0].get(), v[1].get()];
        let metadata = Metadata {
            spacing_m: (flags & HAS_SPACING != 0).then(|| pair(f.spacing)),
            georeference: (flags & HAS_GEOREFERENCE != 0).then(|| Georeference {
                crs: (flags & HAS_CRS != 0).then_some(crs),
                origin: pair(f.origin),
                step: pair(f.step),
            }),
            units: (flags & HAS_UNITS != 0).then_some(units),
            vertical_datum: match (f.vertical_datum, VerticalDatum::from_code(f.vertical_datum)) {
                // Not recorded (a file before 6.1): what its reader's convention says.
                (0, _) => VerticalDatum::of_source_format(&source_format),
                _ if version < (6, 1) && !newer_minor => {
                    return Err(bad(format!(
                        "reserved byte 156 is {} in a {}.{} file",
                        f.vertical_datum, version.0, version.1
                    )))
                }
                (_, Some(datum)) => datum,
                (_, None) if newer_minor => VerticalDatum::Unknown,
                (code, None) => return Err(bad(format!("vertical datum code {code}"))),
            },
            source_format,
        };
        if !newer_minor && f.reserved != [0; 3] {
            return Err(bad("reserved bytes 157..160 are not zero".into()));
        }
        let thinned_by_area = flags & THINNED_BY_AREA != 0;
        if thinned_by_area
            && metadata
                .georeference
                .as_ref()
                .and_then(crate::model::LatLonSpacing::of_georeference)
                .is_none()
        {
            return Err(bad(
                "thinned by area without a geographic georeference to thin by".into(),
            ));
        }
        Ok(DatasetHeader {
            domain,
            valid_samples: f.valid_samples.get(),
            void_samples: f.void_samples.get(),
            delta_min,
            max_error,
            node_count: f.node_count.get(),
            block_count: f.block_count.get(),
            cluster_count,
            precision,
            metadata,
            thinned_by_area,
        })
    }
}

fn string_len(s: &str) -> u32 {
    u32::try_from(s.len()).unwrap_or(u32::MAX)
}

/// `s` cut to at most `max` bytes on a character boundary.
fn truncate_utf8(s: &str, max: usize) -> &str {
    if s.len() <= max {
        return s;
    }
    let mut end = max;
    while !s.is_char_boundary(end) {
        end -= 1;
    }
    &s[..end]
}
