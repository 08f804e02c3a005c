//! Heightfields and meshes out of fmrh in formats other tools read: GeoTIFF ([`geotiff`]),
//! glTF ([`gltf`]) and Cesium's quantized-mesh ([`quantized_mesh`]), with the geographic
//! tile pyramid Cesium's terrain is addressed by ([`geodetic`]). The readers of rasters
//! live in [`crate::ingest`]; nothing here knows of containers or scenes: a caller hands
//! over samples and their georeference, or meshes.

pub mod geodetic;
pub mod geodetic_mesh;
pub mod geotiff;
pub mod gltf;
pub mod quantized_mesh;
pub mod terrain_rgb;
pub mod tileset;
pub mod tin_tile;
