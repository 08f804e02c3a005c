//! CesiumJS's own reading of a quantized-mesh tileset (`tests/js/cesium-sample.mjs`, run on
//! Node.js with `@cesium/engine`): a directory of tiles, or a layer served over HTTP; and
//! the check of what Cesium sampled from a served layer against the source and the tiles.

use std::path::Path;
use std::process::Command;

use super::quantized_mesh::{decode, Source, Tile};
use super::serve::Served;

/// `n` random valid samples of `source` (`[lon, lat]`), and the height Cesium should draw
/// at each: the stored height lifted onto the ellipsoid by the EGM96 geoid (SRTM heights
/// are above the geoid; served, above the ellipsoid: `h = H + N`).
pub fn random_points(source: &Source, n: usize, seed: u64) -> (Vec<[f64; 2]>, Vec<f64>) {
    let mut rng = super::fields::Rng::new(seed);
    let (mut points, mut want) = (Vec::new(), Vec::new());
    while points.len() < n {
        let k = (rng.next_u64() % source.samples.len() as u64) as usize;
        if !source.samples[k].is_nan() {
            let [lon, lat] = source.lon_lat[k];
            points.push([lon, lat]);
            want.push(f64::from(source.samples[k]) + fmrh::geoid::egm96_undulation(lat, lon));
        }
    }
    (points, want)
}

/// The tile of level `z` holding `(lon, lat)`, decoded, from the server.
pub fn tile_at(served: &Served, name: &str, z: u32, lon: f64, lat: f64) -> Tile {
    let d = 180.0 / f64::from(1u32 << z);
    let x = ((lon + 180.0) / d).floor() as u32;
    let y = ((lat + 90.0) / d).floor() as u32;
    let a = served.ask(
        "GET",
        &format!("/{name}/{z}/{x}/{y}.terrain"),
        &[(
            "Accept",
            "application/vnd.quantized-mesh;extensions=octvertexnormals-metadata",
        )],
    );
    assert_eq!(a.status, 200, "{}", String::from_utf8_lossy(&a.body));
    Tile::new(z, x, y, decode(&a.body))
}

/// Checks what Cesium sampled from served layer `name` at `points` (`heights`, from tiles
/// of `levels`): every point from the layer's deepest level `maxzoom`, the height the
/// served tile draws there to a millimetre, and within that tile's declared (measured)
/// error of `want`. Returns the largest `|Cesium - want|`.
pub fn check_samples(
    served: &Served,
    name: &str,
    maxzoom: u32,
    points: &[[f64; 2]],
    want: &[f64],
    (heights, levels): (&[f64], &[u32]),
) -> f64 {
    let mut worst = 0.0f64;
    for (i, &[lon, lat]) in points.iter().enumerate() {
        assert_eq!(levels[i], maxzoom, "{name}: Cesium's level at {lon},{lat}");
        let tile = tile_at(served, name, maxzoom, lon, lat);
        let error = tile.meta()["error"].as_f64().unwrap();
        let ours = tile.height_at(lon, lat);
        assert!(
            (heights[i] - ours).abs() <= 1e-3,
            "{name}: at {lon},{lat} Cesium draws {} where the tile draws {ours}",
            heights[i]
        );
        assert!(
            (heights[i] - want[i]).abs() <= error + 1e-3,
            "{name}: at {lon},{lat} Cesium draws {} where the source has {} (declared error {error})",
            heights[i],
            want[i]
        );
        worst = worst.max((heights[i] - want[i]).abs());
    }
    worst
}

/// The heights `sampleTerrainMostDetailed` gives at `points` (`[lon, lat]` degrees) from
/// the tileset at `tileset` (a directory, or the URL of a layer's directory), and the level
/// it took each from; `scratch` holds the points file.
pub fn samples(tileset: &str, scratch: &Path, points: &[[f64; 2]]) -> (Vec<f64>, Vec<u32>) {
    let js = Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/js");
    assert!(
        js.join("node_modules/@cesium/engine").is_dir(),
        "CesiumJS is not installed: run `npm ci --prefix tests/js` (.ci/run does)"
    );
    let file = scratch.join("points.json");
    std::fs::write(&file, serde_json::to_vec(points).unwrap()).unwrap();
    let out = Command::new("node")
        .arg(js.join("cesium-sample.mjs"))
        .arg(tileset)
        .arg(&file)
        .output()
        .expect("node runs (Node.js is needed for CesiumJS)");
    assert!(
        out.status.success(),
        "cesium-sample.mjs: {}",
        String::from_utf8_lossy(&out.stderr)
    );
    let report: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
    assert_eq!(report["hasVertexNormals"], true);
    assert_eq!(report["hasMetadata"], true);
    let heights = report["heights"]
        .as_array()
        .unwrap()
        .iter()
        .map(|h| h.as_f64().expect("Cesium gave a height at every point"))
        .collect();
    let levels = report["levels"]
        .as_array()
        .unwrap()
        .iter()
        .map(|l| l.as_u64().unwrap() as u32)
        .collect();
    (heights, levels)
}
