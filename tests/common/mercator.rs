//! Web Mercator tiles and terrain-RGB pixels for the tests, written from the public
//! definitions (not fmrh's code): a tile's corners, the tile holding a point, the two
//! encodings' decoders, and the bundled SRTM tile N43E006 drawn between its samples.

#![allow(dead_code)]

/// Metres along the equator: Web Mercator's width at zoom 0.
pub const EQUATOR_M: f64 = 40_075_016.686;

/// Longitude and latitude (degrees) of the point `(fx, fy)` tiles from tile `z/x/y`'s
/// north-west corner.
pub fn lon_lat(z: u32, x: u32, y: u32, fx: f64, fy: f64) -> [f64; 2] {
    let n = f64::from(1u32 << z);
    let lon = (f64::from(x) + fx) / n * 360.0 - 180.0;
    let m = std::f64::consts::PI * (1.0 - 2.0 * (f64::from(y) + fy) / n);
    [lon, m.sinh().atan().to_degrees()]
}

/// Where `(lon, lat)` lies at zoom `z`, in tiles from the north-west corner of the world.
pub fn world(z: u32, lon: f64, lat: f64) -> [f64; 2] {
    let n = f64::from(1u32 << z);
    let r = lat.to_radians();
    [
        (lon + 180.0) / 360.0 * n,
        (1.0 - (r.tan() + 1.0 / r.cos()).ln() / std::f64::consts::PI) / 2.0 * n,
    ]
}

/// The tile holding `(lon, lat)` at zoom `z`.
pub fn tile_of(z: u32, lon: f64, lat: f64) -> (u32, u32) {
    let [x, y] = world(z, lon, lat);
    (x as u32, y as u32)
}

/// The height a pixel encodes; `None` for a transparent one.
pub fn decode(encoding: &str, px: &[u8]) -> Option<f64> {
    if px[3] == 0 {
        return None;
    }
    let (r, g, b) = (f64::from(px[0]), f64::from(px[1]), f64::from(px[2]));
    Some(match encoding {
        "mapbox" => -10_000.0 + (r * 65_536.0 + g * 256.0 + b) * 0.1,
        _ => r * 256.0 + g + b / 256.0 - 32_768.0,
    })
}

/// N43E006 (1201², 3", north-west sample at 6° E, 44° N) drawn between its samples as
/// each cell's two triangles, split from north-west to south-east: `None` off the data.
pub fn n43e006_at(samples: &[f32], lon: f64, lat: f64) -> Option<f64> {
    let step = 1.0 / 1200.0;
    let (u, v) = ((lon - 6.0) / step, (44.0 - lat) / step);
    if !(0.0..=1200.0).contains(&u) || !(0.0..=1200.0).contains(&v) {
        return None;
    }
    let (i, j) = ((u as usize).min(1199), (v as usize).min(1199));
    let (fu, fv) = (u - i as f64, v - j as f64);
    let at = |i: usize, j: usize| f64::from(samples[j * 1201 + i]);
    let (nw, ne, sw, se) = (at(i, j), at(i + 1, j), at(i, j + 1), at(i + 1, j + 1));
    Some(if fu >= fv {
        (1.0 - fu) * nw + (fu - fv) * ne + fv * se
    } else {
        (1.0 - fv) * nw + (fv - fu) * sw + fu * se
    })
}

/// A square RGB or RGBA PNG's pixels as RGBA (RGB made opaque), its side and its colour
/// type.
pub fn rgba(png_bytes: &[u8]) -> (Vec<u8>, u32, png::ColorType) {
    let mut reader = png::Decoder::new(std::io::Cursor::new(png_bytes))
        .read_info()
        .unwrap();
    let mut buf = vec![0; reader.output_buffer_size().unwrap()];
    let info = reader.next_frame(&mut buf).unwrap();
    assert_eq!(info.width, info.height);
    buf.truncate(info.buffer_size());
    let pixels = match info.color_type {
        png::ColorType::Rgba => buf,
        png::ColorType::Rgb => buf
            .chunks(3)
            .flat_map(|p| [p[0], p[1], p[2], 255])
            .collect(),
        other => panic!("a terrain-RGB tile in {other:?}"),
    };
    (pixels, info.width, info.color_type)
}
