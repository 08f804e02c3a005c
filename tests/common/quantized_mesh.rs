//! A reference decoder of quantized-mesh-1.0 tiles, written from the public specification
//! (github.com/CesiumGS/quantized-mesh) and sharing no code with fmrh's encoder: the
//! header, the zig-zag delta-coded vertex arrays, the high-water-mark indices, the edge
//! lists and the extensions, each read as the specification lays it out.

use std::collections::{BTreeMap, BTreeSet};
use std::path::Path;

use fmrh::Heightfield;

/// A tile as the specification describes it.
pub struct Decoded {
    /// The tile's centre (ECEF for a tile on the globe).
    pub centre: [f64; 3],
    pub min_height: f32,
    pub max_height: f32,
    /// Bounding sphere: centre and radius.
    pub sphere: [f64; 4],
    /// The horizon occlusion point, ellipsoid-scaled.
    pub horizon: [f64; 3],
    pub u: Vec<u16>,
    pub v: Vec<u16>,
    pub h: Vec<u16>,
    pub triangles: Vec<[u32; 3]>,
    /// West, south, east, north.
    pub edges: [Vec<u32>; 4],
    pub normals: Option<Vec<[u8; 2]>>,
    pub metadata: Option<serde_json::Value>,
}

struct Reader<'a> {
    bytes: &'a [u8],
    at: usize,
}

impl Reader<'_> {
    fn take(&mut self, n: usize) -> &[u8] {
        let s = &self.bytes[self.at..self.at + n];
        self.at += n;
        s
    }
    fn u8(&mut self) -> u8 {
        self.take(1)[0]
    }
    fn u16(&mut self) -> u16 {
        u16::from_le_bytes(self.take(2).try_into().unwrap())
    }
    fn u32(&mut self) -> u32 {
        u32::from_le_bytes(self.take(4).try_into().unwrap())
    }
    fn f32(&mut self) -> f32 {
        f32::from_le_bytes(self.take(4).try_into().unwrap())
    }
    fn f64(&mut self) -> f64 {
        f64::from_le_bytes(self.take(8).try_into().unwrap())
    }
}

/// Decodes a `.terrain` tile; panics on anything the specification does not allow.
pub fn decode(bytes: &[u8]) -> Decoded {
    let mut r = Reader { bytes, at: 0 };
    // QuantizedMeshHeader: centre (3 doubles), min and max height (2 floats), bounding
    // sphere (4 doubles), horizon occlusion point (3 doubles).
    let centre = [r.f64(), r.f64(), r.f64()];
    let (min_height, max_height) = (r.f32(), r.f32());
    let sphere = [r.f64(), r.f64(), r.f64(), r.f64()];
    let horizon = [r.f64(), r.f64(), r.f64()];
    assert_eq!(r.at, 88);
    let n = r.u32() as usize;
    let mut arrays: Vec<Vec<u16>> = Vec::new();
    for _ in 0..3 {
        let mut value: i32 = 0;
        let mut out = Vec::with_capacity(n);
        for _ in 0..n {
            let z = i32::from(r.u16());
            value += (z >> 1) ^ -(z & 1);
            out.push(u16::try_from(value).expect("a value in 0..=32767"));
        }
        arrays.push(out);
    }
    let wide = n > 65536;
    let align = if wide { 4 } else { 2 };
    while !r.at.is_multiple_of(align) {
        r.u8();
    }
    let index = |r: &mut Reader<'_>| if wide { r.u32() } else { u32::from(r.u16()) };
    let triangle_count = r.u32() as usize;
    let mut highest = 0u32;
    let mut flat = Vec::with_capacity(3 * triangle_count);
    for _ in 0..3 * triangle_count {
        let code = index(&mut r);
        flat.push(highest - code);
        if code == 0 {
            highest += 1;
        }
    }
    let triangles = flat.chunks_exact(3).map(|t| [t[0], t[1], t[2]]).collect();
    let edges: [Vec<u32>; 4] = std::array::from_fn(|_| {
        let count = r.u32() as usize;
        (0..count).map(|_| index(&mut r)).collect()
    });
    let (mut normals, mut metadata) = (None, None);
    while r.at < bytes.len() {
        let id = r.u8();
        let len = r.u32() as usize;
        let body = r.take(len).to_vec();
        match id {
            1 => normals = Some(body.chunks_exact(2).map(|c| [c[0], c[1]]).collect()),
            4 => {
                let json_len = u32::from_le_bytes(body[0..4].try_into().unwrap()) as usize;
                metadata = Some(serde_json::from_slice(&body[4..4 + json_len]).unwrap());
            }
            _ => panic!("unknown extension {id}"),
        }
    }
    let mut it = arrays.into_iter();
    Decoded {
        centre,
        min_height,
        max_height,
        sphere,
        horizon,
        u: it.next().unwrap(),
        v: it.next().unwrap(),
        h: it.next().unwrap(),
        triangles,
        edges,
        normals,
        metadata,
    }
}

/// An oct-encoded normal, decoded (the inverse of the specification's reference).
pub fn oct_decode(e: [u8; 2]) -> [f64; 3] {
    let f = |b: u8| f64::from(b) / 255.0 * 2.0 - 1.0;
    let (mut x, mut y) = (f(e[0]), f(e[1]));
    let z = 1.0 - x.abs() - y.abs();
    if z < 0.0 {
        let (ox, oy) = (x, y);
        x = (1.0 - oy.abs()) * ox.signum();
        y = (1.0 - ox.abs()) * oy.signum();
    }
    let l = (x * x + y * y + z * z).sqrt();
    [x / l, y / l, z / l]
}

impl Decoded {
    /// Vertex `k`'s height, as the specification says to read it.
    pub fn height(&self, k: usize) -> f64 {
        let (lo, hi) = (f64::from(self.min_height), f64::from(self.max_height));
        lo + f64::from(self.h[k]) / 32767.0 * (hi - lo)
    }
}

// Tiles of the global-geodetic pyramid, as a client on the globe reads them.

/// A tile's `[west, south, east, north]`.
pub fn bounds(z: u32, x: u32, y: u32) -> [f64; 4] {
    let d = 180.0 / f64::from(1u32 << z);
    let (w, s) = (-180.0 + f64::from(x) * d, -90.0 + f64::from(y) * d);
    [w, s, w + d, s + d]
}

/// A decoded tile with its address, and a search structure for its triangles.
pub struct Tile {
    pub z: u32,
    pub x: u32,
    pub y: u32,
    pub d: Decoded,
    /// 64 x 64 buckets over (u, v): the triangles meeting each.
    buckets: Vec<Vec<usize>>,
}

impl Tile {
    pub fn new(z: u32, x: u32, y: u32, d: Decoded) -> Tile {
        let mut buckets = vec![Vec::new(); 64 * 64];
        for (k, t) in d.triangles.iter().enumerate() {
            let us = t.map(|i| usize::from(d.u[i as usize]) * 64 / 32768);
            let vs = t.map(|i| usize::from(d.v[i as usize]) * 64 / 32768);
            for bv in *vs.iter().min().unwrap()..=*vs.iter().max().unwrap() {
                for bu in *us.iter().min().unwrap()..=*us.iter().max().unwrap() {
                    buckets[bv * 64 + bu].push(k);
                }
            }
        }
        Tile {
            z,
            x,
            y,
            d,
            buckets,
        }
    }

    pub fn bounds(&self) -> [f64; 4] {
        bounds(self.z, self.x, self.y)
    }

    /// The height the tile draws at `(lon, lat)`: barycentric over the triangle holding
    /// the point in `(u, v)`.
    pub fn height_at(&self, lon: f64, lat: f64) -> f64 {
        let [w, s, e, n] = self.bounds();
        let fu = ((lon - w) / (e - w) * 32767.0).clamp(0.0, 32767.0);
        let fv = ((lat - s) / (n - s) * 32767.0).clamp(0.0, 32767.0);
        let bu = ((fu as usize) * 64 / 32768).min(63);
        let bv = ((fv as usize) * 64 / 32768).min(63);
        let d = &self.d;
        for &k in &self.buckets[bv * 64 + bu] {
            let [a, b, c] = d.triangles[k].map(|i| i as usize);
            let p = |i: usize| (f64::from(d.u[i]), f64::from(d.v[i]));
            let ((x1, y1), (x2, y2), (x3, y3)) = (p(a), p(b), p(c));
            let det = (y2 - y3) * (x1 - x3) + (x3 - x2) * (y1 - y3);
            let l1 = ((y2 - y3) * (fu - x3) + (x3 - x2) * (fv - y3)) / det;
            let l2 = ((y3 - y1) * (fu - x3) + (x1 - x3) * (fv - y3)) / det;
            let l3 = 1.0 - l1 - l2;
            let eps = -1e-9;
            if l1 >= eps && l2 >= eps && l3 >= eps {
                return l1 * d.height(a) + l2 * d.height(b) + l3 * d.height(c);
            }
        }
        panic!(
            "({lon}, {lat}) is in no triangle of tile {}/{}/{}",
            self.z, self.x, self.y
        );
    }

    pub fn meta(&self) -> &serde_json::Value {
        &self.d.metadata.as_ref().expect("a metadata extension")["fmrh"]
    }
}

/// Every `.terrain` under `dir`, decoded, by address.
pub fn read_tiles(dir: &Path) -> BTreeMap<(u32, u32, u32), Tile> {
    let mut out = BTreeMap::new();
    for z in std::fs::read_dir(dir).unwrap() {
        let z = z.unwrap();
        let Ok(zl) = z.file_name().to_string_lossy().parse::<u32>() else {
            continue;
        };
        for x in std::fs::read_dir(z.path()).unwrap() {
            let x = x.unwrap();
            let xl: u32 = x.file_name().to_string_lossy().parse().unwrap();
            for y in std::fs::read_dir(x.path()).unwrap() {
                let y = y.unwrap();
                let name = y.file_name().to_string_lossy().into_owned();
                let yl: u32 = name.strip_suffix(".terrain").unwrap().parse().unwrap();
                let mut bytes = std::fs::read(y.path()).unwrap();
                // A gzipped tile (`--gzip`), as a server with Content-Encoding would send it.
                if bytes.starts_with(&[0x1f, 0x8b]) {
                    use std::io::Read;
                    let mut plain = Vec::new();
                    flate2::read::GzDecoder::new(&bytes[..])
                        .read_to_end(&mut plain)
                        .unwrap();
                    bytes = plain;
                }
                out.insert((zl, xl, yl), Tile::new(zl, xl, yl, decode(&bytes)));
            }
        }
    }
    out
}

/// The tiles an `available` array (one entry per level) names.
pub fn listed(available: &serde_json::Value, first_level: u32) -> BTreeSet<(u32, u32, u32)> {
    let mut out = BTreeSet::new();
    for (k, ranges) in available.as_array().unwrap().iter().enumerate() {
        for r in ranges.as_array().unwrap() {
            let g = |key: &str| r[key].as_u64().unwrap() as u32;
            for y in g("startY")..=g("endY") {
                for x in g("startX")..=g("endX") {
                    out.insert((first_level + k as u32, x, y));
                }
            }
        }
    }
    out
}

/// The source: longitude, latitude and height of every valid sample.
pub struct Source {
    pub width: u32,
    pub height: u32,
    pub lon_lat: Vec<[f64; 2]>,
    pub samples: Vec<f32>,
}

impl Source {
    /// Two fields side by side, the second's first column on the first's last (a
    /// dataset's grid), placed by the first's georeference.
    pub fn beside(a: &Heightfield, b: &Heightfield) -> Source {
        assert_eq!(a.height(), b.height());
        let (w, h) = (a.width() + b.width() - 1, a.height());
        let mut samples = Vec::with_capacity((w * h) as usize);
        for r in 0..h as usize {
            let row = |f: &Heightfield| {
                let fw = f.width() as usize;
                f.samples()[r * fw..(r + 1) * fw].to_vec()
            };
            samples.extend(row(a));
            samples.extend(&row(b)[1..]);
        }
        let field = Heightfield::new(w, h, samples)
            .unwrap()
            .with_metadata(a.metadata.clone());
        Source::of(&field)
    }

    pub fn of(field: &Heightfield) -> Source {
        let g = field.metadata.georeference.clone().expect("a georeference");
        let crs = fmrh::crs::Crs::parse(g.crs.as_deref().unwrap()).expect("a known CRS");
        let (w, h) = (field.width(), field.height());
        let points: Vec<[f64; 2]> = (0..h)
            .flat_map(|r| (0..w).map(move |c| (c, r)))
            .map(|(c, r)| {
                [
                    g.origin[0] + f64::from(c) * g.step[0],
                    g.origin[1] + f64::from(r) * g.step[1],
                ]
            })
            .collect();
        Source {
            width: w,
            height: h,
            lon_lat: crs.to_lon_lat_all(&points).expect("placeable"),
            samples: field.samples().to_vec(),
        }
    }
}

// The WGS 84 formulas a client on the globe uses, written here from the textbook and
// Cesium's "Horizon culling" article (Ring, 2013), sharing no code with fmrh's.

pub const A: f64 = 6_378_137.0;
pub const B: f64 = 6_356_752.314_245_179;

/// ECEF of a longitude, latitude (degrees) and height, on WGS 84.
pub fn ecef(lon: f64, lat: f64, h: f64) -> [f64; 3] {
    let e2 = 1.0 - B * B / (A * A);
    let (l, p) = (lon.to_radians(), lat.to_radians());
    let n = A / (1.0 - e2 * p.sin() * p.sin()).sqrt();
    [
        (n + h) * p.cos() * l.cos(),
        (n + h) * p.cos() * l.sin(),
        (n * (1.0 - e2) + h) * p.sin(),
    ]
}

/// Cesium's `isScaledSpacePointVisible`, from the "Horizon culling" article.
pub fn visible(camera: [f64; 3], p: [f64; 3]) -> bool {
    let dot = |a: [f64; 3], b: [f64; 3]| a[0] * b[0] + a[1] * b[1] + a[2] * b[2];
    let vh2 = dot(camera, camera) - 1.0;
    let vt = [p[0] - camera[0], p[1] - camera[1], p[2] - camera[2]];
    let vt_dot_vc = -dot(vt, camera);
    !(vt_dot_vc > vh2 && vt_dot_vc * vt_dot_vc / dot(vt, vt) > vh2)
}

pub fn scaled(p: [f64; 3]) -> [f64; 3] {
    [p[0] / A, p[1] / A, p[2] / B]
}
