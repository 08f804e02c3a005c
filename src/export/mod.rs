//! Heightfields and meshes out of fmrh in formats other tools read: GeoTIFF ([`geotiff`]),
//! glTF ([`gltf`]), Cesium's quantized-mesh ([`quantized_mesh`]) and terrain-RGB
//! ([`terrain_rgb`]), with the tile pyramids they are addressed by ([`geodetic`],
//! [`tileset`]), and PMTiles archives to keep a pyramid in ([`pmtiles`]). The readers of rasters
//! live in [`crate::ingest`]; nothing here knows of containers or scenes: a caller hands
//! over samples and their georeference, or meshes.

pub mod geodetic;
pub mod geodetic_mesh;
pub mod geotiff;
pub mod gltf;
pub mod pmtiles;
pub mod quantized_mesh;
pub mod terrain_rgb;
pub mod tileset;
pub mod tin_tile;
