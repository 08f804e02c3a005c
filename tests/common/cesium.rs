//! CesiumJS's own reading of a quantized-mesh tileset (`tests/js/cesium-sample.mjs`, run on
//! Node.js with `@cesium/engine`): a directory of tiles, or a layer served over HTTP.

use std::path::Path;
use std::process::Command;

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
