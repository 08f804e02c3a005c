//! The EGM96 geoid: how far the geoid (mean sea level, which SRTM and DTED heights are
//! above) lies above the WGS 84 ellipsoid (which Cesium's heights are above). An
//! ellipsoidal height is `h = H + N`, `H` the orthometric height, `N` the undulation.
//!
//! **The grid.** NGA's 15-minute worldwide grid of EGM96 undulations (`WW15MGH.DAC`, public
//! domain: `data/egm96-nga/`), 721 × 1440 values in centimetres from 90° N and 0° E,
//! compiled into this binary re-coded (`data/egm96-nga/pack.py`: 702 KB where the file is
//! 2.08 MB) and decoded once, on first use, into 2 MB.
//!
//! **Interpolation.** Bilinear between the four grid values around a point, longitudes
//! wrapping at 360°, as NGA's `intptdac.f` does with its bilinear option (its default is a
//! 4 × 4 spline). Against NGA's own test values, computed from the spherical-harmonic model
//! itself (`readme.txt` of the EGM96 distribution), bilinear on this grid is within 0.056 m
//! (measured: +0.023, +0.002, −0.044, +0.056, −0.030, +0.008 m; the test pins 0.06 m);
//! over rough gravity fields it can be off by a few decimetres more, below the 1 m of
//! SRTM's height steps.
//!
//! Nothing here knows tiles or files: degrees in, metres out.

use std::sync::OnceLock;

/// What a terrain's heights are above: recorded in a container's dataset header
/// (`format-spec/container.md` §5, format 6.1) and shown by `fmrh info`.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, serde::Serialize)]
#[serde(rename_all = "lowercase")]
pub enum VerticalDatum {
    /// The EGM96 geoid (mean sea level): SRTM's and DTED's heights.
    Egm96,
    /// The EGM2008 geoid (Copernicus DEM's heights). fmrh bundles no EGM2008 grid, so it
    /// cannot lift such heights to the ellipsoid ([`VerticalDatum::lift`] says so).
    Egm2008,
    /// The WGS 84 ellipsoid.
    Ellipsoid,
    /// Not known: heights are placed as they are, as if above the ellipsoid.
    #[default]
    Unknown,
}

/// How heights of a [`VerticalDatum`] become heights above the WGS 84 ellipsoid.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Lift {
    /// As they are: they are above the ellipsoid, or nothing better is known.
    None,
    /// Plus the EGM96 undulation ([`egm96_undulation`]).
    Egm96,
}

impl VerticalDatum {
    /// Every datum, in the order of their stored codes.
    pub const ALL: [VerticalDatum; 4] = [
        VerticalDatum::Unknown,
        VerticalDatum::Ellipsoid,
        VerticalDatum::Egm96,
        VerticalDatum::Egm2008,
    ];

    /// What a reader's heights are above, when the file says nothing else: EGM96 for SRTM
    /// (`.hgt`) and DTED, unknown for the rest.
    pub fn of_source_format(format: &str) -> VerticalDatum {
        match format {
            "srtm-hgt" | "dted" => VerticalDatum::Egm96,
            _ => VerticalDatum::Unknown,
        }
    }

    /// The datum an EPSG vertical CRS code names (a GeoTIFF's `VerticalCSTypeGeoKey`):
    /// 5773 EGM96 height, 3855 EGM2008 height, 5030 (GeoTIFF 1.0's "WGS 84 ellipsoid") and
    /// 4979 (WGS 84, 3-D) the ellipsoid; any other is unknown to fmrh (NAVD88, say: its
    /// heights are placed as they are).
    pub fn of_epsg(code: u32) -> VerticalDatum {
        match code {
            5773 => VerticalDatum::Egm96,
            3855 => VerticalDatum::Egm2008,
            5030 | 4979 => VerticalDatum::Ellipsoid,
            _ => VerticalDatum::Unknown,
        }
    }

    /// A datum by name: `egm96`, `egm2008`, `ellipsoid` (or `wgs84`) or `unknown`.
    pub fn parse(name: &str) -> Result<VerticalDatum, String> {
        VerticalDatum::ALL
            .into_iter()
            .find(|d| d.name() == name.to_ascii_lowercase())
            .or((name.eq_ignore_ascii_case("wgs84")).then_some(VerticalDatum::Ellipsoid))
            .ok_or_else(|| format!("`{name}`: expected egm96, egm2008, ellipsoid or unknown"))
    }

    /// Its name, as [`VerticalDatum::parse`] reads it.
    pub fn name(&self) -> &'static str {
        match self {
            VerticalDatum::Egm96 => "egm96",
            VerticalDatum::Egm2008 => "egm2008",
            VerticalDatum::Ellipsoid => "ellipsoid",
            VerticalDatum::Unknown => "unknown",
        }
    }

    /// Its code in a dataset header (byte 156, format 6.1): 1 unknown, 2 ellipsoid, 3 EGM96,
    /// 4 EGM2008. 0 is "not recorded" (files before 6.1), which [`VerticalDatum::from_code`]
    /// leaves to the caller.
    pub fn code(&self) -> u8 {
        match self {
            VerticalDatum::Unknown => 1,
            VerticalDatum::Ellipsoid => 2,
            VerticalDatum::Egm96 => 3,
            VerticalDatum::Egm2008 => 4,
        }
    }

    /// The datum of a stored code 1..=4; `None` for 0 (not recorded) and codes fmrh does
    /// not know.
    pub fn from_code(code: u8) -> Option<VerticalDatum> {
        VerticalDatum::ALL.into_iter().find(|d| d.code() == code)
    }

    /// How its heights become ellipsoidal heights (globe scenes, Cesium tiles, glTF in
    /// ECEF), or why they cannot: EGM2008 heights need a grid fmrh does not bundle.
    pub fn lift(&self) -> Result<Lift, String> {
        match self {
            VerticalDatum::Egm96 => Ok(Lift::Egm96),
            VerticalDatum::Ellipsoid | VerticalDatum::Unknown => Ok(Lift::None),
            VerticalDatum::Egm2008 => Err("its heights are above the EGM2008 geoid, and fmrh \
                 bundles no EGM2008 grid (EGM96's only) to place them on the ellipsoid; \
                 `--vertical-datum egm96` places them with EGM96's undulation instead"
                .into()),
        }
    }
}

/// The packed grid (`data/egm96-nga/pack.py`).
const PACKED: &[u8] = include_bytes!("../data/egm96-nga/ww15mgh.i16.zlib");

const ROWS: usize = 721;
const COLS: usize = 1440;
/// Degrees between grid lines.
const STEP: f64 = 0.25;

/// The grid, decoded: centimetres, row-major from 90° N, 0° E.
fn grid() -> &'static [i16] {
    static GRID: OnceLock<Vec<i16>> = OnceLock::new();
    GRID.get_or_init(|| {
        use std::io::Read;
        let mut bytes = Vec::with_capacity(ROWS * COLS * 2);
        let read = flate2::read::ZlibDecoder::new(PACKED).read_to_end(&mut bytes);
        // The data is compiled in: a failure is a build fault, caught by the tests below,
        // never a user's input. Fall back to a flat geoid rather than panic.
        if read.is_err() || bytes.len() != ROWS * COLS * 2 {
            return vec![0; ROWS * COLS];
        }
        let residual = |k: usize| i16::from_le_bytes([bytes[2 * k], bytes[2 * k + 1]]);
        let mut g = vec![0i16; ROWS * COLS];
        for r in 0..ROWS {
            for c in 0..COLS {
                let k = r * COLS + c;
                let predicted = match (r, c) {
                    (0, 0) => 0,
                    (0, _) => g[k - 1],
                    (_, 0) => g[k - COLS],
                    _ => g[k - 1]
                        .wrapping_add(g[k - COLS])
                        .wrapping_sub(g[k - COLS - 1]),
                };
                g[k] = predicted.wrapping_add(residual(k));
            }
        }
        g
    })
}

/// The EGM96 undulation `N` at latitude `lat` and longitude `lon` (degrees, any longitude;
/// latitudes clamped to ±90°): metres of geoid above the WGS 84 ellipsoid. NaN in, NaN out.
pub fn egm96_undulation(lat: f64, lon: f64) -> f64 {
    Egm96Row::new(lat).at(lon)
}

/// [`egm96_undulation`] along one parallel: the two grid rows around latitude `lat` and
/// the weight between them found once, for the many longitudes a row of samples asks.
/// Gives the same value as [`egm96_undulation`], bit for bit.
#[derive(Clone, Copy, Debug)]
pub struct Egm96Row {
    /// The grid row north of the parallel (`None`: the latitude is not finite).
    r0: Option<usize>,
    /// How far south of row `r0` the parallel lies, in rows.
    fy: f64,
}

impl Egm96Row {
    /// The parallel at `lat` (degrees, clamped to ±90°).
    pub fn new(lat: f64) -> Egm96Row {
        if !lat.is_finite() {
            return Egm96Row { r0: None, fy: 0.0 };
        }
        let y = ((90.0 - lat.clamp(-90.0, 90.0)) / STEP).clamp(0.0, (ROWS - 1) as f64);
        let r0 = (y.floor() as usize).min(ROWS - 2);
        Egm96Row {
            r0: Some(r0),
            fy: y - r0 as f64,
        }
    }

    /// The undulation at longitude `lon` (degrees, any) on this parallel; NaN for a
    /// longitude or latitude that is not finite.
    pub fn at(&self, lon: f64) -> f64 {
        let Some(r0) = self.r0 else {
            return f64::NAN;
        };
        if !lon.is_finite() {
            return f64::NAN;
        }
        let g = grid();
        // `rem_euclid` is a call to fmod; a longitude within one turn of [0, 360) needs at
        // most one addition, which is what `rem_euclid` computes for it.
        let east = if (0.0..360.0).contains(&lon) {
            lon
        } else if (-360.0..0.0).contains(&lon) {
            lon + 360.0
        } else {
            lon.rem_euclid(360.0)
        };
        let x = east / STEP;
        // `x >= 0`: truncation is its floor, without a call.
        let c0 = (x as usize).min(COLS - 1);
        let c1 = (c0 + 1) % COLS;
        let fx = x - c0 as f64;
        let at = |r: usize, c: usize| f64::from(g[r * COLS + c]) / 100.0;
        let north = at(r0, c0) + fx * (at(r0, c1) - at(r0, c0));
        let south = at(r0 + 1, c0) + fx * (at(r0 + 1, c1) - at(r0 + 1, c0));
        north + self.fy * (south - north)
    }
}

/// The least and greatest EGM96 undulation over the box `[lon_a, lon_b] x [lat_a, lat_b]`
/// (degrees, either order): bounds that hold every value [`egm96_undulation`] gives inside
/// it. Bilinear interpolation stays within the values of its cell's four nodes, so the
/// nodes of the cells the box meets bound it; a box over more than 64 × 64 cells takes
/// the whole grid's range instead (-106.99 m, +85.39 m), looser but found at once.
pub fn egm96_range(lon_a: f64, lon_b: f64, lat_a: f64, lat_b: f64) -> (f64, f64) {
    const WHOLE: (f64, f64) = (-106.99, 85.39);
    if ![lon_a, lon_b, lat_a, lat_b].iter().all(|v| v.is_finite()) {
        return WHOLE;
    }
    let (lon_lo, lon_hi) = (lon_a.min(lon_b), lon_a.max(lon_b));
    let (lat_lo, lat_hi) = (lat_a.min(lat_b), lat_a.max(lat_b));
    // Rows from 90° N down; columns from 0° E, wrapping.
    let row_of = |lat: f64| (90.0 - lat.clamp(-90.0, 90.0)) / STEP;
    let (r0, r1) = (
        (row_of(lat_hi).floor() as usize).min(ROWS - 1),
        (row_of(lat_lo).ceil() as usize).min(ROWS - 1),
    );
    let c0 = (lon_lo / STEP).floor();
    let c1 = (lon_hi / STEP).ceil();
    if c1 - c0 > 64.0 || r1 - r0 > 64 {
        return WHOLE;
    }
    let g = grid();
    let (mut lo, mut hi) = (f64::INFINITY, f64::NEG_INFINITY);
    for r in r0..=r1 {
        let mut c = c0;
        while c <= c1 {
            let col = (c.rem_euclid(COLS as f64) as usize).min(COLS - 1);
            let v = f64::from(g[r * COLS + col]) / 100.0;
            lo = lo.min(v);
            hi = hi.max(v);
            c += 1.0;
        }
    }
    (lo, hi)
}

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;

    /// The undulation as first written, with `rem_euclid` and `floor` at every call: what
    /// [`Egm96Row`] must give bit for bit.
    fn reference(lat: f64, lon: f64) -> f64 {
        if !(lat.is_finite() && lon.is_finite()) {
            return f64::NAN;
        }
        let g = grid();
        let y = ((90.0 - lat.clamp(-90.0, 90.0)) / STEP).clamp(0.0, (ROWS - 1) as f64);
        let x = lon.rem_euclid(360.0) / STEP;
        let r0 = (y.floor() as usize).min(ROWS - 2);
        let c0 = (x.floor() as usize).min(COLS - 1);
        let c1 = (c0 + 1) % COLS;
        let (fy, fx) = (y - r0 as f64, x - c0 as f64);
        let at = |r: usize, c: usize| f64::from(g[r * COLS + c]) / 100.0;
        let north = at(r0, c0) + fx * (at(r0, c1) - at(r0, c0));
        let south = at(r0 + 1, c0) + fx * (at(r0 + 1, c1) - at(r0 + 1, c0));
        north + fy * (south - north)
    }

    proptest! {
        /// One parallel's rows found once give every longitude's undulation as the
        /// per-call formula does, bit for bit: within a turn of [0, 360), far outside it,
        /// and at the edges.
        #[test]
        fn a_parallel_gives_the_per_point_values(
            lat in -95.0f64..95.0,
            lons in proptest::collection::vec(-1000.0f64..1000.0, 1..40),
        ) {
            let row = Egm96Row::new(lat);
            let edges = [-360.0, -180.0, -1e-300, -0.0, 0.0, 1e-300, 359.999_999_999, 360.0, 720.0, -720.5];
            for lon in lons.iter().chain(&edges) {
                prop_assert_eq!(row.at(*lon).to_bits(), reference(lat, *lon).to_bits(), "{} {}", lat, lon);
                prop_assert_eq!(egm96_undulation(lat, *lon).to_bits(), reference(lat, *lon).to_bits());
            }
        }
    }

    #[test]
    fn not_finite_in_nan_out() {
        assert!(Egm96Row::new(f64::NAN).at(10.0).is_nan());
        assert!(Egm96Row::new(10.0).at(f64::INFINITY).is_nan());
        assert!(egm96_undulation(f64::NEG_INFINITY, 0.0).is_nan());
    }

    /// NGA's test values for EGM96 (the distribution's `readme.txt`: latitude, longitude
    /// east, undulation in metres, from the spherical-harmonic model to degree 360), and how
    /// far bilinear interpolation on the 15' grid is from each, measured: the largest is
    /// 0.014 m.
    #[test]
    fn nga_reference_values() {
        let reference = [
            (38.628_155, 269.779_155, -31.628),
            (-14.621_217, 305.021_114, -2.969),
            (46.874_319, 102.448_729, -43.575),
            (-23.617_446, 133.874_712, 15.871),
            (38.625_473, 359.999_500, 50.066),
            (-0.466_744, 0.002_300, 17.329),
        ];
        for (lat, lon, n) in reference {
            let ours = egm96_undulation(lat, lon);
            assert!(
                (ours - n).abs() <= 0.06,
                "at {lat}, {lon}: {ours} m where NGA says {n} m"
            );
            // The same place by its longitude west of Greenwich.
            assert!((egm96_undulation(lat, lon - 360.0) - ours).abs() < 1e-9);
        }
    }

    /// At a grid node the value is the grid's; the grid's range is EGM96's (−107 m south of
    /// India to +86 m over New Guinea); the poles are one value each.
    #[test]
    fn nodes_range_and_poles() {
        let g = grid();
        assert_eq!(g.len(), ROWS * COLS);
        let (lo, hi) = (g.iter().min().copied(), g.iter().max().copied());
        assert_eq!((lo, hi), (Some(-10699), Some(8539)));
        assert_eq!(egm96_undulation(90.0, 0.0), f64::from(g[0]) / 100.0);
        assert_eq!(egm96_undulation(-90.0, 123.0), egm96_undulation(-90.0, -7.0));
        assert_eq!(
            egm96_undulation(45.0, 7.25),
            f64::from(g[180 * COLS + 29]) / 100.0
        );
        assert!(egm96_undulation(f64::NAN, 0.0).is_nan());
    }

    /// Every datum's name parses back to it, and its stored code back to it; 0 (not
    /// recorded) and unknown codes are no datum; names are case-blind, and a wrong one is
    /// refused with the list.
    #[test]
    fn names_and_codes_round_trip() {
        for d in VerticalDatum::ALL {
            assert_eq!(VerticalDatum::parse(d.name()), Ok(d));
            assert_eq!(VerticalDatum::parse(&d.name().to_uppercase()), Ok(d));
            assert_eq!(VerticalDatum::from_code(d.code()), Some(d));
        }
        let codes: std::collections::BTreeSet<u8> =
            VerticalDatum::ALL.iter().map(|d| d.code()).collect();
        assert_eq!(codes.len(), 4);
        assert!(!codes.contains(&0));
        assert_eq!(VerticalDatum::from_code(0), None);
        assert_eq!(VerticalDatum::from_code(5), None);
        assert_eq!(VerticalDatum::parse("WGS84"), Ok(VerticalDatum::Ellipsoid));
        assert!(VerticalDatum::parse("navd88").is_err_and(|e| e.contains("egm2008")));
        assert_eq!(VerticalDatum::of_epsg(5773), VerticalDatum::Egm96);
        assert_eq!(VerticalDatum::of_epsg(3855), VerticalDatum::Egm2008);
        assert_eq!(VerticalDatum::of_epsg(5703), VerticalDatum::Unknown);
        assert!(VerticalDatum::Egm2008.lift().is_err());
        assert_eq!(VerticalDatum::Egm96.lift(), Ok(Lift::Egm96));
        assert_eq!(VerticalDatum::Unknown.lift(), Ok(Lift::None));
    }

    /// The range over a box holds every interpolated value inside it, and is the nodes'
    /// range when the box is a cell; a huge box takes the grid's range, which holds all.
    #[test]
    fn ranges_hold_what_is_inside() {
        let g = grid();
        let (lo, hi) = (
            f64::from(*g.iter().min().unwrap()) / 100.0,
            f64::from(*g.iter().max().unwrap()) / 100.0,
        );
        assert_eq!(egm96_range(-180.0, 180.0, -90.0, 90.0), (-106.99, 85.39));
        assert_eq!((lo, hi), (-106.99, 85.39));
        let mut seed = 7u64;
        let mut next = || {
            seed = seed.wrapping_mul(6364136223846793005).wrapping_add(1442695040888963407);
            (seed >> 11) as f64 / (1u64 << 53) as f64
        };
        for _ in 0..300 {
            let lon = next() * 360.0 - 180.0;
            let lat = next() * 170.0 - 85.0;
            let (dlon, dlat) = (next() * 3.0, next() * 3.0);
            let (a, b) = egm96_range(lon, lon + dlon, lat, lat + dlat);
            for _ in 0..50 {
                let n = egm96_undulation(lat + next() * dlat, lon + next() * dlon);
                assert!(a <= n && n <= b, "{n} outside {a}..{b} at {lon}, {lat}");
            }
        }
    }
}
