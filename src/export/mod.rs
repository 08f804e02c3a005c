//! Heightfields out of fmrh in formats other tools read: GeoTIFF ([`geotiff`]). The
//! readers of the same formats live in [`crate::ingest`]; nothing here knows of containers
//! or scenes: a caller hands over the samples and their georeference.

pub mod geotiff;
