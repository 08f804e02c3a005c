//! Which EPSG code a WKT describes, when it does not say: an ESRI `.prj` (WKT1 without
//! authority codes), OGC WKT1 or WKT2 stripped of its `ID`. Compared as GDAL's `-e` does,
//! by what the CRS *is*, not by its name: the datum (its EPSG code when the WKT gives one,
//! else its name through the aliases ESRI and EPSG use for the same datum, and its
//! ellipsoid), the prime meridian, the projection method and every parameter (angles in
//! degrees, lengths in metres, so a false easting in US survey feet matches its metres),
//! and the linear unit. The candidates are every CRS of the EPSG registry as the
//! `crs-definitions` crate ships it (WKT1 with datum codes), read once, on first use, with
//! the same parser.
//!
//! A WKT that matches no code, or a datum fmrh has no alias for, stays unresolved: the
//! caller keeps the WKT and says so. Among several codes that match (the registry has a few
//! duplicates), the lowest is taken.

use std::collections::BTreeMap;
use std::sync::OnceLock;

use super::wkt::Node;

/// What a CRS is, as compared here.
#[derive(Clone, Debug)]
struct Shape {
    datum: Datum,
    /// `None` for a geographic CRS.
    projection: Option<Projection>,
}

#[derive(Clone, Debug)]
struct Datum {
    /// The datum's EPSG code (6xxx), when the WKT gives one.
    code: Option<u32>,
    /// The datum's name, normalized through the aliases ([`datum_key`]).
    key: String,
    /// Semi-major axis (metres) and inverse flattening (0 for a sphere).
    a: f64,
    rf: f64,
    /// Prime meridian, degrees east of Greenwich.
    pm: f64,
}

#[derive(Clone, Debug)]
struct Projection {
    method: Method,
    /// Canonical parameters: `lat_0`, `lon_0`, `lat_1`, `lat_2`, `k`, `x_0`, `y_0`; angles
    /// in degrees, lengths in metres.
    params: BTreeMap<&'static str, f64>,
    /// Metres in the CRS's linear unit.
    unit_m: f64,
    /// Whether the first axis is northing (some national grids); `None` when the WKT does
    /// not say (ESRI's never does).
    northing_first: Option<bool>,
}

#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum Method {
    TransverseMercator,
    LambertConic1Sp,
    LambertConic2Sp,
    AlbersEqualArea,
    Mercator1Sp,
    Mercator2Sp,
    WebMercator,
    LambertAzimuthalEqualArea,
    ObliqueStereographic,
    PolarStereographicA,
    PolarStereographicB,
    EquidistantCylindrical,
}

/// Lowercase letters and digits only.
fn squash(s: &str) -> String {
    s.chars()
        .filter(char::is_ascii_alphanumeric)
        .map(|c| c.to_ascii_lowercase())
        .collect()
}

/// A datum's name as compared: squashed, ESRI's `D_` dropped, and the names ESRI, EPSG's
/// WKT1 and WKT2 give one datum brought to one.
fn datum_key(name: &str) -> String {
    let trimmed = name.trim();
    let trimmed = trimmed
        .strip_prefix("D_")
        .or_else(|| trimmed.strip_prefix("d_"))
        .unwrap_or(trimmed);
    let mut k = squash(trimmed);
    if let Some(s) = k.strip_suffix("ensemble") {
        k = s.to_string();
    }
    let alias = match k.as_str() {
        "worldgeodeticsystem1984" => "wgs1984",
        "worldgeodeticsystem1972" => "wgs1972",
        "northamerican1983" | "nad1983" => "northamericandatum1983",
        "northamerican1927" | "nad1927" => "northamericandatum1927",
        "northamerican1983harn" | "nad83harn" | "northamericandatum1983harn" => {
            "nad83highaccuracyreferencenetwork"
        }
        "nad19832011" | "nad83nationalspatialreferencesystem2011" => {
            "nad83nationalspatialreferencesystem2011"
        }
        "northamerican1983csrs" | "nad83canadianspatialreferencesystem" => {
            "nad83canadianspatialreferencesystem"
        }
        "etrs1989" | "europeanterrestrialreferencesystem1989" => "etrs1989",
        "gda1994" | "geocentricdatumofaustralia1994" => "gda1994",
        "gda2020" | "geocentricdatumofaustralia2020" => "gda2020",
        "rgf1993" | "reseaugeodesiquefrancais1993" => "rgf1993",
        "nzgd2000" | "newzealandgeodeticdatum2000" => "nzgd2000",
        "jgd2000" | "japanesegeodeticdatum2000" => "jgd2000",
        "jgd2011" | "japanesegeodeticdatum2011" => "jgd2011",
        "sirgas2000" | "sistemadereferenciageocentricoparalasamericas2000" => "sirgas2000",
        "european1950" | "europeandatum1950" => "europeandatum1950",
        "ordnancesurveyofgreatbritain1936" => "osgb1936",
        "reseaugeodesiquefrancais1993v1" => "rgf1993",
        other => other,
    };
    alias.to_string()
}

/// The `AUTHORITY["EPSG", n]` / `ID["EPSG", n]` of `node`.
fn epsg_id(node: &Node) -> Option<u32> {
    node.children()
        .find(|c| c.keyword == "AUTHORITY" || c.keyword == "ID")
        .filter(|c| c.string(0).is_some_and(|a| a.eq_ignore_ascii_case("EPSG")))
        .and_then(|c| c.number_or_string(1))
        .and_then(|v| v.parse().ok())
}

fn child<'a>(node: &'a Node, keywords: &[&str]) -> Option<&'a Node> {
    node.children().find(|c| keywords.contains(&c.keyword.as_str()))
}

/// A unit node's factor (`UNIT["metre", 1]`): metres or radians per unit.
fn unit_factor(node: Option<&Node>) -> Option<f64> {
    node.and_then(|u| u.number(1)).filter(|f| f.is_finite() && *f > 0.0)
}

const DEGREE: f64 = std::f64::consts::PI / 180.0;

/// The datum of a geographic CRS node (`GEOGCS`, `GEOGCRS`, `BASEGEOGCRS`, ...).
fn datum_of(geog: &Node) -> Option<Datum> {
    let datum = child(geog, &["DATUM", "GEODETICDATUM", "TRF", "ENSEMBLE"])?;
    let ellipsoid = child(datum, &["SPHEROID", "ELLIPSOID"])
        .or_else(|| child(geog, &["SPHEROID", "ELLIPSOID"]))?;
    let a_unit = unit_factor(child(ellipsoid, &["LENGTHUNIT", "UNIT"])).unwrap_or(1.0);
    let a = ellipsoid.number(1)? * a_unit;
    let rf = ellipsoid.number(2)?;
    let pm = child(geog, &["PRIMEM", "PRIMEMERIDIAN"])
        .and_then(|p| {
            let v = p.number(1)?;
            // WKT2 may give the meridian in another angular unit; WKT1 in the CRS's.
            let unit = unit_factor(child(p, &["ANGLEUNIT", "UNIT"])).unwrap_or(DEGREE);
            Some(v * unit / DEGREE)
        })
        .unwrap_or(0.0);
    Some(Datum {
        code: epsg_id(datum),
        key: datum_key(datum.string(0)?),
        a,
        rf,
        pm,
    })
}

/// The method a projection's name (WKT1 `PROJECTION`, ESRI, WKT2 `METHOD`) or EPSG method
/// code names, given its parameters' keys (ESRI's one name for both Lambert conics).
fn method_of(name: &str, code: Option<u32>, params: &BTreeMap<&'static str, f64>) -> Option<Method> {
    if let Some(code) = code {
        let m = match code {
            9807 => Method::TransverseMercator,
            9801 => Method::LambertConic1Sp,
            9802 => Method::LambertConic2Sp,
            9822 => Method::AlbersEqualArea,
            9804 => Method::Mercator1Sp,
            9805 => Method::Mercator2Sp,
            1024 => Method::WebMercator,
            9820 => Method::LambertAzimuthalEqualArea,
            9809 => Method::ObliqueStereographic,
            9810 => Method::PolarStereographicA,
            9829 => Method::PolarStereographicB,
            1028 | 1029 => Method::EquidistantCylindrical,
            _ => return None,
        };
        return Some(m);
    }
    Some(match squash(name).as_str() {
        "transversemercator" | "gausskruger" => Method::TransverseMercator,
        "lambertconformalconic1sp" | "lambertconicconformal1sp" => Method::LambertConic1Sp,
        "lambertconformalconic2sp" | "lambertconicconformal2sp" => Method::LambertConic2Sp,
        // ESRI's one name: two standard parallels, or one with a scale factor.
        "lambertconformalconic" => {
            if params.contains_key("lat_2") {
                Method::LambertConic2Sp
            } else {
                Method::LambertConic1Sp
            }
        }
        "albersconicequalarea" | "albers" | "albersequalarea" => Method::AlbersEqualArea,
        "mercator1sp" | "mercatorvarianta" => Method::Mercator1Sp,
        "mercator2sp" | "mercatorvariantb" => Method::Mercator2Sp,
        "mercator" => {
            if params.get("lat_1").is_some_and(|v| *v != 0.0) {
                Method::Mercator2Sp
            } else {
                Method::Mercator1Sp
            }
        }
        "popularvisualisationpseudomercator" | "mercatorauxiliarysphere" => Method::WebMercator,
        "lambertazimuthalequalarea" => Method::LambertAzimuthalEqualArea,
        "obliquestereographic" | "doublestereographic" => Method::ObliqueStereographic,
        "polarstereographicvarianta" => Method::PolarStereographicA,
        "polarstereographicvariantb" | "stereographicsouthpole" | "stereographicnorthpole" => {
            Method::PolarStereographicB
        }
        // WKT1's one name: variant A at a pole with a scale factor, else variant B, whose
        // `latitude_of_origin` is then the latitude of true scale.
        "polarstereographic" => {
            let at_pole = params.get("lat_0").is_some_and(|l| (l.abs() - 90.0).abs() < 1e-9);
            if at_pole && params.get("k").is_some_and(|k| *k != 1.0) {
                Method::PolarStereographicA
            } else {
                Method::PolarStereographicB
            }
        }
        "equidistantcylindrical" | "equirectangular" => Method::EquidistantCylindrical,
        _ => return None,
    })
}

/// The canonical key of a parameter, by its EPSG code or its (WKT1, ESRI or WKT2) name.
fn param_key(name: &str, code: Option<u32>) -> Option<&'static str> {
    if let Some(code) = code {
        return Some(match code {
            8801 | 8821 | 8811 => "lat_0",
            8802 | 8822 | 8812 | 8833 => "lon_0",
            8805 | 8815 => "k",
            8806 | 8826 | 8816 => "x_0",
            8807 | 8827 | 8817 => "y_0",
            8823 | 8832 => "lat_1",
            8824 => "lat_2",
            _ => return None,
        });
    }
    Some(match squash(name).as_str() {
        "latitudeoforigin" | "latitudeofnaturalorigin" | "latitudeoffalseorigin"
        | "latitudeofcenter" | "latitudeofprojectioncentre" | "latitudeofcentre" => "lat_0",
        "centralmeridian" | "longitudeofnaturalorigin" | "longitudeoffalseorigin"
        | "longitudeofcenter" | "longitudeoforigin" | "longitudeofcentre" => "lon_0",
        "scalefactor" | "scalefactoratnaturalorigin" => "k",
        "falseeasting" | "eastingatfalseorigin" => "x_0",
        "falsenorthing" | "northingatfalseorigin" => "y_0",
        "standardparallel1" | "latitudeof1ststandardparallel" | "latitudeofstandardparallel" => {
            "lat_1"
        }
        "standardparallel2" | "latitudeof2ndstandardparallel" => "lat_2",
        // ESRI's Web Mercator: only the sphere type (0, WGS 84's semi-major axis).
        "auxiliaryspheretype" => "aux_sphere",
        _ => return None,
    })
}

/// The shape of a CRS node: a geographic or projected CRS, WKT1 or WKT2.
fn shape_of(root: &Node) -> Option<Shape> {
    match root.keyword.as_str() {
        "GEOGCS" | "GEOGCRS" | "GEOGRAPHICCRS" | "GEODCRS" | "GEODETICCRS" => {
            // Degrees only: another angular unit is another CRS.
            let unit = unit_factor(child(root, &["UNIT", "ANGLEUNIT"]));
            if unit.is_some_and(|u| (u - DEGREE).abs() > 1e-12) {
                return None;
            }
            if child(root, &["CS"]).is_some_and(|cs| cs.string(0).is_some_and(|t| !t.eq_ignore_ascii_case("ellipsoidal"))) {
                return None;
            }
            Some(Shape {
                datum: datum_of(root)?,
                projection: None,
            })
        }
        "PROJCS" | "PROJCRS" | "PROJECTEDCRS" => {
            let base = child(root, &["GEOGCS", "BASEGEOGCRS", "BASEGEODCRS"])?;
            let mut datum = datum_of(base)?;
            if datum.code.is_none() {
                // WKT2 names the base CRS's code where it leaves the datum's out.
                datum.code = epsg_id(base)
                    .and_then(|c| crs_definitions::from_code(u16::try_from(c).ok()?))
                    .and_then(|def| super::wkt::parse(def.wkt).ok())
                    .and_then(|n| datum_of(&n))
                    .and_then(|d| d.code);
            }
            // The first axis's direction; polar grids' axes run along meridians (`north`
            // along 90° E) and say nothing of this.
            let northing_first = root
                .children()
                .find(|c| c.keyword == "AXIS")
                .filter(|a| child(a, &["MERIDIAN"]).is_none())
                .and_then(|a| a.number_or_string(1))
                .map(|d| d.eq_ignore_ascii_case("north") || d.eq_ignore_ascii_case("south"));
            // The CRS's linear unit: WKT1 among PROJCS's children, WKT2 in the CS's axes.
            let unit_m = unit_factor(child(root, &["UNIT", "LENGTHUNIT"]))
                .or_else(|| {
                    root.children()
                        .filter(|c| c.keyword == "AXIS")
                        .find_map(|a| unit_factor(child(a, &["LENGTHUNIT", "UNIT"])))
                })
                .unwrap_or(1.0);
            let (method_node, param_parent) = match child(root, &["CONVERSION"]) {
                Some(conv) => (child(conv, &["METHOD", "PROJECTION"])?, conv),
                None => (child(root, &["PROJECTION"])?, root),
            };
            let mut params = BTreeMap::new();
            for p in param_parent.children().filter(|c| c.keyword == "PARAMETER") {
                let Some(key) = param_key(p.string(0).unwrap_or(""), epsg_id(p)) else {
                    continue;
                };
                let Some(v) = p.number(1) else { continue };
                let v = if key == "k" || key == "aux_sphere" {
                    v
                } else if key.starts_with('x') || key.starts_with('y') {
                    // WKT2 gives each length its unit; WKT1 the CRS's.
                    v * unit_factor(child(p, &["LENGTHUNIT", "UNIT"])).unwrap_or(unit_m)
                } else {
                    v * unit_factor(child(p, &["ANGLEUNIT", "UNIT"])).unwrap_or(DEGREE) / DEGREE
                };
                params.insert(key, v);
            }
            let mut method = method_of(
                method_node.string(0).unwrap_or(""),
                epsg_id(method_node),
                &params,
            )?;
            // The registry's Web Mercator is WKT1 `Mercator_1SP` on WGS 84 with a PROJ
            // extension that puts it on the sphere: that is what tells it from World Mercator.
            if method == Method::Mercator1Sp
                && child(root, &["EXTENSION"])
                    .and_then(|e| e.string(1))
                    .is_some_and(|p| p.contains("+a=6378137") && p.contains("+b=6378137"))
            {
                method = Method::WebMercator;
            }
            if method == Method::WebMercator {
                // Its parameters are fixed; ESRI's sphere type 0 is WGS 84's semi-major axis.
                if params.get("aux_sphere").is_some_and(|t| *t != 0.0) {
                    return None;
                }
                params.remove("aux_sphere");
                params.remove("k");
                params.remove("lat_1");
            }
            if method == Method::LambertConic1Sp {
                // ESRI repeats the latitude of origin as its one standard parallel.
                params.remove("lat_1");
            }
            if method == Method::PolarStereographicB {
                // The latitude of true scale, whichever name it came under; the origin is
                // the pole on its side.
                if let Some(lat) = params.remove("lat_0") {
                    params.entry("lat_1").or_insert(lat);
                }
                params.remove("k");
            }
            Some(Shape {
                datum,
                projection: Some(Projection {
                    method,
                    params,
                    unit_m,
                    northing_first,
                }),
            })
        }
        _ => None,
    }
}

/// Whether two shapes are the same CRS.
fn same(a: &Shape, b: &Shape) -> bool {
    let close = |x: f64, y: f64, tol: f64| (x - y).abs() <= tol;
    let datum = match (a.datum.code, b.datum.code) {
        (Some(x), Some(y)) => x == y,
        _ => a.datum.key == b.datum.key,
    };
    if !datum
        || !close(a.datum.a, b.datum.a, 1e-3)
        || !close(a.datum.rf, b.datum.rf, 1e-6 * a.datum.rf.max(1.0))
        || !close(a.datum.pm, b.datum.pm, 1e-9)
    {
        return false;
    }
    match (&a.projection, &b.projection) {
        (None, None) => true,
        (Some(p), Some(q)) => {
            let value = |params: &BTreeMap<&'static str, f64>, key: &str| {
                params
                    .get(key)
                    .copied()
                    .unwrap_or(if key == "k" { 1.0 } else { 0.0 })
            };
            let axes = match (p.northing_first, q.northing_first) {
                (Some(x), Some(y)) => x == y,
                _ => true,
            };
            p.method == q.method
                && axes
                && close(p.unit_m, q.unit_m, 1e-9)
                && ["lat_0", "lon_0", "lat_1", "lat_2", "k", "x_0", "y_0"]
                    .iter()
                    .all(|k| {
                        let (x, y) = (value(&p.params, k), value(&q.params, k));
                        let tol = match *k {
                            // A millimetre: feet given to 3 decimals in one, metres in the other.
                            "x_0" | "y_0" => 2e-3,
                            "k" => 1e-9,
                            _ => 1e-8,
                        };
                        close(x, y, tol)
                    })
        }
        _ => false,
    }
}

/// Every CRS of the registry that fmrh can compare, read once.
fn registry() -> &'static Vec<(u32, Shape)> {
    static REGISTRY: OnceLock<Vec<(u32, Shape)>> = OnceLock::new();
    REGISTRY.get_or_init(|| {
        (1..=u16::MAX)
            .filter_map(|code| {
                let def = crs_definitions::from_code(code)?;
                let node = super::wkt::parse(def.wkt).ok()?;
                Some((u32::from(code), shape_of(&node)?))
            })
            .collect()
    })
}

/// The EPSG code whose CRS is what `root` describes: the lowest of those that match. The
/// registry's WKT1 states the axes of easting-first grids and omits those of northing-first
/// ones; a WKT that is easting first or does not say (ESRI's never does, and its grids are
/// stored easting first) takes a code that states easting first when one matches: ETRS89 /
/// UTM 32N (EPSG:25832), not its northing-first twin ETRS89 / ETRS-TM32 (3044); DHDN /
/// Gauss-Kruger zone 3 in ESRI WKT is then 5677, the easting-first twin of 31467.
pub(super) fn epsg_of(root: &Node) -> Option<u32> {
    let shape = shape_of(root)?;
    let matches: Vec<(u32, Option<bool>)> = registry()
        .iter()
        .filter(|(_, s)| same(&shape, s))
        .map(|(code, s)| (*code, s.projection.as_ref().and_then(|p| p.northing_first)))
        .collect();
    let northing_first = shape.projection.as_ref().and_then(|p| p.northing_first);
    let stated_easting_first = matches
        .iter()
        .filter(|m| m.1 == Some(false))
        .map(|m| m.0)
        .min();
    match (northing_first, stated_easting_first) {
        (Some(true), _) | (_, None) => matches.iter().map(|m| m.0).min(),
        (_, Some(code)) => Some(code),
    }
}

/// A PROJ string's parameters as compared: `+key=value` tokens, sorted, without those that
/// do not change the CRS (`+no_defs`, `+type=crs`, `+wktext`).
fn proj4_tokens(text: &str) -> Vec<String> {
    let mut tokens: Vec<String> = text
        .split_whitespace()
        .filter(|t| !matches!(*t, "+no_defs" | "+type=crs" | "+wktext"))
        .map(|t| {
            // Numbers compare by value: `+lat_ts=0.0` is `+lat_ts=0`.
            match t.split_once('=') {
                Some((k, v)) => match v.parse::<f64>() {
                    Ok(n) => format!("{k}={n}"),
                    Err(_) => t.to_string(),
                },
                None => t.to_string(),
            }
        })
        .collect();
    tokens.sort();
    tokens
}

/// The lowest EPSG code whose PROJ string has the same parameters as `text`.
pub(super) fn epsg_of_proj4(text: &str) -> Option<u32> {
    let want = proj4_tokens(text);
    (1..=u16::MAX).find_map(|code| {
        let def = crs_definitions::from_code(code)?;
        (proj4_tokens(def.proj4) == want).then_some(u32::from(code))
    })
}
