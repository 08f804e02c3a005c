//! Heightfields and meshes out of fmrh in formats other tools read: GeoTIFF ([`geotiff`]) and
//! glTF ([`gltf`]). The readers of rasters live in [`crate::ingest`]; nothing here knows of
//! containers or scenes: a caller hands over samples and their georeference, or meshes.

pub mod geotiff;
pub mod gltf;
