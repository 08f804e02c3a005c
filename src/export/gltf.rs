//! Block meshes as one glTF 2.0 binary (`.glb`): one node and one mesh per block, for any
//! glTF viewer or engine.
//!
//! **Axes.** glTF is right-handed with +Y up; fmrh's world frame has x east, y south and z
//! up. A point `(x, y, z)` of the world frame is the glTF point `(x - ox, z, y - oy)`: X
//! east, Y up, Z south, in metres from the origin `(ox, oy)` the caller chooses (the
//! north-west corner of what it meshes, so that single-precision positions keep
//! centimetres), heights as they are. The origin goes into the scene's `extras`. On the
//! globe ([`GltfFrame::Globe`]) the axes are the same at the origin, a point on WGS 84: X
//! east, Y up, Z south of its local east-north-up frame, ECEF positions taken from it.
//!
//! **Layout.** One buffer (the GLB's binary chunk) holds two buffer views: the vertex
//! attributes of every block (positions then normals, three f32 each, block after block),
//! and the triangle indices (u16 where a block has fewer than 65,535 vertices, else u32,
//! each block's run padded to four bytes). Every block's mesh has one triangle primitive
//! with `POSITION` (with the exact min and max glTF asks for) and `NORMAL`, and a material
//! per level, in the level's hue ([`crate::render::level_colour`]). The node of a block
//! carries the caller's `extras` (fmrh puts the level, error, key and footprint there).

use serde_json::{json, Value};

use crate::error::{Error, Result};
use crate::mesh::BlockMesh;
use glam::DVec3;

use crate::scene::{GlobeFrame, WorldFrame};

/// A block's mesh and what its node says of it.
pub struct GltfBlock<'a> {
    /// The mesh.
    pub mesh: &'a BlockMesh,
    /// The node's name.
    pub name: String,
    /// The block's level (its material).
    pub level: u8,
    /// The node's `extras`.
    pub extras: Value,
}

const ARRAY_BUFFER: u32 = 34962;
const ELEMENT_ARRAY_BUFFER: u32 = 34963;
const FLOAT: u32 = 5126;
const UNSIGNED_SHORT: u32 = 5123;
const UNSIGNED_INT: u32 = 5125;
const TRIANGLES: u32 = 4;
/// `glTF` in ASCII, little-endian.
const GLB_MAGIC: u32 = 0x4654_6C67;
const CHUNK_JSON: u32 = 0x4E4F_534A;
const CHUNK_BIN: u32 = 0x004E_4942;

/// An sRGB channel as the linear value glTF's colour factors take.
fn linear(c: u8) -> f64 {
    let c = f64::from(c) / 255.0;
    if c <= 0.04045 {
        c / 12.92
    } else {
        ((c + 0.055) / 1.055).powf(2.4)
    }
}

/// Where a GLB's vertices are: the flat world frame from an origin (see the module doc), or
/// the WGS 84 ellipsoid in a local east-north-up frame.
#[derive(Clone, Copy, Debug)]
pub enum GltfFrame {
    /// `frame`'s `(x, y, z)` as `(x - ox, z, y - oy)`.
    Flat {
        /// The samples' world frame.
        frame: WorldFrame,
        /// `[ox, oy]`, world metres.
        origin: [f64; 2],
    },
    /// `frame`'s ECEF point `p` as `(east, up, south)`: `p - origin` along the east, up and
    /// minus north axes of the origin (its longitude and latitude, height 0). Still X east,
    /// Y up and Z south at the origin; away from it the Earth curves down.
    Globe {
        /// The samples on the globe.
        frame: GlobeFrame,
        /// Longitude and latitude of the origin, degrees.
        lon: f64,
        /// Latitude of the origin, degrees.
        lat: f64,
    },
}

/// A globe frame's origin (ECEF) and its east, up and south axes, found once per GLB.
type Local = (DVec3, [DVec3; 3]);

impl GltfFrame {
    fn local(&self) -> Local {
        match *self {
            GltfFrame::Flat { .. } => (DVec3::ZERO, [DVec3::X, DVec3::Y, DVec3::Z]),
            GltfFrame::Globe { lon, lat, .. } => {
                let [east, north, up] = crate::globe::enu(lon, lat);
                (crate::globe::ecef_point(lon, lat, 0.0), [east, up, -north])
            }
        }
    }

    /// Mesh vertex `(col, row, height)` in glTF metres.
    fn position(&self, (origin, axes): &Local, col: f64, row: f64, h: f64) -> [f64; 3] {
        match self {
            GltfFrame::Flat { frame, origin } => {
                let p = frame.point(col, row, h);
                [p.x - origin[0], p.z, p.y - origin[1]]
            }
            GltfFrame::Globe { frame, .. } => {
                let d = frame.point(col, row, h) - *origin;
                [d.dot(axes[0]), d.dot(axes[1]), d.dot(axes[2])]
            }
        }
    }

    /// A world normal in glTF axes.
    fn normal(&self, (_, axes): &Local, n: [f64; 3]) -> [f64; 3] {
        match self {
            GltfFrame::Flat { .. } => [n[0], n[2], n[1]],
            GltfFrame::Globe { .. } => {
                let n = DVec3::from(n);
                [n.dot(axes[0]), n.dot(axes[1]), n.dot(axes[2])]
            }
        }
    }
}

/// The GLB of `blocks` in `frame`, positions from `origin` (world metres, `[x, y]`), with
/// `scene_extras` on the scene. Blocks without triangles are left out; there must be one
/// with.
#[cfg(any(test, feature = "testing"))]
pub fn glb(
    blocks: &[GltfBlock<'_>],
    frame: &WorldFrame,
    origin: [f64; 2],
    scene_extras: Value,
) -> Result<Vec<u8>> {
    glb_in(
        blocks,
        &GltfFrame::Flat {
            frame: *frame,
            origin,
        },
        scene_extras,
    )
}

/// [`glb`] with the vertices placed by `frame`, flat or on the globe.
pub fn glb_in(blocks: &[GltfBlock<'_>], frame: &GltfFrame, scene_extras: Value) -> Result<Vec<u8>> {
    let local = frame.local();
    let blocks: Vec<&GltfBlock<'_>> = blocks
        .iter()
        .filter(|b| !b.mesh.triangles.is_empty())
        .collect();
    if blocks.is_empty() {
        return Err(Error::InvalidArgument(
            "nothing to mesh: no block has an area".into(),
        ));
    }
    let mut levels: Vec<u8> = blocks.iter().map(|b| b.level).collect();
    levels.sort_unstable();
    levels.dedup();
    let materials: Vec<Value> = levels
        .iter()
        .map(|&l| {
            let [r, g, b] = crate::render::level_colour(l);
            json!({
                "name": format!("level {l}"),
                "pbrMetallicRoughness": {
                    "baseColorFactor": [linear(r), linear(g), linear(b), 1.0],
                    "metallicFactor": 0.0,
                    "roughnessFactor": 1.0
                }
            })
        })
        .collect();

    let mut attributes: Vec<u8> = Vec::new();
    let mut indices: Vec<u8> = Vec::new();
    let mut accessors = Vec::new();
    let mut meshes = Vec::new();
    let mut nodes = Vec::new();
    for (k, b) in blocks.iter().enumerate() {
        let m = b.mesh;
        if m.normals.len() != m.vertices.len() {
            return Err(Error::InvalidArgument(format!(
                "block {}: {} normals for {} vertices",
                m.block,
                m.normals.len(),
                m.vertices.len()
            )));
        }
        let positions: Vec<[f32; 3]> = m
            .vertices
            .iter()
            .map(|v| {
                frame
                    .position(&local, v.col as f64, v.row as f64, v.height)
                    .map(|c| c as f32)
            })
            .collect();
        let mut min = [f32::INFINITY; 3];
        let mut max = [f32::NEG_INFINITY; 3];
        for p in &positions {
            for a in 0..3 {
                min[a] = min[a].min(p[a]);
                max[a] = max[a].max(p[a]);
            }
        }
        let position_offset = attributes.len();
        for p in &positions {
            for c in p {
                attributes.extend_from_slice(&c.to_le_bytes());
            }
        }
        let normal_offset = attributes.len();
        for n in &m.normals {
            let v = glam::Vec3::from(frame.normal(&local, *n).map(|c| c as f32));
            let v = v.try_normalize().unwrap_or(glam::Vec3::Y);
            for c in v.to_array() {
                attributes.extend_from_slice(&c.to_le_bytes());
            }
        }
        let wide = m.vertices.len() >= usize::from(u16::MAX);
        let index_offset = indices.len();
        for t in &m.triangles {
            for &i in t {
                if wide {
                    indices.extend_from_slice(&i.to_le_bytes());
                } else {
                    indices.extend_from_slice(&(i as u16).to_le_bytes());
                }
            }
        }
        while !indices.len().is_multiple_of(4) {
            indices.push(0);
        }
        let a = accessors.len();
        accessors.push(json!({
            "bufferView": 0, "byteOffset": position_offset, "componentType": FLOAT,
            "count": positions.len(), "type": "VEC3", "min": min, "max": max
        }));
        accessors.push(json!({
            "bufferView": 0, "byteOffset": normal_offset, "componentType": FLOAT,
            "count": positions.len(), "type": "VEC3"
        }));
        accessors.push(json!({
            "bufferView": 1, "byteOffset": index_offset,
            "componentType": if wide { UNSIGNED_INT } else { UNSIGNED_SHORT },
            "count": 3 * m.triangles.len(), "type": "SCALAR"
        }));
        let material = levels.partition_point(|&l| l < b.level);
        meshes.push(json!({
            "primitives": [{
                "attributes": { "POSITION": a, "NORMAL": a + 1 },
                "indices": a + 2,
                "material": material,
                "mode": TRIANGLES
            }]
        }));
        nodes.push(json!({ "mesh": k, "name": b.name, "extras": b.extras }));
    }
    let bin_len = attributes.len() + indices.len();
    let doc = json!({
        "asset": {
            "version": "2.0",
            "generator": concat!("fmrh ", env!("CARGO_PKG_VERSION"))
        },
        "scene": 0,
        "scenes": [{ "nodes": (0..nodes.len()).collect::<Vec<_>>(), "extras": scene_extras }],
        "nodes": nodes,
        "meshes": meshes,
        "materials": materials,
        "accessors": accessors,
        "bufferViews": [
            { "buffer": 0, "byteOffset": 0, "byteLength": attributes.len(), "byteStride": 12,
              "target": ARRAY_BUFFER },
            { "buffer": 0, "byteOffset": attributes.len(), "byteLength": indices.len(),
              "target": ELEMENT_ARRAY_BUFFER }
        ],
        "buffers": [{ "byteLength": bin_len }]
    });
    let mut json =
        serde_json::to_vec(&doc).map_err(|e| Error::InvalidArgument(format!("glTF JSON: {e}")))?;
    while !json.len().is_multiple_of(4) {
        json.push(b' ');
    }
    let total = 12 + 8 + json.len() + 8 + bin_len;
    let total = u32::try_from(total).map_err(|_| {
        Error::InvalidArgument(format!(
            "the mesh needs {total} bytes, past a GLB's 4 GiB; mesh a smaller window"
        ))
    })?;
    let mut out = Vec::with_capacity(total as usize);
    out.extend_from_slice(&GLB_MAGIC.to_le_bytes());
    out.extend_from_slice(&2u32.to_le_bytes());
    out.extend_from_slice(&total.to_le_bytes());
    out.extend_from_slice(&(json.len() as u32).to_le_bytes());
    out.extend_from_slice(&CHUNK_JSON.to_le_bytes());
    out.extend_from_slice(&json);
    out.extend_from_slice(&(bin_len as u32).to_le_bytes());
    out.extend_from_slice(&CHUNK_BIN.to_le_bytes());
    out.extend_from_slice(&attributes);
    out.extend_from_slice(&indices);
    Ok(out)
}

/// A GLB (as [`glb_in`] writes it) as glTF JSON with its binary buffer apart: the JSON's one
/// buffer gets `uri = bin_uri` (the `.bin` file beside it, a relative URI), the bytes are the
/// GLB's binary chunk. The two are the same asset as the GLB, for tools that want text.
pub fn gltf_from_glb(glb: &[u8], bin_uri: &str) -> Result<(Vec<u8>, Vec<u8>)> {
    let bad = |what: &str| Error::InvalidArgument(format!("glTF: {what}"));
    let word = |at: usize| -> Result<usize> {
        glb.get(at..at + 4)
            .map(|b| u32::from_le_bytes([b[0], b[1], b[2], b[3]]) as usize)
            .ok_or_else(|| bad("a truncated GLB"))
    };
    if word(0)? != GLB_MAGIC as usize || word(12 + 4)? != CHUNK_JSON as usize {
        return Err(bad("not a GLB"));
    }
    let json_len = word(12)?;
    let json = glb
        .get(20..20 + json_len)
        .ok_or_else(|| bad("a truncated JSON chunk"))?;
    let bin_at = 20 + json_len;
    let bin_len = word(bin_at)?;
    if word(bin_at + 4)? != CHUNK_BIN as usize {
        return Err(bad("no binary chunk"));
    }
    let bin = glb
        .get(bin_at + 8..bin_at + 8 + bin_len)
        .ok_or_else(|| bad("a truncated binary chunk"))?;
    let mut doc: Value =
        serde_json::from_slice(json).map_err(|e| bad(&format!("its JSON: {e}")))?;
    doc["buffers"][0]["uri"] = Value::String(bin_uri.to_string());
    let mut text =
        serde_json::to_vec_pretty(&doc).map_err(|e| bad(&format!("its JSON: {e}")))?;
    text.push(b'\n');
    Ok((text, bin.to_vec()))
}
