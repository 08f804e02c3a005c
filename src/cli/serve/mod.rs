//! `fmrh serve`: containers and datasets over HTTP, and a WebGL page to fly over them.
//!
//! Three kinds of address, each a room of its own:
//!
//! * `/files/NAME` (a container) and `/files/NAME/FILE` (a dataset's `MANIFEST` and tiles):
//!   the raw bytes, with single and multiple byte ranges, a strong `ETag` and `If-Match`
//!   ([`ranges`]), which is all the remote reader (`crate::store::remote`) needs: `fmrh
//!   scene http://HOST/files/NAME` reads a served container as it would one in a bucket.
//! * `/api/items`, `/api/scene?…` and `/api/mesh?…`: what is served, the scene a camera
//!   sees (JSON: the blocks, their levels, the payload bytes, the schedule time and the
//!   largest error), and that scene meshed crack-free as one glTF binary (`fmrh mesh`'s).
//! * `/` and `/viewer.js`: the page (plain JavaScript and WebGL 2, compiled into this
//!   binary; nothing is fetched from elsewhere), which asks for a scene and its mesh
//!   whenever its camera settles and shows the stats the scene JSON gives.
//!
//! Every request opens what it reads afresh, so a commit made while the server runs (by
//! `fmrh replace` or `dataset add`) is seen by the next request, and a reader never holds a
//! state a writer waits on. The server only reads: nothing it does can change a file.

use std::collections::BTreeMap;
use std::io::{Seek, SeekFrom};
use std::net::TcpListener;
use std::path::{Path, PathBuf};
use std::process::ExitCode;
use std::time::Instant;

use serde::Serialize;
use serde_json::{json, Value};

use crate::mesh::Cracks;
use crate::scene::{Camera, SceneStats, Terrain, DEFAULT_GAP};
use crate::Error;

mod terrain;
mod terrain_rgb;

use super::args::RefineArg;
use super::args::{ModeArg, ViewArgs};
use super::mesh::MeshStyle;
use crate::http::{self, ranges, Body, Request, Response};

/// The viewer page and its script, served at `/` and `/viewer.js`.
const INDEX_HTML: &str = include_str!("page/index.html");
const VIEWER_JS: &str = include_str!("page/viewer.js");

#[derive(clap::Args)]
pub struct ServeArgs {
    /// Containers and dataset directories to serve, each under its file name.
    #[arg(required = true)]
    paths: Vec<PathBuf>,
    /// The port to listen on (0: any free port; the address is printed).
    #[arg(long, default_value_t = 8737)]
    port: u16,
    /// The address to listen on. The default answers this machine only; `0.0.0.0` answers
    /// anyone who can reach it (the server only reads, but it reads everything served).
    #[arg(long, default_value = "127.0.0.1")]
    bind: String,
    /// Seconds a connection may idle, a request head may take to arrive, and a client may
    /// take an answer's first bytes (after that, it must read at least 16 KiB a second).
    #[arg(long, default_value_t = 30.0, value_parser = positive_seconds)]
    timeout: f64,
    /// Cesium terrain: the most a tile's mesh may differ from its grid, metres (default:
    /// half Cesium's geometric error at the tile's level).
    #[arg(long, value_name = "METRES", allow_negative_numbers = true)]
    max_error: Option<f64>,
    /// Cesium terrain: what the served heights are above: egm96 (lifted onto the WGS 84
    /// ellipsoid by the geoid's undulation), ellipsoid or unknown (both served as stored).
    /// Default: what the data's format says (SRTM and DTED: egm96), else unknown.
    #[arg(long, value_name = "DATUM", value_parser = crate::geoid::VerticalDatum::parse)]
    vertical_datum: Option<crate::geoid::VerticalDatum>,
    /// Cesium terrain: cut each state's coarse tiles only when asked. By default they are
    /// cut ahead on a thread of their own, at start and at the first request after each
    /// commit (each measures its mesh against every sample under it: tens of ms).
    #[arg(long)]
    no_warm: bool,
}

/// A timeout in seconds: finite, more than 0, at most a day.
fn positive_seconds(text: &str) -> Result<f64, String> {
    match text.parse::<f64>() {
        Ok(s) if s > 0.0 && s <= 86_400.0 => Ok(s),
        _ => Err(format!(
            "{text:?}: expected seconds, more than 0 and at most 86400"
        )),
    }
}

/// One served path.
#[derive(Clone)]
struct Item {
    /// Its address under `/files/` and its name in the API: the file or directory name.
    name: String,
    path: PathBuf,
    dataset: bool,
}

/// Runs `fmrh serve`: checks every path opens, then answers until killed.
pub fn run(args: &ServeArgs) -> Result<ExitCode, Error> {
    if let Some(m) = args.max_error {
        if m.is_nan() || m < 0.0 {
            return Err(Error::InvalidArgument(format!(
                "--max-error {m}: must be a number of metres >= 0"
            )));
        }
    }
    let mut items: Vec<Item> = Vec::new();
    for path in &args.paths {
        if super::url_of(path).is_some() {
            return Err(Error::InvalidArgument(format!(
                "{}: serve takes local containers and datasets, not URLs",
                path.display()
            )));
        }
        let dataset = super::is_dataset(path)?;
        // Refuse what does not open now, rather than on the first request.
        if dataset {
            crate::dataset::Dataset::open(path)?;
        } else {
            super::open(path)?;
        }
        let name = path
            .file_name()
            .and_then(|n| n.to_str())
            .filter(|n| !n.is_empty() && !n.starts_with('.'))
            .ok_or_else(|| {
                Error::InvalidArgument(format!(
                    "{}: cannot be served under its name (it needs a UTF-8 file name not \
                     starting with `.`)",
                    path.display()
                ))
            })?
            .to_string();
        if items.iter().any(|i| i.name == name) {
            return Err(Error::InvalidArgument(format!(
                "two paths are both named `{name}`: each is served under its file name, so \
                 the names must differ"
            )));
        }
        items.push(Item {
            name,
            path: path.clone(),
            dataset,
        });
    }
    let address = format!("{}:{}", args.bind, args.port);
    let listener = TcpListener::bind(&address)
        .map_err(|e| Error::InvalidArgument(format!("cannot listen on {address}: {e}")))?;
    let local = listener
        .local_addr()
        .map_or(address.clone(), |a| a.to_string());
    {
        use std::io::Write;
        let mut out = std::io::stdout().lock();
        // The first line is the address (tests read it when they ask for port 0).
        let _ = writeln!(out, "fmrh: serving on http://{local}/");
        for item in &items {
            let _ = writeln!(
                out,
                "  {:<9} /files/{}{}",
                if item.dataset { "dataset" } else { "container" },
                item.name,
                if item.dataset { "/" } else { "" }
            );
            // Cesium terrain for what can be placed on the globe; for what has a
            // georeference but cannot be, why not.
            let Ok(info) = crate::terrain::Terrain::open(&item.path).and_then(|t| t.info()) else {
                continue;
            };
            let datum = args.vertical_datum.unwrap_or(info.vertical_datum);
            match crate::export::tileset::Tileset::new(
                &crate::pyramid::shape_of(&info),
                args.max_error,
                datum,
            ) {
                Ok(tileset) => {
                    let _ = writeln!(
                        out,
                        "  {:<9} /{}/layer.json (Cesium quantized-mesh, levels 0..={}, heights {})",
                        "terrain",
                        item.name,
                        tileset.maxzoom(),
                        match tileset.datum() {
                            crate::geoid::VerticalDatum::Egm96 => "EGM96 + N: above the ellipsoid",
                            crate::geoid::VerticalDatum::Ellipsoid => "above the ellipsoid",
                            crate::geoid::VerticalDatum::Unknown => "as stored (datum unknown)",
                            // `Tileset::new` refuses it.
                            crate::geoid::VerticalDatum::Egm2008 => "above EGM2008",
                        }
                    );
                }
                Err(e) if info.georeference.is_some() => {
                    let _ = writeln!(out, "  {:<9} none: {e}", "terrain");
                }
                Err(_) => {}
            }
        }
        let _ = out.flush();
    }
    let limits = http::Limits {
        timeout: std::time::Duration::from_secs_f64(args.timeout),
        ..http::Limits::default()
    };
    let cache = std::sync::Arc::new(terrain::TileCache::default());
    let options = terrain::Options {
        max_error: args.max_error,
        datum: args.vertical_datum,
        warm: !args.no_warm,
    };
    if options.warm {
        for item in &items {
            terrain::spawn_warm(item, &cache, options);
        }
    }
    http::serve(listener, limits, move |request| {
        answer(&items, &cache, options, request)
    });
    Ok(ExitCode::SUCCESS)
}

type Answer = Response;

fn bytes(status: u16, content_type: &str, body: Vec<u8>) -> Answer {
    Response::new(status, content_type, Body::Bytes(body)).with("Cache-Control", "no-cache")
}

fn json_answer(status: u16, value: &Value) -> Answer {
    let body = serde_json::to_vec(value).unwrap_or_default();
    bytes(status, "application/json", body)
}

/// A failed request: the status and what went wrong, as JSON.
fn error(status: u16, message: impl Into<String>) -> Answer {
    json_answer(status, &json!({ "error": message.into() }))
}

/// The status for a library error: the request's fault (400), a file that is not a usable
/// container (422), or the server's (500).
fn fmrh_error(e: &Error) -> Answer {
    let status = match e {
        Error::InvalidArgument(_) => 400,
        Error::Input { .. } | Error::Unsupported { .. } | Error::Corrupt { .. } => 422,
        _ => 500,
    };
    error(status, e.to_string())
}

fn answer(
    items: &[Item],
    cache: &std::sync::Arc<terrain::TileCache>,
    options: terrain::Options,
    request: &Request,
) -> Answer {
    let url = request.target.as_str();
    let (path, query) = url.split_once('?').unwrap_or((url, ""));
    let method = request.method.as_str();
    let Some(path) = percent_decode(path, false) else {
        return error(400, "the path is not valid percent-encoded UTF-8");
    };
    // The Cesium terrain's addresses, `/NAME/layer.json` and `/NAME/Z/X/Y.terrain`, also
    // answer a CORS preflight.
    let terrain = !path.starts_with("/files/")
        && !path.starts_with("/api/")
        && terrain::is_address(items, &path);
    match (method, terrain) {
        ("GET" | "HEAD" | "OPTIONS", true) => {
            if let Some(r) = terrain_rgb::route(items, cache, &path, query, request) {
                return r;
            }
            if let Some(r) = terrain::route(items, cache, options, &path, query, request) {
                return r;
            }
            route(items, &path, query, request)
        }
        ("GET" | "HEAD", false) => route(items, &path, query, request),
        (_, true) => error(405, "the terrain answers GET, HEAD and OPTIONS only")
            .with("Allow", "GET, HEAD, OPTIONS"),
        (_, false) => error(405, "fmrh serve answers GET and HEAD only").with("Allow", "GET, HEAD"),
    }
}

fn route(items: &[Item], path: &str, query: &str, request: &Request) -> Answer {
    match path {
        "/" | "/index.html" => bytes(200, "text/html; charset=utf-8", INDEX_HTML.into()),
        "/viewer.js" => bytes(200, "text/javascript; charset=utf-8", VIEWER_JS.into()),
        // Browsers ask for it unbidden; there is none.
        "/favicon.ico" => bytes(204, "image/x-icon", Vec::new()),
        "/api/items" => match list(items) {
            Ok(v) => json_answer(200, &v),
            Err(e) => fmrh_error(&e),
        },
        "/api/scene" => match parse_view(items, query).and_then(|v| scene(&v)) {
            Ok(v) => json_answer(200, &v),
            Err(e) => fmrh_error(&e),
        },
        "/api/mesh" => match parse_view(items, query).and_then(|v| mesh(&v)) {
            Ok(m) => m,
            Err(e) => fmrh_error(&e),
        },
        _ => match path.strip_prefix("/files/") {
            Some(rest) => match file_of(items, rest) {
                Some(file) => serve_file(&file, request),
                None => error(404, format!("nothing is served at {path}")),
            },
            None => error(404, format!("nothing is served at {path}")),
        },
    }
}

/// The file `/files/REST` names: a container by its name, or a file directly inside a
/// served dataset's directory. Never anything else: no `..`, no subdirectories, no links.
fn file_of(items: &[Item], rest: &str) -> Option<PathBuf> {
    let mut segments = rest.split('/');
    let name = segments.next()?;
    let item = items.iter().find(|i| i.name == name)?;
    let member = segments.next();
    if segments.next().is_some() {
        return None;
    }
    match (item.dataset, member) {
        (false, None) => Some(item.path.clone()),
        (true, Some(m)) if !m.is_empty() && m != "." && m != ".." && !m.contains(['\\', '\0']) => {
            let path = item.path.join(m);
            // A regular file in the directory itself, never a symbolic link: a link there
            // could point anywhere on the machine.
            let meta = std::fs::symlink_metadata(&path).ok()?;
            meta.file_type().is_file().then_some(path)
        }
        _ => None,
    }
}

/// A file's bytes, whole or by ranges, with its `ETag`; `412` when `If-Match` names
/// another version.
fn serve_file(path: &Path, request: &Request) -> Answer {
    let mut file = match std::fs::File::open(path) {
        Ok(f) => f,
        Err(e) if e.kind() == std::io::ErrorKind::NotFound => {
            return error(404, "the file is gone")
        }
        Err(e) => return error(500, format!("cannot open the file: {e}")),
    };
    let meta = match file.metadata() {
        Ok(m) if m.is_file() => m,
        Ok(_) => return error(404, "not a file"),
        Err(e) => return error(500, format!("cannot read the file's metadata: {e}")),
    };
    let len = meta.len();
    let etag = etag_of(&meta);
    if let Some(wanted) = request.header("If-Match") {
        let matches = wanted
            .split(',')
            .map(str::trim)
            .any(|t| t == "*" || t == etag);
        if !matches {
            return error(
                412,
                "the file changed: its ETag is no longer the one asked for",
            )
            .with("ETag", etag.as_str());
        }
    }
    let common = |r: Answer| r.with("Accept-Ranges", "bytes").with("ETag", etag.as_str());
    let octets = |status: u16, body: Body| {
        Response::new(status, "application/octet-stream", body).with("Cache-Control", "no-cache")
    };
    match ranges::parse(request.header("Range"), len) {
        ranges::Asked::Whole => common(octets(200, Body::File(file, len))),
        ranges::Asked::Unsatisfiable => common(
            error(
                416,
                format!("no range asked for starts inside the {len} bytes"),
            )
            .with("Content-Range", format!("bytes */{len}")),
        ),
        ranges::Asked::Ranges(rs) if rs.len() == 1 => {
            let r = rs[0].clone();
            if let Err(e) = file.seek(SeekFrom::Start(r.start)) {
                return error(500, format!("cannot read the file: {e}"));
            }
            common(
                octets(206, Body::File(file, r.end - r.start))
                    .with("Content-Range", ranges::content_range(&r, len)),
            )
        }
        ranges::Asked::Ranges(rs) => {
            let boundary = format!("fmrh-{:016x}", boundary_for(&etag, rs.len()));
            let (parts, end) = ranges::multipart_heads(&rs, len, &boundary);
            common(
                Response::new(
                    206,
                    &format!("multipart/byteranges; boundary={boundary}"),
                    Body::Parts(file, parts, end),
                )
                .with("Cache-Control", "no-cache"),
            )
        }
    }
}

/// A boundary that differs between objects and requests (it only has to be absent from
/// the parts' bytes in practice; the reader finds parts by their announced lengths).
fn boundary_for(etag: &str, n: usize) -> u64 {
    use std::hash::{BuildHasher, Hasher};
    let mut h = std::collections::hash_map::RandomState::new().build_hasher();
    h.write(etag.as_bytes());
    h.write_usize(n);
    h.finish()
}

/// A strong validator from what changes when a file does: its length, modification time
/// and identity (every fmrh commit writes, so every commit changes the time).
fn etag_of(meta: &std::fs::Metadata) -> String {
    let nanos = meta
        .modified()
        .ok()
        .and_then(|t| t.duration_since(std::time::UNIX_EPOCH).ok())
        .map_or(0, |d| d.as_nanos());
    #[cfg(unix)]
    let id = {
        use std::os::unix::fs::MetadataExt;
        (meta.dev() << 32) ^ meta.ino()
    };
    #[cfg(not(unix))]
    let id = 0u64;
    format!("\"{:x}-{:x}-{:x}\"", meta.len(), nanos, id)
}

/// `%XX` decoding (and `+` as a space in queries); `None` for a bad escape or bytes that
/// are not UTF-8.
fn percent_decode(text: &str, plus_is_space: bool) -> Option<String> {
    let mut out = Vec::with_capacity(text.len());
    let mut bytes = text.bytes();
    while let Some(b) = bytes.next() {
        match b {
            b'%' => {
                let hex = |c: Option<u8>| (c? as char).to_digit(16);
                let (hi, lo) = (hex(bytes.next())?, hex(bytes.next())?);
                out.push((hi * 16 + lo) as u8);
            }
            b'+' if plus_is_space => out.push(b' '),
            b => out.push(b),
        }
    }
    String::from_utf8(out).ok()
}

/// What is served: each item's address, size in samples, spacing and height range (the
/// page places its first camera from them), and the level hues.
fn list(items: &[Item]) -> Result<Value, Error> {
    let mut out = Vec::new();
    for item in items {
        let (width, height, spacing, range, levels) = if item.dataset {
            let ds = crate::dataset::Dataset::open(&item.path)?;
            let grid = ds.grid();
            let range = ds.tiles()?.iter().fold(None, |r: Option<[f32; 2]>, t| {
                let (lo, hi) = (t.record.min_height.get(), t.record.max_height.get());
                if lo > hi {
                    return r; // an all-void tile
                }
                Some(r.map_or([lo, hi], |[a, b]| [a.min(lo), b.max(hi)]))
            });
            (
                grid.col1 - grid.col0 + 1,
                grid.row1 - grid.row0 + 1,
                ds.spacing_m(),
                range,
                None,
            )
        } else {
            let store = super::open(&item.path)?;
            let d = *store.domain();
            let h = store.header();
            let range = store
                .nodes()?
                .first()
                .filter(|_| h.valid_samples > 0)
                .map(|root| [root.min_height, root.max_height]);
            (
                u64::from(d.width()),
                u64::from(d.height()),
                h.metadata.spacing_m,
                range,
                Some(d.levels()),
            )
        };
        out.push(json!({
            "name": item.name,
            "kind": if item.dataset { "dataset" } else { "container" },
            "url": format!("/files/{}{}", item.name, if item.dataset { "/" } else { "" }),
            "width": width,
            "height": height,
            "spacing_m": spacing,
            "height_range": range,
            "levels": levels,
        }));
    }
    // The hues `fmrh render` tints levels with, so the page and the pictures agree.
    let colours: Vec<[u8; 3]> = (0..=u8::MAX).map(crate::render::level_colour).collect();
    Ok(json!({ "items": out, "level_colours": colours }))
}

/// A camera, a tolerance and an item, from a query string.
struct ViewQuery<'a> {
    item: &'a Item,
    camera: Camera,
    view: ViewArgs,
    style: MeshStyle,
    refine: Option<RefineArg>,
}

fn parse_view<'a>(items: &'a [Item], query: &str) -> Result<ViewQuery<'a>, Error> {
    let mut params: BTreeMap<String, String> = BTreeMap::new();
    for pair in query.split('&').filter(|p| !p.is_empty()) {
        let (k, v) = pair.split_once('=').unwrap_or((pair, ""));
        let bad = || Error::InvalidArgument(format!("`{pair}`: not valid percent-encoded UTF-8"));
        let k = percent_decode(k, true).ok_or_else(bad)?;
        let v = percent_decode(v, true).ok_or_else(bad)?;
        const KNOWN: [&str; 11] = [
            "item",
            "eye",
            "target",
            "up",
            "tau",
            "fov",
            "viewport",
            "mode",
            "cracks",
            "refine",
            "max_error",
        ];
        if !KNOWN.contains(&k.as_str()) {
            return Err(Error::InvalidArgument(format!(
                "unknown parameter `{k}` (known: {})",
                KNOWN.join(", ")
            )));
        }
        params.insert(k, v);
    }
    let need = |k: &str| {
        params
            .get(k)
            .map(String::as_str)
            .ok_or_else(|| Error::InvalidArgument(format!("the parameter `{k}` is required")))
    };
    let name = need("item")?;
    let item = items
        .iter()
        .find(|i| i.name == name)
        .ok_or_else(|| Error::InvalidArgument(format!("no item is served as `{name}`")))?;
    let tau: f64 = need("tau")?
        .parse()
        .map_err(|_| Error::InvalidArgument("`tau`: expected a number of pixels".into()))?;
    let fov = match params.get("fov") {
        Some(f) => f
            .parse()
            .map_err(|_| Error::InvalidArgument("`fov`: expected degrees".into()))?,
        None => crate::scene::camera::DEFAULT_FOV_DEG,
    };
    let mode = match params.get("mode").map(String::as_str) {
        None | Some("view") => ModeArg::View,
        Some("uniform") => ModeArg::Uniform,
        Some(m) => {
            return Err(Error::InvalidArgument(format!(
                "`mode`: `{m}` is neither view nor uniform"
            )))
        }
    };
    let cracks = match params.get("cracks").map(String::as_str) {
        None | Some("stitch") => Cracks::Stitch,
        Some("skirts") => Cracks::Skirts,
        Some(c) => {
            return Err(Error::InvalidArgument(format!(
                "`cracks`: `{c}` is neither stitch nor skirts"
            )))
        }
    };
    // `max_error`: each block a TIN within that many metres, closed with skirts.
    let style = match params.get("max_error").map(String::as_str) {
        None | Some("") => MeshStyle::Grid(cracks),
        Some(_) if params.get("cracks").map(String::as_str) == Some("stitch") => {
            return Err(Error::InvalidArgument(
                "`max_error` meshes TINs, whose cracks close with skirts: leave out \
                 `cracks=stitch`"
                    .into(),
            ))
        }
        Some(m) => {
            let metres = m.parse().map_err(|_| {
                Error::InvalidArgument(format!("`max_error`: `{m}` is not a number of metres"))
            })?;
            MeshStyle::tin(metres, "`max_error`")?
        }
    };
    let refine = match params.get("refine").map(String::as_str) {
        None | Some("none") => None,
        Some("fractal") => Some(RefineArg::Fractal),
        Some(r) => {
            return Err(Error::InvalidArgument(format!(
                "`refine`: `{r}` is neither none nor fractal"
            )))
        }
    };
    let view = ViewArgs {
        fov,
        viewport: params
            .get("viewport")
            .cloned()
            .unwrap_or_else(|| "1024x768".into()),
        tau,
        mode,
        gap: DEFAULT_GAP,
        mmap: false,
        spacing: None,
    };
    let camera = Camera {
        eye: super::args::parse_vec3(need("eye")?, "eye")?,
        target: super::args::parse_vec3(need("target")?, "target")?,
        up: super::args::parse_vec3(params.get("up").map_or("0,0,1", String::as_str), "up")?,
        fov_y_deg: fov,
        viewport: view.viewport()?,
        handedness: crate::scene::Handedness::Left,
    };
    Ok(ViewQuery {
        item,
        camera,
        view,
        style,
        refine,
    })
}

/// One block as the page lists it.
#[derive(Serialize)]
struct BlockAnswer {
    #[serde(skip_serializing_if = "Option::is_none")]
    tile: Option<u64>,
    level: u8,
    x: u32,
    y: u32,
    key: u64,
    error: f64,
    screen_error: f64,
}

/// The scene `q` asks for, as the page shows it: the stats its panel prints, and the
/// blocks.
fn scene(q: &ViewQuery<'_>) -> Result<Value, Error> {
    let started = Instant::now();
    let options = q.view.options();
    let (stats, blocks): (SceneStats, Vec<BlockAnswer>) = if q.item.dataset {
        let ds = crate::dataset::Dataset::open(&q.item.path)?;
        let s = ds.scene(&q.camera, &options, None)?;
        let blocks = s
            .blocks
            .iter()
            .map(|b| block_answer(Some(b.tile), &b.block))
            .collect();
        (s.stats, blocks)
    } else {
        let store = super::open(&q.item.path)?;
        let spacing = q.view.spacing(&store, &q.item.path)?;
        let s = Terrain::with_spacing(&store, spacing)?.scene(&q.camera, &options)?;
        let blocks = s.blocks.iter().map(|b| block_answer(None, b)).collect();
        (s.stats, blocks)
    };
    let mut levels: BTreeMap<u8, u64> = BTreeMap::new();
    for b in &blocks {
        *levels.entry(b.level).or_default() += 1;
    }
    Ok(json!({
        "item": q.item.name,
        "tau": q.view.tau,
        "blocks": stats.blocks,
        "levels": levels,
        "payload_bytes": stats.bytes,
        "samples": stats.samples,
        "index_pages": stats.index_pages,
        "node_reads": stats.node_reads,
        "top_reads": stats.top_reads,
        "schedule_us": stats.schedule_ns as f64 / 1e3,
        "max_error_m": stats.max_error,
        "max_screen_error_px": stats.max_screen_error,
        "server_ms": started.elapsed().as_secs_f64() * 1e3,
        "list": blocks,
    }))
}

fn block_answer(tile: Option<u64>, b: &crate::scene::SceneBlock) -> BlockAnswer {
    BlockAnswer {
        tile,
        level: b.level,
        x: b.x,
        y: b.y,
        key: b.key,
        error: b.error,
        screen_error: b.screen_error,
    }
}

/// The scene `q` asks for, meshed as `fmrh mesh` meshes it: one glTF binary.
fn mesh(q: &ViewQuery<'_>) -> Result<Answer, Error> {
    let options = q.view.options();
    let meshed = super::mesh::mesh_scene(
        &q.item.path,
        &q.view,
        &q.camera,
        &options,
        q.style,
        q.refine,
        false,
    )?;
    let glb = meshed.glb()?;
    Ok(bytes(200, "model/gltf-binary", glb)
        .with("X-Fmrh-Triangles", meshed.triangles().to_string()))
}

#[cfg(test)]
mod tests {
    use super::percent_decode;

    #[test]
    fn percent_decoding() {
        assert_eq!(percent_decode("a%2Cb+c", true).as_deref(), Some("a,b c"));
        assert_eq!(percent_decode("a+b", false).as_deref(), Some("a+b"));
        assert_eq!(percent_decode("%e2%82%ac", false).as_deref(), Some("€"));
        assert_eq!(percent_decode("%2", false), None);
        assert_eq!(percent_decode("%zz", false), None);
        assert_eq!(percent_decode("%ff", false), None);
    }
}
