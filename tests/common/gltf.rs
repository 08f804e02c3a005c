//! Reading back the GLB files `fmrh mesh` writes: the container's chunks and an accessor's
//! elements, checked as glTF 2.0 lays them out.

use serde_json::Value;

/// The JSON and binary chunks of a GLB, after checking its framing.
pub fn chunks(glb: &[u8]) -> (Value, Vec<u8>) {
    let word = |at: usize| u32::from_le_bytes(glb[at..at + 4].try_into().unwrap()) as usize;
    assert_eq!(&glb[0..4], b"glTF");
    assert_eq!(word(4), 2, "version");
    assert_eq!(word(8), glb.len(), "the header's length");
    let json_len = word(12);
    assert_eq!(&glb[16..20], b"JSON");
    assert_eq!(json_len % 4, 0);
    let json: Value = serde_json::from_slice(&glb[20..20 + json_len]).unwrap();
    let at = 20 + json_len;
    let bin_len = word(at);
    assert_eq!(&glb[at + 4..at + 8], b"BIN\0");
    assert_eq!(bin_len % 4, 0);
    assert_eq!(at + 8 + bin_len, glb.len());
    (json, glb[at + 8..].to_vec())
}

/// The `count` elements of accessor `a`, as f32 components (or integers, widened).
pub fn read_accessor(json: &Value, bin: &[u8], a: u64) -> Vec<f64> {
    let acc = &json["accessors"][a as usize];
    let view = &json["bufferViews"][acc["bufferView"].as_u64().unwrap() as usize];
    let start =
        (view["byteOffset"].as_u64().unwrap() + acc["byteOffset"].as_u64().unwrap()) as usize;
    let count = acc["count"].as_u64().unwrap() as usize;
    let comps = match acc["type"].as_str().unwrap() {
        "VEC3" => 3,
        "SCALAR" => 1,
        t => panic!("type {t}"),
    };
    let n = count * comps;
    let bytes = &bin[start..];
    match acc["componentType"].as_u64().unwrap() {
        5126 => (0..n)
            .map(|i| {
                f64::from(f32::from_le_bytes(
                    bytes[4 * i..4 * i + 4].try_into().unwrap(),
                ))
            })
            .collect(),
        5123 => (0..n)
            .map(|i| {
                f64::from(u16::from_le_bytes(
                    bytes[2 * i..2 * i + 2].try_into().unwrap(),
                ))
            })
            .collect(),
        5125 => (0..n)
            .map(|i| {
                f64::from(u32::from_le_bytes(
                    bytes[4 * i..4 * i + 4].try_into().unwrap(),
                ))
            })
            .collect(),
        c => panic!("component type {c}"),
    }
}
