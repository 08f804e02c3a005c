//! Coordinate reference systems: what a georeference's coordinates are (degrees of longitude
//! and latitude, or a projected CRS's linear unit), how far apart in metres its samples lie,
//! and the way back to longitude and latitude.
//!
//! The ingest readers need one fact to turn a grid step into metres: whether the CRS is
//! geographic, and if not, the metres in its linear unit. State-plane systems count in US
//! survey feet (1200/3937 m) or international feet (0.3048 m), so taking every projected
//! coordinate as metres is wrong by 3.28× for them. The facts come from three places:
//!
//! * an EPSG code ([`Crs::from_epsg`]), looked up in the EPSG registry as shipped by the
//!   `crs-definitions` crate (PROJ strings for every EPSG CRS);
//! * WKT (WKT1 as in ESRI `.prj` files and GDAL's output, or WKT2), parsed here
//!   ([`Crs::from_wkt`]): the root keyword says geographic or projected, the projected CRS's
//!   own `UNIT` / `LENGTHUNIT` gives the unit, an `AUTHORITY` / `ID` the EPSG code;
//! * a name fmrh stored itself ([`Crs::parse`]): `EPSG:n`, or WKT.
//!
//! Longitude and latitude of projected coordinates ([`Crs::to_lon_lat`]) go through
//! `proj4rs`, a pure-Rust port of PROJ.4, from the EPSG registry's PROJ string. A CRS known
//! only by WKT without an EPSG code has no such string: its bounds stay in CRS units.
//!
//! Nothing here knows of files or grids; the readers ask, and [`geographic_spacing`] answers
//! for degrees.

/// What kind of coordinates a CRS has.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum CrsKind {
    /// Longitude and latitude in degrees.
    Geographic,
    /// Easting and northing in a linear unit: `metres_per_unit` when known.
    Projected {
        /// Metres in one unit of the CRS's coordinates (1 for metres, 0.3048 for feet).
        metres_per_unit: Option<f64>,
    },
    /// Something fmrh cannot place on the ground (geocentric, vertical, engineering).
    Other,
}

/// A coordinate reference system, as far as fmrh needs one.
#[derive(Clone, Debug, PartialEq)]
pub struct Crs {
    /// The EPSG code, when the source gave one.
    pub epsg: Option<u32>,
    /// Geographic, projected (with its unit), or other.
    pub kind: CrsKind,
    /// The PROJ string, from the EPSG registry, when the code is known to it.
    proj4: Option<&'static str>,
}

/// Metres per degree-of-arc in WGS 84: semi-major axis and first eccentricity squared.
const WGS84_A: f64 = 6_378_137.0;
const WGS84_E2: f64 = 6.694_379_990_141_316e-3;

/// Ground spacing `[east, south]` in metres of a geographic grid whose steps are `step_deg`
/// degrees, at latitude `lat_deg`, on the WGS 84 ellipsoid: a degree of longitude is
/// `π/180 · N cos φ`, a degree of latitude `π/180 · M`, with `N` and `M` the prime-vertical and
/// meridional radii of curvature. (A sphere of the equatorial radius is up to 0.7 % off in the
/// north-south step; other datums' ellipsoids differ from WGS 84's by under 0.01 %.)
pub fn geographic_spacing(step_deg: [f64; 2], lat_deg: f64) -> [f64; 2] {
    let phi = lat_deg.clamp(-90.0, 90.0).to_radians();
    let w = 1.0 - WGS84_E2 * phi.sin().powi(2);
    let n = WGS84_A / w.sqrt();
    let m = WGS84_A * (1.0 - WGS84_E2) / (w * w.sqrt());
    let rad = std::f64::consts::PI / 180.0;
    [
        step_deg[0].abs() * rad * n * phi.cos(),
        step_deg[1].abs() * rad * m,
    ]
}

/// Metres per unit of the EPSG linear unit `code`, for the units projected CRSs use.
pub fn epsg_linear_unit(code: u32) -> Option<f64> {
    Some(match code {
        9001 => 1.0,             // metre
        9002 => 0.3048,          // international foot
        9003 => 1200.0 / 3937.0, // US survey foot
        9005 => 0.304_797_265_4, // Clarke's foot
        9030 => 1852.0,          // nautical mile
        9036 => 1000.0,          // kilometre
        9093 => 1609.344,        // statute mile
        _ => return None,
    })
}

impl Crs {
    /// The CRS with EPSG code `code`, when the registry knows it.
    pub fn from_epsg(code: u32) -> Option<Crs> {
        let def = crs_definitions::from_code(u16::try_from(code).ok()?)?;
        let proj4 = def.proj4;
        let kind = if proj4_param(proj4, "proj").is_some_and(|p| p == "longlat" || p == "latlong") {
            CrsKind::Geographic
        } else if proj4_param(proj4, "proj") == Some("geocent") {
            CrsKind::Other
        } else {
            CrsKind::Projected {
                metres_per_unit: proj4_metres_per_unit(proj4),
            }
        };
        Some(Crs {
            epsg: Some(code),
            kind,
            proj4: Some(proj4),
        })
    }

    /// A CRS from WKT (WKT1, including ESRI's `.prj` flavour, or WKT2).
    pub fn from_wkt(text: &str) -> Result<Crs, String> {
        let root = wkt::parse(text)?;
        let root = match root.keyword.as_str() {
            // A compound CRS: its horizontal part is what places samples.
            "COMPD_CS" | "COMPOUNDCRS" => root
                .children()
                .find(|c| c.keyword != "VERT_CS" && c.keyword != "VERTCRS")
                .ok_or("a compound CRS without a horizontal part")?,
            _ => &root,
        };
        let epsg = root
            .children()
            .find(|c| c.keyword == "AUTHORITY" || c.keyword == "ID")
            .filter(|c| c.string(0).is_some_and(|a| a.eq_ignore_ascii_case("EPSG")))
            .and_then(|c| c.number_or_string(1))
            .and_then(|v| v.parse::<u32>().ok());
        let kind = match root.keyword.as_str() {
            "GEOGCS" | "GEOGCRS" | "GEOGRAPHICCRS" => {
                // Degrees are what the readers' steps mean; another angular unit (grads,
                // radians) would need converting, so it is left unknown.
                let degrees = root
                    .children()
                    .find(|c| c.keyword == "UNIT" || c.keyword == "ANGLEUNIT")
                    .and_then(|u| u.number(1))
                    .is_none_or(|f| (f - std::f64::consts::PI / 180.0).abs() < 1e-12);
                if degrees {
                    CrsKind::Geographic
                } else {
                    CrsKind::Other
                }
            }
            "PROJCS" | "PROJCRS" | "PROJECTEDCRS" => {
                // The projected CRS's own unit: WKT1 puts it among PROJCS's children (the
                // GEOGCS child has its own, angular, UNIT); WKT2 in the CS's axes or after CS.
                let unit = root
                    .children()
                    .find(|c| c.keyword == "UNIT" || c.keyword == "LENGTHUNIT")
                    .or_else(|| {
                        root.children()
                            .filter(|c| c.keyword == "AXIS")
                            .find_map(|a| a.children().find(|c| c.keyword == "LENGTHUNIT"))
                    })
                    .and_then(|u| u.number(1))
                    .filter(|f| f.is_finite() && *f > 0.0);
                CrsKind::Projected {
                    metres_per_unit: unit,
                }
            }
            _ => CrsKind::Other,
        };
        // No code in the WKT (an ESRI `.prj`): the registry's CRS that is the same datum,
        // projection and parameters, if one is.
        let epsg = epsg.or_else(|| {
            resolve::epsg_of(root)
                .filter(|&c| Crs::from_epsg(c).is_some_and(|c| kind_matches(c.kind, kind)))
        });
        let proj4 = epsg
            .and_then(Crs::from_epsg)
            .filter(|c| kind_matches(c.kind, kind))
            .and_then(|c| c.proj4);
        Ok(Crs { epsg, kind, proj4 })
    }

    /// The name a WKT gives its CRS (the root's first string), for display.
    pub fn wkt_name(text: &str) -> Option<String> {
        wkt::parse(text).ok()?.string(0).map(str::to_owned)
    }

    /// A CRS as a user gives it (`--crs`): `EPSG:n`, WKT, or a PROJ string the EPSG
    /// registry has (the same parameters, in any order). An error says why not.
    pub fn from_user(text: &str) -> Result<Crs, String> {
        let text = text.trim();
        if let Some(code) = text
            .strip_prefix("EPSG:")
            .or_else(|| text.strip_prefix("epsg:"))
        {
            let code: u32 = code
                .trim()
                .parse()
                .map_err(|_| format!("--crs {text}: not an EPSG code"))?;
            return Crs::from_epsg(code)
                .ok_or_else(|| format!("--crs {text}: the EPSG registry fmrh has knows no such CRS"));
        }
        if text.contains('[') {
            return Crs::from_wkt(text).map_err(|e| format!("--crs: {e}"));
        }
        if text.starts_with("+proj=") || text.contains(" +proj=") {
            return resolve::epsg_of_proj4(text)
                .and_then(Crs::from_epsg)
                .ok_or_else(|| {
                    format!(
                        "--crs {text}: no EPSG code has this PROJ string; give EPSG:N or WKT"
                    )
                });
        }
        Err(format!("--crs {text}: give EPSG:N, WKT or a PROJ string (+proj=...)"))
    }

    /// A CRS from the name a georeference carries: `EPSG:n`, or WKT.
    pub fn parse(name: &str) -> Option<Crs> {
        let name = name.trim();
        if let Some(code) = name
            .strip_prefix("EPSG:")
            .or_else(|| name.strip_prefix("epsg:"))
        {
            return Crs::from_epsg(code.trim().parse().ok()?);
        }
        Crs::from_wkt(name).ok()
    }

    /// Metres per coordinate unit of a projected CRS, when known.
    #[cfg(any(test, feature = "testing"))]
    pub fn metres_per_unit(&self) -> Option<f64> {
        match self.kind {
            CrsKind::Projected { metres_per_unit } => metres_per_unit,
            _ => None,
        }
    }

    /// Ground spacing in metres of a grid whose steps are `step` CRS units, `centre_lat` being
    /// the grid's middle latitude for a geographic CRS. `None` when the unit is unknown.
    pub fn spacing(&self, step: [f64; 2], centre_lat: f64) -> Option<[f64; 2]> {
        self.kind.spacing(step, centre_lat)
    }

    /// Longitude and latitude in degrees (WGS 84) of the CRS point `(x, y)`: the point itself
    /// for a geographic CRS, the inverse projection for a projected one whose EPSG code the
    /// registry knows. `None` otherwise, or where the projection has no inverse.
    ///
    /// A datum whose shift to WGS 84 needs PROJ's grid files (NAD27 and a few others) is
    /// taken on its own ellipsoid with no shift: the answer is then off by the datum shift,
    /// at most about 100 m (under 0.002°) in North America. Good enough for bounds; not a
    /// survey conversion.
    pub fn to_lon_lat(&self, x: f64, y: f64) -> Option<[f64; 2]> {
        self.to_lon_lat_all(&[[x, y]])
            .and_then(|v| v.first().copied())
    }

    /// [`Crs::to_lon_lat`] of every point, the projections set up once; `None` if any
    /// point has no answer.
    pub fn to_lon_lat_all(&self, points: &[[f64; 2]]) -> Option<Vec<[f64; 2]>> {
        match self.kind {
            CrsKind::Geographic => Some(points.to_vec()),
            CrsKind::Projected { .. } => {
                let proj4 = self.proj4?;
                inverse(proj4, points).or_else(|| inverse(&without_grid_shift(proj4), points))
            }
            CrsKind::Other => None,
        }
    }
}

impl Crs {
    /// The CRS coordinates of each WGS 84 longitude and latitude in `points` (degrees): the
    /// inverse of [`Crs::to_lon_lat_all`], with the same datum caveat. `None` if any point
    /// has no answer (outside the projection's domain) or the CRS has no PROJ string.
    pub fn lon_lat_to_crs_all(&self, points: &[[f64; 2]]) -> Option<Vec<[f64; 2]>> {
        match self.kind {
            CrsKind::Geographic => Some(points.to_vec()),
            CrsKind::Projected { .. } => {
                let proj4 = self.proj4?;
                forward(proj4, points).or_else(|| forward(&without_grid_shift(proj4), points))
            }
            CrsKind::Other => None,
        }
    }
}

impl CrsKind {
    /// Ground spacing in metres of steps of `step` units (see [`Crs::spacing`]).
    pub fn spacing(self, step: [f64; 2], centre_lat: f64) -> Option<[f64; 2]> {
        match self {
            CrsKind::Geographic => Some(geographic_spacing(step, centre_lat)),
            CrsKind::Projected {
                metres_per_unit: Some(m),
            } => Some([step[0].abs() * m, step[1].abs() * m]),
            _ => None,
        }
    }
}

/// The WGS 84 longitude and latitude of each of `points` under the PROJ string `proj4`.
fn inverse(proj4: &str, points: &[[f64; 2]]) -> Option<Vec<[f64; 2]>> {
    let from = proj4rs::Proj::from_proj_string(proj4).ok()?;
    let to = proj4rs::Proj::from_proj_string("+proj=longlat +datum=WGS84 +no_defs").ok()?;
    points
        .iter()
        .map(|&[x, y]| {
            let mut p = (x, y, 0.0);
            proj4rs::transform::transform(&from, &to, &mut p).ok()?;
            let (lon, lat) = (p.0.to_degrees(), p.1.to_degrees());
            (lon.is_finite() && lat.is_finite() && lat.abs() <= 90.0).then_some([lon, lat])
        })
        .collect()
}

/// The coordinates under the PROJ string `proj4` of each WGS 84 longitude and latitude of
/// `points` (degrees).
fn forward(proj4: &str, points: &[[f64; 2]]) -> Option<Vec<[f64; 2]>> {
    let from = proj4rs::Proj::from_proj_string("+proj=longlat +datum=WGS84 +no_defs").ok()?;
    let to = proj4rs::Proj::from_proj_string(proj4).ok()?;
    points
        .iter()
        .map(|&[lon, lat]| {
            let mut p = (lon.to_radians(), lat.to_radians(), 0.0);
            proj4rs::transform::transform(&from, &to, &mut p).ok()?;
            (p.0.is_finite() && p.1.is_finite()).then_some([p.0, p.1])
        })
        .collect()
}

/// `proj4` with a grid-shift datum replaced by its bare ellipsoid.
fn without_grid_shift(proj4: &str) -> String {
    proj4
        .split_whitespace()
        .filter(|t| !t.starts_with("+nadgrids="))
        .map(|t| match t {
            "+datum=NAD27" => "+ellps=clrk66",
            "+datum=potsdam" => "+ellps=bessel",
            "+datum=nzgd49" => "+ellps=intl",
            other => other,
        })
        .collect::<Vec<_>>()
        .join(" ")
}

fn kind_matches(a: CrsKind, b: CrsKind) -> bool {
    matches!(
        (a, b),
        (CrsKind::Geographic, CrsKind::Geographic)
            | (CrsKind::Projected { .. }, CrsKind::Projected { .. })
    )
}

/// The value of `+key=value` in a PROJ string.
fn proj4_param<'a>(proj4: &'a str, key: &str) -> Option<&'a str> {
    proj4.split_whitespace().find_map(|t| {
        let (k, v) = t.strip_prefix('+')?.split_once('=')?;
        (k == key).then_some(v)
    })
}

/// Metres per unit of a projected PROJ string: `+to_meter` wins over `+units`; neither
/// means metres (PROJ's default).
fn proj4_metres_per_unit(proj4: &str) -> Option<f64> {
    if let Some(f) = proj4_param(proj4, "to_meter") {
        return f.parse().ok().filter(|f: &f64| f.is_finite() && *f > 0.0);
    }
    match proj4_param(proj4, "units") {
        None | Some("m") => Some(1.0),
        Some("km") => Some(1000.0),
        Some("ft") => Some(0.3048),
        Some("us-ft") => Some(1200.0 / 3937.0),
        Some("yd") => Some(0.9144),
        Some("us-yd") => Some(3600.0 / 3937.0),
        Some("mi") => Some(1609.344),
        Some("us-mi") => Some(6_336_000.0 / 3937.0),
        Some("kmi") => Some(1852.0),
        Some("link") => Some(0.201_168),
        Some("ch") => Some(20.1168),
        Some("cm") => Some(0.01),
        _ => None,
    }
}

mod resolve;

/// A small WKT reader: `KEYWORD[value, value, ...]` trees (or with parentheses), values being
/// quoted strings, numbers, bare words or nested nodes. It keeps no meaning; `Crs` asks.
mod wkt {
    /// A node: `KEYWORD[...]`.
    #[derive(Debug)]
    pub struct Node {
        pub keyword: String,
        pub args: Vec<Value>,
    }

    #[derive(Debug)]
    pub enum Value {
        Text(String),
        Number(String),
        Node(Node),
    }

    /// The deepest nesting accepted: real CRSs need under 10 levels.
    const MAX_DEPTH: usize = 32;

    impl Node {
        pub fn children(&self) -> impl Iterator<Item = &Node> {
            self.args.iter().filter_map(|a| match a {
                Value::Node(n) => Some(n),
                _ => None,
            })
        }

        pub fn string(&self, i: usize) -> Option<&str> {
            match self.args.get(i)? {
                Value::Text(s) => Some(s),
                _ => None,
            }
        }

        pub fn number(&self, i: usize) -> Option<f64> {
            match self.args.get(i)? {
                Value::Number(s) => s.parse().ok(),
                _ => None,
            }
        }

        pub fn number_or_string(&self, i: usize) -> Option<&str> {
            match self.args.get(i)? {
                Value::Text(s) | Value::Number(s) => Some(s.trim()),
                Value::Node(_) => None,
            }
        }
    }

    pub fn parse(text: &str) -> Result<Node, String> {
        let mut p = Parser {
            s: text.as_bytes(),
            i: 0,
        };
        p.skip_space();
        let node = p.node(0)?;
        p.skip_space();
        if p.i != p.s.len() {
            return Err(format!("WKT: unexpected text at byte {}", p.i));
        }
        Ok(node)
    }

    struct Parser<'a> {
        s: &'a [u8],
        i: usize,
    }

    impl Parser<'_> {
        fn skip_space(&mut self) {
            while self.s.get(self.i).is_some_and(u8::is_ascii_whitespace) {
                self.i += 1;
            }
        }

        fn word(&mut self) -> String {
            let start = self.i;
            while self
                .s
                .get(self.i)
                .is_some_and(|c| c.is_ascii_alphanumeric() || *c == b'_')
            {
                self.i += 1;
            }
            String::from_utf8_lossy(&self.s[start..self.i]).to_ascii_uppercase()
        }

        fn node(&mut self, depth: usize) -> Result<Node, String> {
            if depth > MAX_DEPTH {
                return Err("WKT: nested too deeply".into());
            }
            let keyword = self.word();
            if keyword.is_empty() {
                return Err(format!("WKT: expected a keyword at byte {}", self.i));
            }
            self.skip_space();
            let close = match self.s.get(self.i) {
                Some(b'[') => b']',
                Some(b'(') => b')',
                _ => {
                    return Err(format!("WKT: expected '[' after {keyword}"));
                }
            };
            self.i += 1;
            let mut args = Vec::new();
            loop {
                self.skip_space();
                match self.s.get(self.i) {
                    None => return Err(format!("WKT: {keyword}[ is never closed")),
                    Some(&c) if c == close => {
                        self.i += 1;
                        return Ok(Node { keyword, args });
                    }
                    Some(b',') if !args.is_empty() => {
                        self.i += 1;
                        self.skip_space();
                    }
                    Some(_) if args.is_empty() => {}
                    Some(_) => return Err(format!("WKT: expected ',' at byte {}", self.i)),
                }
                args.push(self.value(depth)?);
            }
        }

        fn value(&mut self, depth: usize) -> Result<Value, String> {
            match self.s.get(self.i) {
                Some(b'"') => {
                    // A quoted string; `""` inside is a literal quote (WKT2).
                    let mut out = Vec::new();
                    self.i += 1;
                    loop {
                        match self.s.get(self.i) {
                            None => return Err("WKT: a string is never closed".into()),
                            Some(b'"') if self.s.get(self.i + 1) == Some(&b'"') => {
                                out.push(b'"');
                                self.i += 2;
                            }
                            Some(b'"') => {
                                self.i += 1;
                                return Ok(Value::Text(String::from_utf8_lossy(&out).into()));
                            }
                            Some(&c) => {
                                out.push(c);
                                self.i += 1;
                            }
                        }
                    }
                }
                Some(c) if c.is_ascii_digit() || matches!(c, b'-' | b'+' | b'.') => {
                    let start = self.i;
                    while self.s.get(self.i).is_some_and(|c| {
                        c.is_ascii_alphanumeric() || matches!(c, b'-' | b'+' | b'.')
                    }) {
                        self.i += 1;
                    }
                    Ok(Value::Number(
                        String::from_utf8_lossy(&self.s[start..self.i]).into(),
                    ))
                }
                Some(c) if c.is_ascii_alphabetic() => {
                    let save = self.i;
                    let word = self.word();
                    self.skip_space();
                    if matches!(self.s.get(self.i), Some(b'[' | b'(')) {
                        self.i = save;
                        Ok(Value::Node(self.node(depth + 1)?))
                    } else {
                        // A bare enumeration value, e.g. AXIS["x", EAST].
                        Ok(Value::Text(word))
                    }
                }
                _ => Err(format!("WKT: unexpected character at byte {}", self.i)),
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    const US_FT: f64 = 1200.0 / 3937.0;

    #[test]
    fn epsg_codes_give_kind_and_unit() {
        let wa = Crs::from_epsg(2927).expect("EPSG:2927");
        assert_eq!(
            wa.kind,
            CrsKind::Projected {
                metres_per_unit: Some(US_FT)
            }
        );
        assert_eq!(
            Crs::from_epsg(4326).map(|c| c.kind),
            Some(CrsKind::Geographic)
        );
        assert_eq!(
            Crs::from_epsg(32610).and_then(|c| c.metres_per_unit()),
            Some(1.0)
        );
        assert_eq!(
            Crs::from_epsg(2222).and_then(|c| c.metres_per_unit()),
            Some(0.3048)
        );
        assert_eq!(Crs::from_epsg(1), None);
        assert_eq!(Crs::from_epsg(1 << 20), None);
    }

    #[test]
    fn wkt1_esri_prj() {
        let prj = r#"PROJCS["NAD_1983_HARN_StatePlane_Washington_South_FIPS_4602_Feet",GEOGCS["GCS_North_American_1983_HARN",DATUM["D_North_American_1983_HARN",SPHEROID["GRS_1980",6378137.0,298.257222101]],PRIMEM["Greenwich",0.0],UNIT["Degree",0.0174532925199433]],PROJECTION["Lambert_Conformal_Conic"],PARAMETER["False_Easting",1640416.666666667],PARAMETER["Standard_Parallel_1",45.83333333333334],UNIT["Foot_US",0.3048006096012192]]"#;
        let crs = Crs::from_wkt(prj).expect("parses");
        assert_eq!(crs.epsg, None);
        assert_eq!(
            Crs::wkt_name(prj).as_deref(),
            Some("NAD_1983_HARN_StatePlane_Washington_South_FIPS_4602_Feet")
        );
        let m = crs.metres_per_unit().expect("unit");
        assert!((m - US_FT).abs() < 1e-12);
        assert_eq!(
            crs.to_lon_lat(0.0, 0.0),
            None,
            "no EPSG code, no PROJ string"
        );
    }

    #[test]
    fn wkt1_with_authority_and_wkt2() {
        let wkt1 = r#"GEOGCS["WGS 84",DATUM["WGS_1984",SPHEROID["WGS 84",6378137,298.257223563,AUTHORITY["EPSG","7030"]]],PRIMEM["Greenwich",0],UNIT["degree",0.0174532925199433,AUTHORITY["EPSG","9122"]],AUTHORITY["EPSG","4326"]]"#;
        let crs = Crs::from_wkt(wkt1).expect("parses");
        assert_eq!((crs.epsg, crs.kind), (Some(4326), CrsKind::Geographic));
        let wkt2 = r#"PROJCRS["NAD83(HARN) / Washington South (ftUS)",
            BASEGEOGCRS["NAD83(HARN)",DATUM["NAD83 (High Accuracy Reference Network)",
            ELLIPSOID["GRS 1980",6378137,298.257222101,LENGTHUNIT["metre",1]]],
            PRIMEM["Greenwich",0,ANGLEUNIT["degree",0.0174532925199433]]],
            CONVERSION["SPCS83 Washington South zone (US survey foot)",
            METHOD["Lambert Conic Conformal (2SP)",ID["EPSG",9802]]],
            CS[Cartesian,2],
            AXIS["easting (X)",east,ORDER[1],LENGTHUNIT["US survey foot",0.304800609601219]],
            AXIS["northing (Y)",north,ORDER[2],LENGTHUNIT["US survey foot",0.304800609601219]],
            ID["EPSG",2927]]"#;
        let crs = Crs::from_wkt(wkt2).expect("parses");
        assert_eq!(crs.epsg, Some(2927));
        assert!((crs.metres_per_unit().expect("unit") - US_FT).abs() < 1e-9);
        let [lon, lat] = crs.to_lon_lat(1_042_127.0, 631_474.0).expect("inverse");
        assert!(
            (lon + 122.9).abs() < 1e-3 && (lat - 47.04).abs() < 1e-3,
            "{lon} {lat}"
        );
    }

    #[test]
    fn nad27_bounds_without_grid_files() {
        // Mount St Helens' USGS DEM corner, EPSG:26710; GDAL (with its grids) says
        // 122°15'0.36"W, 46°15'4.05"N.
        let [lon, lat] = Crs::from_epsg(26710)
            .and_then(|c| c.to_lon_lat(557_805.0, 5_122_005.0))
            .expect("inverse");
        let (want_lon, want_lat) = (
            -(122.0 + 15.0 / 60.0 + 0.36 / 3600.0),
            46.0 + 15.0 / 60.0 + 4.05 / 3600.0,
        );
        assert!(
            (lon - want_lon).abs() < 0.002 && (lat - want_lat).abs() < 0.002,
            "{lon} {lat}"
        );
    }

    #[test]
    fn malformed_wkt_is_an_error() {
        for bad in [
            "",
            "PROJCS[",
            "PROJCS[\"x\"",
            "PROJCS[\"x\",,]",
            "PROJCS[\"x\"] trailing",
            "[1]",
            &"A[".repeat(100),
        ] {
            assert!(Crs::from_wkt(bad).is_err(), "{bad:?}");
        }
    }

    #[test]
    fn ellipsoidal_spacing() {
        // One arc-second at the equator: 30.922 m east (a·π/180/3600), 30.72 m north.
        let [e, n] = geographic_spacing([1.0 / 3600.0; 2], 0.0);
        assert!((e - 30.9221).abs() < 1e-3, "{e}");
        assert!((n - 30.7152).abs() < 1e-3, "{n}");
        // At 60°: a degree of latitude is 111,412 m, of longitude 55,800 m.
        let [e, n] = geographic_spacing([1.0; 2], 60.0);
        assert!((n - 111_412.0).abs() < 2.0, "{n}");
        assert!((e - 55_800.0).abs() < 2.0, "{e}");
    }

    proptest::proptest! {
        /// Any text, and any prefix of a real WKT, parses or is refused; nothing panics.
        #[test]
        fn wkt_parser_never_panics(text in "[A-Z\\[\\](),\"0-9. _-]{0,200}", cut in 0usize..400) {
            let _ = Crs::from_wkt(&text);
            let real = r#"PROJCS["x",GEOGCS["g",UNIT["degree",0.0174532925199433]],UNIT["Foot_US",0.3048006096012192],AUTHORITY["EPSG","2927"]]"#;
            let _ = Crs::from_wkt(&real[..cut.min(real.len())]);
        }
    }

    proptest::proptest! {
        /// Projecting a longitude and latitude into a projected CRS and back gives the point
        /// again (UTM 10N and Washington state plane in feet, near their zones), and a
        /// geographic CRS leaves it as it is.
        #[test]
        fn forward_then_inverse_is_the_point(
            lon in -124.5f64..-119.5, lat in 44.0f64..49.0, code_at in 0usize..2,
        ) {
            let crs = Crs::from_epsg([32610, 2927][code_at]).expect("in the registry");
            let xy = crs.lon_lat_to_crs_all(&[[lon, lat]]).expect("forward");
            let back = crs.to_lon_lat_all(&xy).expect("inverse");
            proptest::prop_assert!(
                (back[0][0] - lon).abs() < 1e-7 && (back[0][1] - lat).abs() < 1e-7,
                "{lon} {lat} -> {xy:?} -> {back:?}"
            );
            let geographic = Crs::from_epsg(4326).expect("4326");
            proptest::prop_assert_eq!(geographic.lon_lat_to_crs_all(&[[lon, lat]]), Some(vec![[lon, lat]]));
        }
    }

    /// A known UTM coordinate: 123° W on the equator is zone 10's central meridian, at
    /// easting 500,000 m.
    #[test]
    fn forward_projection_of_a_known_point() {
        let crs = Crs::from_epsg(32610).expect("UTM 10N");
        let [[x, y]] = crs.lon_lat_to_crs_all(&[[-123.0, 0.0]]).expect("forward")[..] else {
            panic!("one point");
        };
        assert!((x - 500_000.0).abs() < 1e-6 && y.abs() < 1e-6, "{x} {y}");
    }

    #[test]
    fn parse_names() {
        assert_eq!(Crs::parse("EPSG:2927").and_then(|c| c.epsg), Some(2927));
        assert_eq!(Crs::parse("EPSG:x"), None);
        assert_eq!(Crs::parse("not a crs"), None);
    }
}
