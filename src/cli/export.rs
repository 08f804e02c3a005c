//! `fmrh export`: a terrain's whole web tile pyramid (Cesium's quantized-mesh, or
//! terrain-RGB for web maps) written once for static hosting, to a directory or one
//! PMTiles archive (`crate::pyramid::export`), tile for tile what `fmrh serve` answers.

use std::path::PathBuf;
use std::process::ExitCode;
use std::time::Instant;

use crate::export::terrain_rgb::{Encoding, NoData};
use crate::pyramid::export::{self, Destination, Selection};
use crate::pyramid::{Pyramid, TileFormat};
use crate::terrain::Terrain;
use crate::Error;

/// The pyramids `export` writes.
#[derive(Clone, Copy, Debug, PartialEq, Eq, clap::ValueEnum)]
pub enum TilesArg {
    /// Cesium terrain: quantized-mesh 1.0 tiles (global-geodetic TMS) and `layer.json`.
    QuantizedMesh,
    /// Web maps' terrain: PNG tiles whose colours encode heights (Web Mercator XYZ) and a
    /// TileJSON, as MapLibre's `raster-dem` reads them.
    TerrainRgb,
}

/// Terrain-RGB encodings.
#[derive(Clone, Copy, Debug, PartialEq, Eq, clap::ValueEnum)]
pub enum EncodingArg {
    /// Mapbox terrain-RGB: h = -10000 + (R·65536 + G·256 + B)·0.1.
    Mapbox,
    /// Terrarium: h = R·256 + G + B/256 - 32768.
    Terrarium,
}

#[derive(clap::Args)]
pub struct ExportArgs {
    /// The container or dataset directory.
    file: PathBuf,
    /// Which pyramid.
    #[arg(long, value_enum)]
    tiles: TilesArg,
    /// Where: a `.pmtiles` archive, or else a directory (`z/x/y.terrain` or `z/x/y.png`,
    /// with `layer.json` or `tilejson.json`).
    #[arg(short, long)]
    output: PathBuf,
    /// Only tiles meeting this box: WEST,SOUTH,EAST,NORTH in degrees.
    #[arg(long, value_name = "W,S,E,N", allow_hyphen_values = true)]
    bbox: Option<String>,
    /// The zooms: `A..=B`, `A..B`, `A..`, `..=B` or one zoom (default: all). Quantized-mesh
    /// zooms are Cesium's levels.
    #[arg(long, value_name = "RANGE")]
    zoom: Option<String>,
    /// Terrain-RGB: the colour encoding.
    #[arg(long, value_enum, default_value_t = EncodingArg::Mapbox)]
    encoding: EncodingArg,
    /// Terrain-RGB: what a pixel with no data under it holds: a height in metres, opaque
    /// (default 0: web maps read every pixel's colour, a transparent one as -10 km), or
    /// `transparent`.
    #[arg(long, value_name = "METRES|transparent", allow_hyphen_values = true)]
    nodata: Option<String>,
    /// Terrain-RGB: pixels along a tile's side, 256 or 512.
    #[arg(long, default_value_t = 256)]
    size: u32,
    /// Terrain-RGB in a directory: the address the tiles will be served from, written
    /// into `tilejson.json` as `URL/{z}/{x}/{y}.png` (MapLibre does not resolve a relative
    /// template). Default: the relative `{z}/{x}/{y}.png`.
    #[arg(long, value_name = "URL")]
    base_url: Option<String>,
    /// Quantized-mesh: the most a tile's mesh may differ from its grid, metres (as `serve
    /// --max-error`).
    #[arg(long, value_name = "METRES", allow_negative_numbers = true)]
    max_error: Option<f64>,
    /// Quantized-mesh: what the heights are above (as `serve --vertical-datum`).
    #[arg(long, value_name = "DATUM", value_parser = crate::geoid::VerticalDatum::parse)]
    vertical_datum: Option<crate::geoid::VerticalDatum>,
    /// Replace an existing output.
    #[arg(long)]
    force: bool,
    /// Quiet: no progress bar, and no message on success.
    #[arg(long, short)]
    quiet: bool,
}

/// `A..=B`, `A..B`, `A..`, `..=B`, `..B` or `A`, within `0..=max`.
fn parse_zooms(text: &str, max: u8) -> Result<std::ops::RangeInclusive<u8>, Error> {
    let bad = || {
        Error::InvalidArgument(format!(
            "--zoom `{text}`: expected A..=B, A..B, A.., ..=B or one zoom (0 to 255)"
        ))
    };
    let number = |s: &str| s.trim().parse::<u8>().map_err(|_| bad());
    let (lo, hi) = if let Some((a, b)) = text.split_once("..=") {
        (if a.is_empty() { 0 } else { number(a)? }, number(b)?)
    } else if let Some((a, b)) = text.split_once("..") {
        let lo = if a.is_empty() { 0 } else { number(a)? };
        let hi = if b.is_empty() {
            max
        } else {
            number(b)?.checked_sub(1).ok_or_else(bad)?
        };
        (lo, hi)
    } else {
        let z = number(text)?;
        (z, z)
    };
    if lo > hi {
        return Err(bad());
    }
    Ok(lo..=hi)
}

fn parse_bbox(text: &str) -> Result<[f64; 4], Error> {
    let v: Vec<f64> = text
        .split(',')
        .map(|p| p.trim().parse::<f64>())
        .collect::<Result<_, _>>()
        .map_err(|_| {
            Error::InvalidArgument(format!("--bbox `{text}`: expected W,S,E,N in degrees"))
        })?;
    match v.as_slice() {
        &[w, s, e, n] if v.iter().all(|x| x.is_finite()) => Ok([w, s, e, n]),
        _ => Err(Error::InvalidArgument(format!(
            "--bbox `{text}`: expected four numbers W,S,E,N in degrees"
        ))),
    }
}

/// Runs `fmrh export`.
pub fn run(args: &ExportArgs) -> Result<ExitCode, Error> {
    let started = Instant::now();
    let format = match args.tiles {
        TilesArg::QuantizedMesh => {
            if args.base_url.is_some()
                || args.size != 256
                || args.encoding != EncodingArg::Mapbox
                || args.nodata.is_some()
            {
                return Err(Error::InvalidArgument(
                    "--base-url, --size, --encoding and --nodata are for --tiles terrain-rgb"
                        .into(),
                ));
            }
            TileFormat::QuantizedMesh {
                max_error: args.max_error,
                datum: args.vertical_datum,
            }
        }
        TilesArg::TerrainRgb => {
            if args.max_error.is_some() || args.vertical_datum.is_some() {
                return Err(Error::InvalidArgument(
                    "--max-error and --vertical-datum are for --tiles quantized-mesh \
                     (terrain-RGB heights are the stored ones)"
                        .into(),
                ));
            }
            TileFormat::TerrainRgb {
                encoding: match args.encoding {
                    EncodingArg::Mapbox => Encoding::Mapbox,
                    EncodingArg::Terrarium => Encoding::Terrarium,
                },
                size: args.size,
                nodata: match &args.nodata {
                    None => NoData::default(),
                    Some(text) => NoData::parse(text).ok_or_else(|| {
                        Error::InvalidArgument(format!(
                            "--nodata `{text}`: expected transparent or a height in metres"
                        ))
                    })?,
                },
            }
        }
    };
    let destination = Destination::of(&args.output);
    if matches!(destination, Destination::Pmtiles(_)) && args.base_url.is_some() {
        return Err(Error::InvalidArgument(
            "--base-url is for a directory (a PMTiles client names its own tile addresses)".into(),
        ));
    }
    // Refused before any cutting: an export can take minutes.
    super::check_output(&args.output, args.force)?;
    let pyramid = Pyramid::new(Terrain::open(&args.file)?, format)?;
    let zooms = match &args.zoom {
        Some(text) => parse_zooms(text, pyramid.maxzoom())?,
        None => 0..=pyramid.maxzoom(),
    };
    let bbox = args.bbox.as_deref().map(parse_bbox).transpose()?;
    let selection = Selection { zooms, bbox };
    let tiles = export::plan(&pyramid, &selection)?;
    let name = args.file.file_name().map_or_else(
        || "terrain".to_string(),
        |n| n.to_string_lossy().into_owned(),
    );
    let version = pyramid.info().txn_id.to_string();
    let template = args.base_url.as_ref().map(|u| {
        format!(
            "{}/{{z}}/{{x}}/{{y}}.{}",
            u.trim_end_matches('/'),
            pyramid.extension()
        )
    });
    let description = export::describe(
        &pyramid,
        &name,
        &version,
        template.as_deref(),
        &selection,
        &tiles,
        &destination,
    );
    let bar = (!args.quiet).then(super::progress::Bar::new);
    let silent = crate::progress::Silent;
    let progress: &dyn crate::progress::Progress = match &bar {
        Some(b) => b,
        None => &silent,
    };
    let done = export::export(
        &pyramid,
        &tiles,
        &description,
        &destination,
        args.force,
        progress,
    )?;
    if !args.quiet {
        let zooms: Vec<String> = done
            .per_zoom
            .iter()
            .map(|(z, n)| format!("{z}:{n}"))
            .collect();
        let stored = match done.archive {
            Some(a) => format!("{} distinct, {} bytes", a.contents, done.bytes),
            None => format!("{} bytes", done.bytes),
        };
        eprintln!(
            "fmrh: wrote {} tiles ({stored}) to {} in {:.1} s; tiles per zoom {}",
            done.tiles(),
            args.output.display(),
            started.elapsed().as_secs_f64(),
            zooms.join(" ")
        );
    }
    Ok(ExitCode::SUCCESS)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn zoom_ranges_parse() {
        assert_eq!(parse_zooms("3..=7", 12).ok(), Some(3..=7));
        assert_eq!(parse_zooms("3..7", 12).ok(), Some(3..=6));
        assert_eq!(parse_zooms("5..", 12).ok(), Some(5..=12));
        assert_eq!(parse_zooms("..=4", 12).ok(), Some(0..=4));
        assert_eq!(parse_zooms("9", 12).ok(), Some(9..=9));
        for bad in ["", "7..3", "..0", "a..b", "-1", "300", "1..=x"] {
            assert!(parse_zooms(bad, 12).is_err(), "{bad}");
        }
    }

    #[test]
    fn boxes_parse() {
        assert_eq!(
            parse_bbox("-122.5,47,-122,47.5").ok(),
            Some([-122.5, 47.0, -122.0, 47.5])
        );
        for bad in ["1,2,3", "1,2,3,x", "nan,0,1,1", ""] {
            assert!(parse_bbox(bad).is_err(), "{bad}");
        }
    }
}
