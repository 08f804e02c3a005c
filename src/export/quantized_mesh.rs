//! Block meshes as Cesium quantized-mesh-1.0 tiles (`.terrain`), each with oct-encoded
//! vertex normals and a metadata extension, for the tileset's `layer.json`.
//!
//! The format (github.com/CesiumGS/quantized-mesh): a little-endian header of 88 bytes
//! (tile centre, height range, bounding sphere, horizon occlusion point), then the vertex
//! count and three arrays of u16 (`u` west to east and `v` south to north in `0..=32767`
//! across the tile, heights in `0..=32767` across the header's range), each delta- and
//! zig-zag-coded; padding to the index size; the triangle count and the indices (u16 up to
//! 65,536 vertices, else u32) in *high-water-mark* code, which numbers vertices in the order
//! the triangles first use them; then the vertices on the west, south, east and north edges;
//! then extensions, each an id byte and a u32 length: 1, `octvertexnormals` (two bytes a
//! vertex), and 4, `metadata` (a u32 length and JSON).
//!
//! **Frames.** [`write()`] takes a tile whose header is already in its frame: Earth-centred
//! (ECEF, WGS 84) for the global-geodetic tiles of [`super::geodetic_mesh`], which Cesium
//! places on the globe as they are. [`encode`] writes a block's mesh in fmrh's node tiling:
//! the tile's rectangle is given in the world frame (metres, x east, y south), and so are the
//! header's points, as `(x, -y, z)`: x east, y north, z up, a local Cartesian frame and not
//! Earth-centred. Normals are oct-encoded in the same axes. The header's "horizon occlusion
//! point" is then the bounding sphere's centre: a local frame has no horizon. A client that
//! places such tiles on the globe must place this frame itself (the layer's `fmrh` object says
//! where its origin is on the map, when the source said).

use crate::error::{Error, Result};
use crate::mesh::BlockMesh;
use crate::scene::WorldFrame;

/// Extension id of oct-encoded per-vertex normals.
pub const EXT_OCT_NORMALS: u8 = 1;
/// Extension id of per-tile JSON metadata.
pub const EXT_METADATA: u8 = 4;
/// The largest quantized coordinate.
pub const QUANTIZED_MAX: u16 = 32767;

/// Zig-zag code of a signed delta: small magnitudes give small codes.
fn zigzag(v: i32) -> u16 {
    ((v << 1) ^ (v >> 31)) as u16
}

/// The unit vector `n` in oct encoding, two bytes (Cigolle et al. 2014, as CesiumJS's
/// `AttributeCompression.octEncode` with a range of 255).
pub fn oct_encode(n: [f64; 3]) -> [u8; 2] {
    let l1 = n[0].abs() + n[1].abs() + n[2].abs();
    let (mut x, mut y) = if l1 > 0.0 {
        (n[0] / l1, n[1] / l1)
    } else {
        (0.0, 0.0)
    };
    if n[2] < 0.0 {
        let sign = |v: f64| if v >= 0.0 { 1.0 } else { -1.0 };
        let (ox, oy) = (x, y);
        x = (1.0 - oy.abs()) * sign(ox);
        y = (1.0 - ox.abs()) * sign(oy);
    }
    let unorm = |v: f64| ((v.clamp(-1.0, 1.0) * 0.5 + 0.5) * 255.0).round() as u8;
    [unorm(x), unorm(y)]
}

/// A tile's header: where it is and how big, in the frame its points are given in.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Header {
    /// The tile's centre.
    pub centre: [f64; 3],
    /// The height range the vertices' heights are quantized over.
    pub min_height: f32,
    /// Its top.
    pub max_height: f32,
    /// A sphere holding every vertex: centre and radius.
    pub sphere_centre: [f64; 3],
    /// Its radius, metres.
    pub sphere_radius: f64,
    /// The horizon occlusion point (ellipsoid-scaled frame; see [`super::geodetic`]).
    pub horizon: [f64; 3],
}

/// A tile ready to write: quantized vertices and the triangles over them.
#[derive(Clone, Debug, PartialEq)]
pub struct TileData {
    /// The header; `min_height` and `max_height` are the range `h` is quantized over.
    pub header: Header,
    /// West to east across the tile, `0..=QUANTIZED_MAX`.
    pub u: Vec<u16>,
    /// South to north, `0..=QUANTIZED_MAX`.
    pub v: Vec<u16>,
    /// Heights, `0..=QUANTIZED_MAX` across the header's range ([`quantize_heights`]).
    pub h: Vec<u16>,
    /// Triangles, counter-clockwise seen from above, over any numbering of the vertices: the
    /// tile is written with its vertices renumbered in the order the triangles first use
    /// them, and vertices no triangle uses are left out.
    pub triangles: Vec<[u32; 3]>,
    /// Oct-encoded unit normals ([`oct_encode`]), one per vertex, when known.
    pub normals: Option<Vec<[u8; 2]>>,
    /// The metadata extension's JSON.
    pub metadata: serde_json::Value,
}

/// The range `[lo, hi]` (binary32, as the header stores it) and quantized codes of
/// `heights`: `round((h - lo) / (hi - lo) * QUANTIZED_MAX)`, all 0 for a flat tile.
pub fn quantize_heights(heights: &[f64]) -> (f32, f32, Vec<u16>) {
    let lo = heights
        .iter()
        .map(|&h| h as f32)
        .fold(f32::INFINITY, f32::min);
    let hi = heights
        .iter()
        .map(|&h| h as f32)
        .fold(f32::NEG_INFINITY, f32::max);
    let span = f64::from(hi) - f64::from(lo);
    let q = f64::from(QUANTIZED_MAX);
    let codes = heights
        .iter()
        .map(|&h| {
            if span > 0.0 {
                ((h - f64::from(lo)) / span * q).round().clamp(0.0, q) as u16
            } else {
                0
            }
        })
        .collect();
    (lo, hi, codes)
}

/// The height code `h` stands for over `[lo, hi]`, as a decoder reads it.
pub fn dequantize_height(lo: f32, hi: f32, h: u16) -> f64 {
    f64::from(lo) + f64::from(h) / f64::from(QUANTIZED_MAX) * (f64::from(hi) - f64::from(lo))
}

/// The `.terrain` bytes of `tile`.
pub fn write(tile: &TileData) -> Result<Vec<u8>> {
    let count = tile.u.len();
    if tile.v.len() != count
        || tile.h.len() != count
        || tile.normals.as_ref().is_some_and(|n| n.len() != count)
        || tile
            .triangles
            .iter()
            .flatten()
            .any(|&i| i as usize >= count)
    {
        return Err(Error::Internal(format!(
            "quantized-mesh tile: {count} vertices, {} v, {} h, triangles past them",
            tile.v.len(),
            tile.h.len()
        )));
    }
    if tile.triangles.is_empty() {
        return Err(Error::InvalidArgument("a tile with no triangle".into()));
    }
    // Number the vertices in the order the triangles first use them (the index code needs
    // it).
    let mut order: Vec<u32> = Vec::new();
    let mut new_index = vec![u32::MAX; count];
    let mut triangles: Vec<[u32; 3]> = Vec::with_capacity(tile.triangles.len());
    for t in &tile.triangles {
        let mut out = [0u32; 3];
        for (k, &i) in t.iter().enumerate() {
            if new_index[i as usize] == u32::MAX {
                new_index[i as usize] = order.len() as u32;
                order.push(i);
            }
            out[k] = new_index[i as usize];
        }
        triangles.push(out);
    }
    let pick = |values: &[u16]| -> Vec<i32> {
        order
            .iter()
            .map(|&i| i32::from(values[i as usize]))
            .collect()
    };
    let (u, v, h) = (pick(&tile.u), pick(&tile.v), pick(&tile.h));

    let mut out = Vec::new();
    let put_f64 = |out: &mut Vec<u8>, x: f64| out.extend_from_slice(&x.to_le_bytes());
    let hd = &tile.header;
    for c in hd.centre {
        put_f64(&mut out, c);
    }
    out.extend_from_slice(&hd.min_height.to_le_bytes());
    out.extend_from_slice(&hd.max_height.to_le_bytes());
    for c in hd.sphere_centre {
        put_f64(&mut out, c);
    }
    put_f64(&mut out, hd.sphere_radius);
    for c in hd.horizon {
        put_f64(&mut out, c);
    }
    // Vertex data.
    let n = order.len();
    out.extend_from_slice(&(n as u32).to_le_bytes());
    for values in [&u, &v, &h] {
        let mut prev = 0;
        for &x in values.iter() {
            out.extend_from_slice(&zigzag(x - prev).to_le_bytes());
            prev = x;
        }
    }
    // Index data, high-water-mark coded.
    let wide = n > 65536;
    let size = if wide { 4 } else { 2 };
    while !out.len().is_multiple_of(size) {
        out.push(0);
    }
    let put_index = |out: &mut Vec<u8>, i: u32| {
        if wide {
            out.extend_from_slice(&i.to_le_bytes());
        } else {
            out.extend_from_slice(&(i as u16).to_le_bytes());
        }
    };
    out.extend_from_slice(&(triangles.len() as u32).to_le_bytes());
    let mut highest = 0u32;
    for &i in triangles.iter().flatten() {
        put_index(&mut out, highest - i);
        if i == highest {
            highest += 1;
        }
    }
    // Edge vertices: west and east by v, south and north by u.
    // Each edge: which quantized coordinate is fixed, at what value, and the one along it.
    let q = i32::from(QUANTIZED_MAX);
    for (fixed, at, along) in [(&u, 0, &v), (&v, 0, &u), (&u, q, &v), (&v, q, &u)] {
        let mut list: Vec<usize> = (0..n).filter(|&k| fixed[k] == at).collect();
        list.sort_by_key(|&k| along[k]);
        out.extend_from_slice(&(list.len() as u32).to_le_bytes());
        for k in list {
            put_index(&mut out, k as u32);
        }
    }
    // Extensions.
    if let Some(normals) = &tile.normals {
        out.push(EXT_OCT_NORMALS);
        out.extend_from_slice(&(2 * n as u32).to_le_bytes());
        for &i in &order {
            out.extend_from_slice(&normals[i as usize]);
        }
    }
    // No metadata (`null`): no extension, for a client that did not ask for it.
    if !tile.metadata.is_null() {
        let json = serde_json::to_vec(&tile.metadata)
            .map_err(|e| Error::InvalidArgument(format!("tile metadata: {e}")))?;
        out.push(EXT_METADATA);
        out.extend_from_slice(&(4 + json.len() as u32).to_le_bytes());
        out.extend_from_slice(&(json.len() as u32).to_le_bytes());
        out.extend_from_slice(&json);
    }
    Ok(out)
}

/// One tile: a block's mesh over its rectangle (samples, the node's whole footprint, which
/// may reach past the data), with the JSON of its metadata extension.
pub struct QuantizedTile<'a> {
    /// The mesh (skirt vertices are left out: clients hang their own from the edge lists).
    pub mesh: &'a BlockMesh,
    /// West, north, east and south edges of the tile, in samples: `[col0, row0, col1, row1]`.
    pub rect: [u64; 4],
    /// The metadata extension's JSON.
    pub metadata: serde_json::Value,
}

/// The `.terrain` bytes of `tile` in `frame` (a local frame: see the module's notes).
pub fn encode(tile: &QuantizedTile<'_>, frame: &WorldFrame) -> Result<Vec<u8>> {
    let m = tile.mesh;
    let [c0, r0, c1, r1] = tile.rect;
    if c0 >= c1 || r0 >= r1 {
        return Err(Error::InvalidArgument(format!(
            "tile rectangle {c0},{r0},{c1},{r1} has no area"
        )));
    }
    // Skirts are dropped, with their triangles.
    let triangles: Vec<[u32; 3]> = m
        .triangles
        .iter()
        .filter(|t| t.iter().all(|&i| !m.vertices[i as usize].skirt))
        .copied()
        .collect();
    if triangles.is_empty() {
        return Err(Error::InvalidArgument(format!(
            "block {}: no triangle to write",
            m.block
        )));
    }
    let heights: Vec<f64> = m
        .vertices
        .iter()
        .map(|p| if p.skirt { f64::NAN } else { p.height })
        .collect();
    let surface: Vec<f64> = heights.iter().copied().filter(|h| !h.is_nan()).collect();
    let (lo, hi, _) = quantize_heights(&surface);
    let span = f64::from(hi) - f64::from(lo);
    let q = f64::from(QUANTIZED_MAX);
    let quantize = |t: f64| (t * q).round().clamp(0.0, q) as i32;
    // A position strictly inside the tile stays off its edges (a node 2^20 samples wide has
    // vertices 8 samples in), so that the edge lists are exactly the edge's vertices.
    let across = |t: u64, lo: u64, hi: u64| {
        let x = quantize((t - lo) as f64 / (hi - lo) as f64);
        if t == lo || t == hi {
            x
        } else {
            x.clamp(1, i32::from(QUANTIZED_MAX) - 1)
        }
    };
    let u: Vec<u16> = m
        .vertices
        .iter()
        .map(|p| across(p.col.clamp(c0, c1), c0, c1) as u16)
        .collect();
    let v: Vec<u16> = m
        .vertices
        .iter()
        .map(|p| (i32::from(QUANTIZED_MAX) - across(p.row.clamp(r0, r1), r0, r1)) as u16)
        .collect();
    let h: Vec<u16> = heights
        .iter()
        .map(|&z| {
            if span > 0.0 && !z.is_nan() {
                quantize((z - f64::from(lo)) / span) as u16
            } else {
                0
            }
        })
        .collect();
    // The header, in the local frame (x east, y north, z up).
    let corner = |col: u64, row: u64, z: f64| {
        let p = frame.point(col as f64, row as f64, z);
        [p.x, -p.y, p.z]
    };
    let (zl, zh) = (f64::from(lo), f64::from(hi));
    let a = corner(c0, r1, zl);
    let b = corner(c1, r0, zh);
    let centre = [
        (a[0] + b[0]) / 2.0,
        (a[1] + b[1]) / 2.0,
        (a[2] + b[2]) / 2.0,
    ];
    let radius =
        ((b[0] - a[0]).powi(2) + (b[1] - a[1]).powi(2) + (b[2] - a[2]).powi(2)).sqrt() / 2.0;
    let normals = (m.normals.len() == m.vertices.len()).then(|| {
        m.normals
            .iter()
            .map(|&[e, s, up]| oct_encode([e, -s, up]))
            .collect()
    });
    write(&TileData {
        header: Header {
            centre,
            min_height: lo,
            max_height: hi,
            sphere_centre: centre,
            sphere_radius: radius,
            horizon: centre,
        },
        u,
        v,
        h,
        triangles,
        normals,
        metadata: tile.metadata.clone(),
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn zigzag_codes_small_magnitudes_small() {
        assert_eq!([0, -1, 1, -2, 2].map(zigzag), [0, 1, 2, 3, 4],);
        assert_eq!(zigzag(32767), 65534);
        assert_eq!(zigzag(-32767), 65533);
    }

    /// A vertex 8 samples into a tile 2^20 samples wide rounds to `u = 0`, the west edge;
    /// it is kept off it, so the edge list holds only the edge's vertices.
    #[test]
    fn a_vertex_just_inside_a_huge_tile_stays_off_its_edge() {
        use crate::mesh::{BlockMesh, MeshVertex};
        let at = |col, row| MeshVertex {
            col,
            row,
            height: 1.0,
            skirt: false,
        };
        let side = 1u64 << 20;
        let mesh = BlockMesh {
            block: 0,
            vertices: vec![at(0, 0), at(8, 0), at(side, 0), at(0, side)],
            normals: vec![[0.0, 0.0, 1.0]; 4],
            triangles: vec![[0, 3, 1], [1, 3, 2]],
            stitched: [false; 4],
            skirts: [0.0; 4],
            tin_error: 0.0,
        };
        let tile = QuantizedTile {
            mesh: &mesh,
            rect: [0, 0, side, side],
            metadata: serde_json::json!({}),
        };
        let bytes = encode(&tile, &WorldFrame::new(None)).unwrap();
        // Vertices in order of first use: (0,0), (0,side), (8,0), (side,0); u deltas.
        let u: Vec<u16> = (0..4)
            .map(|k| u16::from_le_bytes([bytes[92 + 2 * k], bytes[93 + 2 * k]]))
            .collect();
        assert_eq!(u, [0, 0, zigzag(1), zigzag(32766)]);
        // West edge (after 3 u16 arrays, the triangle count and 6 indices): two vertices.
        let west = 92 + 3 * 8 + 4 + 12;
        assert_eq!(
            u32::from_le_bytes(bytes[west..west + 4].try_into().unwrap()),
            2
        );
    }

    #[test]
    fn oct_encoding_of_the_axes() {
        assert_eq!(oct_encode([0.0, 0.0, 1.0]), [128, 128]);
        assert_eq!(oct_encode([1.0, 0.0, 0.0]), [255, 128]);
        assert_eq!(oct_encode([0.0, -1.0, 0.0]), [128, 0]);
        // The lower hemisphere folds onto the corners.
        assert_eq!(oct_encode([0.0, 0.0, -1.0]), [255, 255]);
    }
}
