//! `fmrh serve`'s Cesium terrain: `/NAME/layer.json` and `/NAME/{z}/{x}/{y}.terrain` for
//! every served container and dataset that can be placed on the globe
//! (`crate::export::tileset`), each tile cut on request from the current state of the
//! store.
//!
//! **Freshness.** Every request opens the terrain afresh, so a commit (`fmrh replace`,
//! `dataset add`) is seen by the next request. The layer's `version` (in the tiles'
//! addresses, `?v=`) is the state's transaction id and the file's identity, so a new state
//! gets new addresses. A tile's `ETag` is a hash of its bytes: a tile the commit did not
//! change keeps its tag, and a client's `If-None-Match` gets `304`. Tiles of the current
//! version may be cached a day (`Cache-Control`); anything else must revalidate.
//!
//! **The cache.** Cut tiles are kept, by state, address and extensions, in a small LRU
//! ([`TileCache`], 64 MiB), with their gzip form; a new state misses it and cuts afresh.
//! Cuts run twice as many at once as there are cores, the others waiting their turn in
//! order ([`CutGate`]), so a slow tile is not slowed further by every other client's.
//!
//! **What a client asks.** `Accept: application/vnd.quantized-mesh;extensions=a-b-c` picks
//! the extensions (`octvertexnormals`, `metadata`; `watermask` is not made and is left
//! out); `application/octet-stream` or `*/*` gets the tile without extensions; an `Accept`
//! that takes none of these gets `406`. `Accept-Encoding: gzip` gets it gzipped. Every
//! answer carries CORS headers (`Access-Control-Allow-Origin: *`), and `OPTIONS` answers
//! a preflight.

use std::collections::HashMap;
use std::hash::{Hash, Hasher};
use std::io::Write;
use std::sync::{Arc, Mutex};

use crate::export::geodetic::GeodeticTile;
use crate::export::terrain_rgb::{Encoding, MercatorTile};
use crate::export::tileset::{EdgeCache, Tileset};
use crate::geoid::VerticalDatum;
use crate::http::{Body, Request, Response};
use crate::pyramid::{cut_blocks, shape_of};
use crate::terrain::Terrain;
use crate::Error;

use super::Item;

/// Bytes of tiles the cache keeps.
const CACHE_BYTES: usize = 64 << 20;

/// What `fmrh serve` was told about its terrain.
#[derive(Clone, Copy, Debug)]
pub struct Options {
    /// The cap on every level's TIN budget, metres.
    pub max_error: Option<f64>,
    /// What the heights are above; `None`: what each terrain's format says.
    pub datum: Option<VerticalDatum>,
    /// Whether each state's coarse tiles are cut ahead ([`warm`]).
    pub warm: bool,
}

/// Levels at least this many above the deepest are the coarse ones [`warm`] cuts ahead:
/// each of their tiles holds 2^10 or more of the deepest level's tiles, and measures its
/// TIN against every data sample under it.
const WARM_ABOVE_DEEPEST: u8 = 5;

/// Every combination of extensions a client may ask: a tile warmed is encoded for each.
const ALL_EXTENSIONS: [Extensions; 4] = [
    Extensions {
        normals: false,
        metadata: false,
    },
    Extensions {
        normals: true,
        metadata: false,
    },
    Extensions {
        normals: false,
        metadata: true,
    },
    Extensions {
        normals: true,
        metadata: true,
    },
];

/// The extensions a tile is written with.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub(super) struct Extensions {
    normals: bool,
    metadata: bool,
}

impl Extensions {
    fn names(&self) -> String {
        let mut v = Vec::new();
        if self.normals {
            v.push("octvertexnormals");
        }
        if self.metadata {
            v.push("metadata");
        }
        v.join("-")
    }
}

/// A cached tile: its bytes, gzipped, and its tag.
#[derive(Clone)]
struct Cached {
    plain: Arc<Vec<u8>>,
    gzip: Arc<Vec<u8>>,
    tag: u64,
}

/// Key: item, state version, and which tile of which pyramid.
type Key = (String, String, Tile);

/// A cached tile's own part of the key.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub(super) enum Tile {
    /// A quantized-mesh tile with its extensions.
    Mesh(GeodeticTile, Extensions),
    /// A terrain-RGB tile: its address, encoding, size and no-data fill (as its bits, or
    /// `u64::MAX` for transparent).
    Rgb(MercatorTile, Encoding, u32, u64),
}

/// Cut tiles, least recently used dropped first past [`CACHE_BYTES`].
#[derive(Default)]
pub struct TileCache {
    inner: Mutex<CacheState>,
    /// Each item's meshed edges, for its current state ([`EdgeCache`]).
    edges: Mutex<HashMap<String, (String, Arc<EdgeCache>)>>,
    /// Who may cut a tile now.
    gate: CutGate,
}

/// Cutting tiles, twice as many at once as there are cores, the rest waiting in the order
/// they came. Every connection has its own thread; without the gate, sixteen clients' cuts
/// share two cores evenly, and a coarse tile (measured at every sample under it, tens of
/// milliseconds of one core) takes eight times its own time to finish. In turn, each
/// waits for the cuts ahead of it and then shares the cores with only a few others.
struct CutGate {
    slots: usize,
    state: Mutex<GateState>,
    turn: std::sync::Condvar,
}

impl Default for CutGate {
    fn default() -> CutGate {
        // Twice the cores: a cut also waits (on page faults, on the store's locks), and
        // with one slot a core the cores idled a third of the time (measured: 2 slots on 2
        // cores cut 192 tiles/s at 16 clients, 4 slots 269, 8 slots 279, p99 556, 314 and
        // 357 ms).
        CutGate::new(2 * std::thread::available_parallelism().map_or(1, |n| n.get()))
    }
}

#[derive(Default)]
struct GateState {
    /// Tickets of the cuts waiting, first come first.
    waiting: std::collections::VecDeque<u64>,
    next: u64,
    running: usize,
}

/// A cut's place at the gate, given back when dropped.
struct Slot<'a>(&'a CutGate);

impl CutGate {
    fn new(slots: usize) -> CutGate {
        CutGate {
            slots: slots.max(1),
            state: Mutex::default(),
            turn: std::sync::Condvar::new(),
        }
    }

    /// Waits for this cut's turn: a free slot, and no one who came earlier still waiting.
    fn enter(&self) -> Slot<'_> {
        let slots = self.slots;
        let mut s = self.state.lock().unwrap_or_else(|p| p.into_inner());
        let ticket = s.next;
        s.next += 1;
        s.waiting.push_back(ticket);
        while !(s.running < slots && s.waiting.front() == Some(&ticket)) {
            s = self.turn.wait(s).unwrap_or_else(|p| p.into_inner());
        }
        s.waiting.pop_front();
        s.running += 1;
        // The next in line may have a free slot too.
        self.turn.notify_all();
        Slot(self)
    }
}

impl Drop for Slot<'_> {
    fn drop(&mut self) {
        let mut s = self.0.state.lock().unwrap_or_else(|p| p.into_inner());
        s.running -= 1;
        self.0.turn.notify_all();
    }
}

#[derive(Default)]
struct CacheState {
    /// Each tile, with the tick it was last used at.
    map: HashMap<Key, (Cached, u64)>,
    /// The tiles by the tick they were last used at: the first is the least recent.
    order: std::collections::BTreeMap<u64, Key>,
    tick: u64,
    bytes: usize,
}

impl TileCache {
    fn get(&self, key: &Key) -> Option<Cached> {
        let mut s = self.inner.lock().unwrap_or_else(|p| p.into_inner());
        s.tick += 1;
        let tick = s.tick;
        let (hit, old) = {
            let (c, used) = s.map.get_mut(key)?;
            let old = std::mem::replace(used, tick);
            (c.clone(), old)
        };
        if let Some(k) = s.order.remove(&old) {
            s.order.insert(tick, k);
        }
        Some(hit)
    }

    /// The edge cache of `item` at state `version` (a new one when the state changed), and
    /// whether this call made it: the first look at a new state.
    fn edges(&self, item: &str, version: &str) -> (Arc<EdgeCache>, bool) {
        let mut all = self.edges.lock().unwrap_or_else(|p| p.into_inner());
        match all.get(item) {
            Some((v, cache)) if v == version => (cache.clone(), false),
            _ => {
                let cache = Arc::new(EdgeCache::default());
                all.insert(item.to_string(), (version.to_string(), cache.clone()));
                (cache, true)
            }
        }
    }

    /// The bytes of `tile` of `item` at `version` and their tag, from the cache or cut by
    /// `cut` through the gate (and kept), and whether they came from the cache. For tiles
    /// sent as they are (no gzip form).
    pub(super) fn get_or_cut(
        &self,
        item: &str,
        version: &str,
        tile: Tile,
        cut: impl FnOnce() -> Result<Vec<u8>, Error>,
    ) -> Result<(Arc<Vec<u8>>, u64, bool), Error> {
        let key: Key = (item.to_string(), version.to_string(), tile);
        let _slot = match self.get_or_turn(&key) {
            Ok(hit) => return Ok((hit.plain, hit.tag, true)),
            Err(slot) => slot,
        };
        let plain = Arc::new(cut()?);
        let tag = tag_of(&plain);
        self.put(key, plain.clone(), Arc::new(Vec::new()), tag);
        Ok((plain, tag, false))
    }

    /// The tile at `key` from the cache, or else this caller's turn to cut it (the slot
    /// held until dropped): looked up again once the turn comes, since another request (or
    /// the warming) may have cut it meanwhile.
    fn get_or_turn(&self, key: &Key) -> Result<Cached, Slot<'_>> {
        if let Some(hit) = self.get(key) {
            return Ok(hit);
        }
        let slot = self.gate.enter();
        match self.get(key) {
            Some(hit) => Ok(hit),
            None => Err(slot),
        }
    }

    fn put(&self, key: Key, plain: Arc<Vec<u8>>, gzip: Arc<Vec<u8>>, tag: u64) {
        let size = plain.len() + gzip.len();
        if size > CACHE_BYTES / 4 {
            return;
        }
        let mut s = self.inner.lock().unwrap_or_else(|p| p.into_inner());
        if s.map.contains_key(&key) {
            return;
        }
        while s.bytes + size > CACHE_BYTES {
            let Some((_, old)) = s.order.pop_first() else {
                break;
            };
            if let Some((c, _)) = s.map.remove(&old) {
                s.bytes -= c.plain.len() + c.gzip.len();
            }
        }
        s.tick += 1;
        let tick = s.tick;
        s.bytes += size;
        s.order.insert(tick, key.clone());
        s.map.insert(key, (Cached { plain, gzip, tag }, tick));
    }
}

/// A tile's tag: a hash of its bytes (its `ETag`).
fn tag_of(bytes: &[u8]) -> u64 {
    let mut h = std::collections::hash_map::DefaultHasher::new();
    bytes.hash(&mut h);
    h.finish()
}

/// The answer to a CORS preflight for tiles: GET and HEAD, with `allow_headers`.
pub(super) fn preflight(allow_headers: &str) -> Response {
    with_cors(
        Response::new(204, "text/plain", Body::Bytes(Vec::new()))
            .with("Access-Control-Allow-Methods", "GET, HEAD, OPTIONS")
            .with("Access-Control-Allow-Headers", allow_headers)
            .with("Access-Control-Max-Age", "86400"),
    )
}

pub(super) fn with_cors(r: Response) -> Response {
    r.with("Access-Control-Allow-Origin", "*")
        .with("Access-Control-Expose-Headers", "ETag, Content-Encoding")
}

pub(super) fn text_error(status: u16, message: impl Into<String>) -> Response {
    let body =
        serde_json::to_vec(&serde_json::json!({ "error": message.into() })).unwrap_or_default();
    with_cors(
        Response::new(status, "application/json", Body::Bytes(body))
            .with("Cache-Control", "no-cache"),
    )
}

/// What a terrain address asks for.
enum Asked {
    Layer,
    Tile(GeodeticTile),
}

/// Whether `path` is under a served item's terrain: `/NAME/` and more, `NAME` served.
pub fn is_address(items: &[Item], path: &str) -> bool {
    path.strip_prefix('/')
        .and_then(|rest| rest.split_once('/'))
        .is_some_and(|(name, _)| items.iter().any(|i| i.name == name))
}

/// The terrain answer for `path` (already percent-decoded), or `None` when the path is not
/// a terrain address (`/NAME/layer.json`, `/NAME/Z/X/Y.terrain`) of a served item.
pub fn route(
    items: &[Item],
    cache: &Arc<TileCache>,
    options: Options,
    path: &str,
    query: &str,
    request: &Request,
) -> Option<Response> {
    let rest = path.strip_prefix('/')?;
    let (name, tail) = rest.split_once('/')?;
    let item = items.iter().find(|i| i.name == name)?;
    let asked = if tail == "layer.json" {
        Asked::Layer
    } else {
        let parts: Vec<&str> = tail.split('/').collect();
        let [z, x, y] = parts.as_slice() else {
            return None;
        };
        let y = y.strip_suffix(".terrain")?;
        match (tile_number(z), tile_number(x), tile_number(y)) {
            (Some(z), Some(x), Some(y)) if z <= 255 => {
                Asked::Tile(GeodeticTile { z: z as u8, x, y })
            }
            _ => return Some(text_error(400, format!("`{tail}`: expected Z/X/Y.terrain"))),
        }
    };
    if request.method == "OPTIONS" {
        return Some(preflight("Accept, Accept-Encoding, If-None-Match"));
    }
    Some(answer(item, cache, options, &asked, query, request).unwrap_or_else(failed))
}

/// A tile address's number: decimal digits only, at most ten of them.
pub(super) fn tile_number(s: &str) -> Option<u32> {
    (!s.is_empty() && s.len() <= 10 && s.bytes().all(|b| b.is_ascii_digit()))
        .then(|| s.parse().ok())
        .flatten()
}

/// The answer for a tile that could not be made: the request's fault (404: nothing
/// there), a file that is not a usable container (422), or the server's (500).
pub(super) fn failed(e: Error) -> Response {
    let status = match &e {
        Error::InvalidArgument(_) => 404,
        Error::Input { .. } | Error::Unsupported { .. } | Error::Corrupt { .. } => 422,
        _ => 500,
    };
    text_error(status, e.to_string())
}

/// The state's version: its transaction id and the identity of the file that holds it.
pub(super) fn version(item: &Item, txn: u64) -> String {
    let file = if item.dataset {
        item.path.join("MANIFEST")
    } else {
        item.path.clone()
    };
    let id = std::fs::metadata(&file).map_or(String::new(), |m| super::etag_of(&m));
    let mut h = std::collections::hash_map::DefaultHasher::new();
    id.hash(&mut h);
    format!("{txn}-{:08x}", h.finish() as u32)
}

fn answer(
    item: &Item,
    cache: &Arc<TileCache>,
    options: Options,
    asked: &Asked,
    query: &str,
    request: &Request,
) -> Result<Response, Error> {
    let terrain = Terrain::open(&item.path)?;
    let info = terrain.info()?;
    let datum = options.datum.unwrap_or(info.vertical_datum);
    let tileset = Tileset::new(&shape_of(&info), options.max_error, datum)?;
    let version = version(item, info.txn_id);
    match asked {
        Asked::Layer => {
            let body = serde_json::to_vec_pretty(&tileset.layer_json(&item.name, &version))
                .map_err(|e| Error::InvalidArgument(format!("layer.json: {e}")))?;
            Ok(with_cors(
                Response::new(200, "application/json", Body::Bytes(body))
                    .with("Cache-Control", "no-cache"),
            ))
        }
        Asked::Tile(t) => {
            let columns = 2u64 << t.z.min(31);
            let rows = 1u64 << t.z.min(31);
            if t.z > tileset.maxzoom() {
                return Ok(text_error(
                    404,
                    format!("level {} is past the deepest, {}", t.z, tileset.maxzoom()),
                ));
            }
            if u64::from(t.x) >= columns || u64::from(t.y) >= rows {
                return Ok(text_error(
                    400,
                    format!(
                        "tile {}/{}/{}: level {} has columns 0..{columns} and rows 0..{rows}",
                        t.z, t.x, t.y, t.z
                    ),
                ));
            }
            if !tileset.has(*t) {
                return Ok(text_error(
                    404,
                    "no data in this tile (see layer.json's available)",
                ));
            }
            let Some(ext) = accepted(request.header("Accept")) else {
                return Ok(text_error(
                    406,
                    "this serves application/vnd.quantized-mesh (or application/octet-stream)",
                ));
            };
            let gzip = request.header("Accept-Encoding").is_some_and(|v| {
                v.split(',')
                    .any(|e| e.trim().split(';').next() == Some("gzip"))
            });
            let key: Key = (item.name.clone(), version.clone(), Tile::Mesh(*t, ext));
            let looked = cache.get_or_turn(&key);
            let from_cache = looked.is_ok();
            let Cached {
                plain,
                gzip: zipped,
                tag,
            } = match looked {
                Ok(hit) => hit,
                Err(_slot) => {
                    let (edges, new_state) = cache.edges(&item.name, &version);
                    if new_state && options.warm {
                        spawn_warm(item, cache, options);
                    }
                    let cut = tileset.cut(*t, |w, bound| cut_blocks(&terrain, w, bound), &edges)?;
                    put_encoded(cache, &item.name, &version, *t, &cut, &[ext])?.0
                }
            };
            let etag = format!(
                "\"{tag:016x}-{}{}\"",
                ext.names(),
                if gzip { "-gz" } else { "" }
            );
            let current = query
                .split('&')
                .any(|p| p.strip_prefix("v=") == Some(version.as_str()));
            let cache_control = if current {
                "public, max-age=86400"
            } else {
                "no-cache"
            };
            let content_type = if ext.names().is_empty() {
                "application/vnd.quantized-mesh".to_string()
            } else {
                format!("application/vnd.quantized-mesh;extensions={}", ext.names())
            };
            let matches = request
                .header("If-None-Match")
                .is_some_and(|v| v.split(',').map(str::trim).any(|t| t == etag || t == "*"));
            let status = if matches { 304 } else { 200 };
            let body = if matches {
                Vec::new()
            } else if gzip {
                zipped.as_ref().clone()
            } else {
                plain.as_ref().clone()
            };
            let mut r = Response::new(status, &content_type, Body::Bytes(body))
                .with("X-Fmrh-Cache", if from_cache { "hit" } else { "miss" })
                .with("ETag", etag)
                .with("Cache-Control", cache_control)
                .with("Vary", "Accept, Accept-Encoding");
            if gzip && !matches {
                r = r.with("Content-Encoding", "gzip");
            }
            Ok(with_cors(r))
        }
    }
}

/// Encodes cut tile `t` of `item` at `version` with each of `exts`, puts each (with its
/// gzip form and tag) in the cache, and returns the first.
fn put_encoded(
    cache: &TileCache,
    item: &str,
    version: &str,
    t: GeodeticTile,
    cut: &crate::export::tin_tile::TinTile,
    exts: &[Extensions],
) -> Result<(Cached, usize), Error> {
    let mut first = None;
    let mut bytes = 0;
    for &ext in exts {
        let plain = Tileset::encode(cut, ext.normals, ext.metadata)?;
        let tag = tag_of(&plain);
        let zipped = crate::pyramid::gzip(&plain)?;
        bytes += plain.len() + zipped.len();
        let (plain, gzip) = (Arc::new(plain), Arc::new(zipped));
        let key: Key = (item.to_string(), version.to_string(), Tile::Mesh(t, ext));
        cache.put(key, plain.clone(), gzip.clone(), tag);
        first.get_or_insert(Cached { plain, gzip, tag });
    }
    let first = first
        .ok_or_else(|| Error::InvalidArgument("no extensions to encode a tile with".into()))?;
    Ok((first, bytes))
}

/// Cuts `item`'s warming ([`warm`]) on a thread of its own, and says on standard output
/// what it cut: `fmrh: warmed N tiles of NAME (levels 0..=K, state V) in S s`, or why not.
pub fn spawn_warm(item: &Item, cache: &Arc<TileCache>, options: Options) {
    let (item, cache) = (item.clone(), Arc::clone(cache));
    let spawned = std::thread::Builder::new()
        .name(format!("warm {}", item.name))
        .spawn(move || {
            let started = std::time::Instant::now();
            let line = match warm(&item, &cache, options) {
                Ok(Some((n, top, version))) => format!(
                    "fmrh: warmed {n} tiles of {} (levels 0..={top}, state {version}) in {:.2} s",
                    item.name,
                    started.elapsed().as_secs_f64()
                ),
                Ok(None) => return,
                Err(e) => format!("fmrh: warming {} stopped: {e}", item.name),
            };
            let mut out = std::io::stdout().lock();
            let _ = writeln!(out, "{line}");
            let _ = out.flush();
        });
    // No thread to be had: the tiles are cut when asked, as without warming.
    drop(spawned);
}

/// Cuts the coarse tiles of `item`'s current state (levels up to the deepest less
/// [`WARM_ABOVE_DEEPEST`], where the data is, coarsest first) into the cache, encoded with
/// every combination of extensions, each through the gate in its turn like a client's. A
/// coarse tile measures its TIN against every sample under it (tens of milliseconds of a
/// core); over one SRTM tile they are few (about one a level, then four, then sixteen),
/// and cut ahead no client waits for them. Over a wide dataset they are many: the warming
/// stops once it has put a quarter of the cache's bytes in, so it never pushes out what
/// clients asked, and the finer of them are cut when asked. Returns how many were cut, the
/// last level and the state; `None` when the item has no terrain or no level is coarse.
fn warm(
    item: &Item,
    cache: &TileCache,
    options: Options,
) -> Result<Option<(usize, u8, String)>, Error> {
    let terrain = Terrain::open(&item.path)?;
    let info = terrain.info()?;
    let datum = options.datum.unwrap_or(info.vertical_datum);
    let Ok(tileset) = Tileset::new(&shape_of(&info), options.max_error, datum) else {
        return Ok(None);
    };
    let version = version(item, info.txn_id);
    let Some(top) = tileset.maxzoom().checked_sub(WARM_ABOVE_DEEPEST) else {
        return Ok(None);
    };
    let (edges, _) = cache.edges(&item.name, &version);
    let (mut n, mut bytes) = (0, 0);
    for z in 0..=top {
        let Some((x0, y0, x1, y1)) = tileset.available(z) else {
            continue;
        };
        for y in y0..=y1 {
            for x in x0..=x1 {
                let t = GeodeticTile { z, x, y };
                if !tileset.has(t) {
                    continue;
                }
                let _slot = cache.gate.enter();
                let asked = ALL_EXTENSIONS.iter().all(|&e| {
                    cache
                        .get(&(item.name.clone(), version.clone(), Tile::Mesh(t, e)))
                        .is_some()
                });
                if asked {
                    continue;
                }
                if bytes > CACHE_BYTES / 4 {
                    return Ok(Some((n, z, version)));
                }
                let cut = tileset.cut(t, |w, bound| cut_blocks(&terrain, w, bound), &edges)?;
                bytes += put_encoded(cache, &item.name, &version, t, &cut, &ALL_EXTENSIONS)?.1;
                n += 1;
            }
        }
    }
    Ok(Some((n, top, version)))
}

/// The extensions an `Accept` header asks for; `None` when it takes neither
/// quantized-mesh nor an octet stream nor anything. No header: no extensions.
fn accepted(accept: Option<&str>) -> Option<Extensions> {
    let Some(accept) = accept else {
        return Some(Extensions {
            normals: false,
            metadata: false,
        });
    };
    let mut fallback = false;
    for range in accept.split(',') {
        let mut params = range.split(';').map(str::trim);
        let media = params.next().unwrap_or("").to_ascii_lowercase();
        let mut quality_zero = false;
        let mut extensions: Option<&str> = None;
        for p in params {
            if let Some((k, v)) = p.split_once('=') {
                match k.trim().to_ascii_lowercase().as_str() {
                    "q" => quality_zero = v.trim().parse::<f64>().is_ok_and(|q| q <= 0.0),
                    "extensions" => extensions = Some(v.trim()),
                    _ => {}
                }
            }
        }
        if quality_zero {
            continue;
        }
        match media.as_str() {
            "application/vnd.quantized-mesh" => {
                let names: Vec<&str> = extensions.map_or(Vec::new(), |e| e.split('-').collect());
                return Some(Extensions {
                    normals: names.contains(&"octvertexnormals"),
                    metadata: names.contains(&"metadata"),
                });
            }
            "application/octet-stream" | "application/*" | "*/*" => fallback = true,
            _ => {}
        }
    }
    fallback.then_some(Extensions {
        normals: false,
        metadata: false,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The waiting get in in the order they came: threads that enter one after another
    /// (each seen waiting before the next comes) get in in that order. One slot is held
    /// by the test throughout, so the threads pass the other one by one and each records
    /// its turn before it hands the slot on. (With both slots free, two threads are let
    /// in together and may record their turns in either order: CI saw `[1, 0, …]`.)
    #[test]
    fn the_gate_lets_the_waiting_in_in_the_order_they_came() {
        let gate = Arc::new(CutGate::new(2));
        let order = Arc::new(Mutex::new(Vec::new()));
        let (a, b) = (gate.enter(), gate.enter());
        let mut threads = Vec::new();
        for id in 0..8usize {
            let (g, order) = (gate.clone(), order.clone());
            threads.push(std::thread::spawn(move || {
                let slot = g.enter();
                order.lock().unwrap().push(id);
                drop(slot);
            }));
            // Wait until this thread is in the line before the next one comes.
            while gate.state.lock().unwrap().waiting.len() < id + 1 {
                std::thread::yield_now();
            }
        }
        drop(a);
        for t in threads {
            t.join().unwrap();
        }
        assert_eq!(*order.lock().unwrap(), (0..8).collect::<Vec<_>>());
        drop(b);
        assert_eq!(gate.state.lock().unwrap().running, 0);
    }

    /// The gate never lets in more than its slots: eight threads wanting in at once,
    /// each staying a while, are never more than two inside a two-slot gate.
    #[test]
    fn the_gate_keeps_its_slots() {
        use std::sync::atomic::{AtomicUsize, Ordering};
        let gate = Arc::new(CutGate::new(2));
        let inside = Arc::new(AtomicUsize::new(0));
        let most = Arc::new(AtomicUsize::new(0));
        let threads: Vec<_> = (0..8)
            .map(|_| {
                let (g, inside, most) = (gate.clone(), inside.clone(), most.clone());
                std::thread::spawn(move || {
                    let slot = g.enter();
                    let now = inside.fetch_add(1, Ordering::SeqCst) + 1;
                    most.fetch_max(now, Ordering::SeqCst);
                    std::thread::sleep(std::time::Duration::from_millis(2));
                    inside.fetch_sub(1, Ordering::SeqCst);
                    drop(slot);
                })
            })
            .collect();
        for t in threads {
            t.join().unwrap();
        }
        let most = most.load(Ordering::SeqCst);
        assert!((1..=2).contains(&most), "{most} inside at once");
        assert_eq!(gate.state.lock().unwrap().running, 0);
    }

    /// The cache keeps at most `CACHE_BYTES`, dropping the least recently used first: a
    /// tile asked for again outlives those put after it.
    #[test]
    fn the_cache_drops_the_least_recently_used() {
        let cache = TileCache::default();
        // Counted twice (plain and gzip): 10 MiB an entry, six fit in 64 MiB.
        let body = Arc::new(vec![0u8; 5 << 20]);
        let key = |x: u32| -> Key {
            (
                "t".into(),
                "1".into(),
                Tile::Mesh(
                    GeodeticTile { z: 3, x, y: 0 },
                    Extensions {
                        normals: true,
                        metadata: true,
                    },
                ),
            )
        };
        for x in 0..6 {
            cache.put(key(x), body.clone(), body.clone(), u64::from(x));
        }
        assert!(cache.get(&key(0)).is_some());
        cache.put(key(6), body.clone(), body.clone(), 6);
        // Tile 1 was the least recently used; tile 0 was asked for again.
        assert!(cache.get(&key(1)).is_none());
        assert_eq!(cache.get(&key(0)).map(|c| c.tag), Some(0));
        assert_eq!(cache.get(&key(6)).map(|c| c.tag), Some(6));
        let s = cache.inner.lock().unwrap();
        assert!(s.bytes <= CACHE_BYTES);
        assert_eq!(s.map.len(), s.order.len());
    }

    #[test]
    fn accept_headers() {
        let cesium = "application/vnd.quantized-mesh;extensions=octvertexnormals-watermask-metadata,application/octet-stream;q=0.9,*/*;q=0.01";
        assert_eq!(
            accepted(Some(cesium)),
            Some(Extensions {
                normals: true,
                metadata: true
            })
        );
        assert_eq!(
            accepted(Some("application/vnd.quantized-mesh")),
            Some(Extensions {
                normals: false,
                metadata: false
            })
        );
        assert!(accepted(Some("*/*")).is_some());
        assert_eq!(accepted(Some("image/png")), None);
        assert_eq!(accepted(Some("application/octet-stream;q=0")), None);
        assert_eq!(accepted(Some(";;;,,,===")), None);
        assert!(accepted(None).is_some());
    }
}
