//! `fmrh serve`'s terrain for web maps: `/NAME/terrain-rgb.json` (TileJSON) and
//! `/NAME/terrain-rgb/{z}/{x}/{y}.png`, Web Mercator tiles whose colours encode heights
//! (`crate::export::terrain_rgb`), for every served container and dataset that can be
//! placed on a map. `?encoding=mapbox|terrarium` (default mapbox), `?size=256|512`
//! (default 256) and `?nodata=METRES|transparent` (default 0) pick the tiles; each is cut on
//! request from the current state, from the coarsest blocks whose measured error is within
//! its smallest pixel (the exact blocks at the deepest zoom), and kept in the server's tile
//! cache by state, address and options, cut through the same gate as the Cesium tiles
//! (`X-Fmrh-Cache: hit|miss` says which). Answers carry an
//! `ETag` (a hash of the bytes; `304` for a matching `If-None-Match`), CORS headers, and
//! `Cache-Control` as the quantized-mesh tiles do (a day when the address names the
//! current version, `?v=`, else revalidate).

use crate::export::terrain_rgb::{self, Encoding, MercatorTile, NoData, RgbTiles};
use crate::http::{Body, Request, Response};
use crate::terrain::Terrain;
use crate::Error;

use super::terrain::{
    failed, preflight, text_error, tile_number, version, with_cors, Tile, TileCache,
};
use super::Item;
use crate::pyramid::shape_of;

/// What was asked of one item.
enum Asked {
    TileJson,
    Tile(MercatorTile),
}

/// The answer for `path` (percent-decoded), or `None` when it is not a terrain-RGB
/// address of a served item.
pub fn route(
    items: &[Item],
    cache: &TileCache,
    path: &str,
    query: &str,
    request: &Request,
) -> Option<Response> {
    let rest = path.strip_prefix('/')?;
    let (name, tail) = rest.split_once('/')?;
    let item = items.iter().find(|i| i.name == name)?;
    let asked = if tail == "terrain-rgb.json" {
        Asked::TileJson
    } else {
        let address = tail.strip_prefix("terrain-rgb/")?;
        let parts: Vec<&str> = address.split('/').collect();
        let [z, x, y] = parts.as_slice() else {
            return Some(text_error(
                400,
                format!("`{tail}`: expected terrain-rgb/Z/X/Y.png"),
            ));
        };
        let Some(y) = y.strip_suffix(".png") else {
            return Some(text_error(
                404,
                format!("`{tail}`: terrain-RGB tiles are PNG (Z/X/Y.png)"),
            ));
        };
        match (tile_number(z), tile_number(x), tile_number(y)) {
            (Some(z), Some(x), Some(y)) if z <= 255 => {
                Asked::Tile(MercatorTile { z: z as u8, x, y })
            }
            _ => {
                return Some(text_error(
                    400,
                    format!("`{tail}`: expected terrain-rgb/Z/X/Y.png"),
                ))
            }
        }
    };
    if request.method == "OPTIONS" {
        return Some(preflight("If-None-Match"));
    }
    Some(answer(item, cache, &asked, query, request).unwrap_or_else(failed))
}

/// What a query asks of a tile.
struct Options<'a> {
    encoding: Encoding,
    size: u32,
    nodata: NoData,
    /// The version it names, `v=`.
    version: Option<&'a str>,
}

/// The encoding, size, no-data fill and version a query names; an error names a bad one.
fn options(query: &str) -> Result<Options<'_>, String> {
    let (mut encoding, mut size, mut v) = (Encoding::Mapbox, 256, None);
    let mut nodata = NoData::default();
    for pair in query.split('&').filter(|p| !p.is_empty()) {
        let (k, value) = pair.split_once('=').unwrap_or((pair, ""));
        match k {
            "encoding" => {
                encoding = Encoding::parse(value)
                    .ok_or_else(|| format!("encoding `{value}`: expected mapbox or terrarium"))?;
            }
            "size" => {
                size = match value {
                    "256" => 256,
                    "512" => 512,
                    _ => return Err(format!("size `{value}`: expected 256 or 512")),
                }
            }
            "nodata" => {
                nodata = NoData::parse(value).ok_or_else(|| {
                    format!("nodata `{value}`: expected transparent or a height in metres")
                })?;
            }
            "v" => v = Some(value),
            _ => {
                return Err(format!(
                    "unknown parameter `{k}` (encoding, size, nodata, v)"
                ))
            }
        }
    }
    Ok(Options {
        encoding,
        size,
        nodata,
        version: v,
    })
}

fn answer(
    item: &Item,
    cache: &TileCache,
    asked: &Asked,
    query: &str,
    request: &Request,
) -> Result<Response, Error> {
    let Options {
        encoding,
        size,
        nodata,
        version: asked_version,
    } = match options(query) {
        Ok(o) => o,
        Err(why) => return Ok(text_error(400, why)),
    };
    let terrain = Terrain::open(&item.path)?;
    let info = terrain.info()?;
    let tiles = RgbTiles::new(&shape_of(&info), size)?;
    let version = version(item, info.txn_id);
    match asked {
        Asked::TileJson => {
            let mut params = format!("v={version}");
            if encoding != Encoding::Mapbox {
                params.push_str(&format!("&encoding={}", encoding.name()));
            }
            if size != 256 {
                params.push_str(&format!("&size={size}"));
            }
            match nodata {
                NoData::Height(0.0) => {}
                NoData::Height(h) => params.push_str(&format!("&nodata={h}")),
                NoData::Transparent => params.push_str("&nodata=transparent"),
            }
            // Absolute when the request names its host (MapLibre takes a TileJSON's tile
            // addresses as they are), else relative to the TileJSON.
            let template = match request.header("Host") {
                Some(host) if !host.is_empty() && !host.contains(['/', ' ']) => format!(
                    "http://{host}/{}/terrain-rgb/{{z}}/{{x}}/{{y}}.png?{params}",
                    item.name
                ),
                _ => format!("terrain-rgb/{{z}}/{{x}}/{{y}}.png?{params}"),
            };
            let mut json = tiles.tilejson(&template, encoding, size, nodata);
            json["name"] = item.name.clone().into();
            json["version"] = version.clone().into();
            let body = serde_json::to_vec_pretty(&json)
                .map_err(|e| Error::InvalidArgument(format!("TileJSON: {e}")))?;
            Ok(with_cors(
                Response::new(200, "application/json", Body::Bytes(body))
                    .with("Cache-Control", "no-cache"),
            ))
        }
        Asked::Tile(t) => {
            if !t.is_valid() {
                let n = 1u64 << t.z.min(63);
                return Ok(text_error(
                    400,
                    format!(
                        "tile {}/{}/{}: zoom {} has columns and rows 0..{n} (zooms 0..={})",
                        t.z,
                        t.x,
                        t.y,
                        t.z,
                        terrain_rgb::MAX_ZOOM
                    ),
                ));
            }
            if t.z > tiles.maxzoom() {
                return Ok(text_error(
                    404,
                    format!("zoom {} is past the deepest, {}", t.z, tiles.maxzoom()),
                ));
            }
            if !tiles.meets(*t) {
                return Ok(text_error(
                    404,
                    "no data in this tile (see terrain-rgb.json's bounds)",
                ));
            }
            let fill = match nodata {
                NoData::Height(h) => h.to_bits(),
                NoData::Transparent => u64::MAX,
            };
            let (png, tag, hit) = cache.get_or_cut(
                &item.name,
                &version,
                Tile::Rgb(*t, encoding, size, fill),
                || crate::pyramid::rgb_tile(&terrain, &tiles, *t, size, encoding, nodata),
            )?;
            let etag = format!("\"{tag:016x}\"");
            let matches = request
                .header("If-None-Match")
                .is_some_and(|v| v.split(',').map(str::trim).any(|x| x == etag || x == "*"));
            let cache_control = if asked_version == Some(version.as_str()) {
                "public, max-age=86400"
            } else {
                "no-cache"
            };
            let (status, body) = if matches {
                (304, Vec::new())
            } else {
                (200, png.as_ref().clone())
            };
            Ok(with_cors(
                Response::new(status, "image/png", Body::Bytes(body))
                    .with("X-Fmrh-Cache", if hit { "hit" } else { "miss" })
                    .with("ETag", etag)
                    .with("Cache-Control", cache_control),
            ))
        }
    }
}
