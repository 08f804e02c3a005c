//! A little-endian TIFF writer for fixtures: any tags, one strip per given byte run.

// Each test file that includes this uses a subset of it.
#![allow(dead_code)]

/// A tag's values.
pub enum Value {
    Short(Vec<u16>),
    Long(Vec<u32>),
    Double(Vec<f64>),
    Ascii(String),
}

impl Value {
    fn kind_count_bytes(&self) -> (u16, u32, Vec<u8>) {
        match self {
            Value::Short(v) => (
                3,
                v.len() as u32,
                v.iter().flat_map(|x| x.to_le_bytes()).collect(),
            ),
            Value::Long(v) => (
                4,
                v.len() as u32,
                v.iter().flat_map(|x| x.to_le_bytes()).collect(),
            ),
            Value::Double(v) => (
                12,
                v.len() as u32,
                v.iter().flat_map(|x| x.to_le_bytes()).collect(),
            ),
            Value::Ascii(s) => {
                let mut b = s.as_bytes().to_vec();
                b.push(0);
                (2, b.len() as u32, b)
            }
        }
    }
}

/// A TIFF of `strips` (their offsets and byte counts filled in) and `tags` (which must not
/// include 273 or 279).
pub fn tiff(tags: Vec<(u16, Value)>, strips: &[Vec<u8>]) -> Vec<u8> {
    let mut offsets = Vec::new();
    let mut data = Vec::new();
    for s in strips {
        offsets.push(8 + data.len() as u32);
        data.extend_from_slice(s);
    }
    let mut all = tags;
    all.push((273, Value::Long(offsets)));
    all.push((
        279,
        Value::Long(strips.iter().map(|s| s.len() as u32).collect()),
    ));
    tiff_raw(all, &data)
}

/// A TIFF whose image data `data` lies at byte 8, with exactly `tags` (offsets into the file
/// are the caller's: the data's first byte is at 8).
pub fn tiff_raw(tags: Vec<(u16, Value)>, data: &[u8]) -> Vec<u8> {
    let mut t = b"II*\0\0\0\0\0".to_vec();
    t.extend_from_slice(data);
    let mut all = tags;
    all.sort_by_key(|(tag, _)| *tag);
    // Values longer than 4 bytes go before the IFD, word-aligned.
    let mut entries = Vec::new();
    for (tag, value) in &all {
        let (kind, count, bytes) = value.kind_count_bytes();
        let field = if bytes.len() <= 4 {
            let mut inline = bytes.clone();
            inline.resize(4, 0);
            inline
        } else {
            if t.len() % 2 == 1 {
                t.push(0);
            }
            let at = t.len() as u32;
            t.extend_from_slice(&bytes);
            at.to_le_bytes().to_vec()
        };
        entries.push((*tag, kind, count, field));
    }
    if t.len() % 2 == 1 {
        t.push(0);
    }
    let ifd = t.len() as u32;
    t[4..8].copy_from_slice(&ifd.to_le_bytes());
    t.extend((entries.len() as u16).to_le_bytes());
    for (tag, kind, count, field) in entries {
        t.extend(tag.to_le_bytes());
        t.extend(kind.to_le_bytes());
        t.extend(count.to_le_bytes());
        t.extend(field);
    }
    t.extend(0u32.to_le_bytes());
    t
}

/// A tiled GeoTIFF of `w × h` `f32` samples in `tile²` tiles, PackBits-compressed, where every
/// sample of tile `k` (row-major among the tiles) holds `tile_value(k)`: its four bytes the same
/// byte `tile_byte(k)`, so a tile codes as 128-byte runs (2 bytes each, 64:1). Georeferenced
/// at 10 m steps in UTM 10N. A raster of hundreds of MB in a few MB of file.
pub fn packbits_tiled(w: u32, h: u32, tile: u32) -> Vec<u8> {
    let (across, down) = (w.div_ceil(tile), h.div_ceil(tile));
    let run: Vec<u8> = (0..tile * tile * 4 / 128)
        .flat_map(|_| [0x81u8, 0])
        .collect();
    let mut data = Vec::new();
    let (mut offsets, mut counts) = (Vec::new(), Vec::new());
    for k in 0..across * down {
        offsets.push(8 + data.len() as u32);
        counts.push(run.len() as u32);
        data.extend(run.chunks(2).flat_map(|p| [p[0], tile_byte(k)]));
    }
    tiff_raw(
        vec![
            (256, Value::Long(vec![w])),
            (257, Value::Long(vec![h])),
            (258, Value::Short(vec![32])),
            (259, Value::Short(vec![32773])),
            (262, Value::Short(vec![1])),
            (277, Value::Short(vec![1])),
            (322, Value::Long(vec![tile])),
            (323, Value::Long(vec![tile])),
            (324, Value::Long(offsets)),
            (325, Value::Long(counts)),
            (339, Value::Short(vec![3])),
            (33550, Value::Double(vec![10.0, 10.0, 0.0])),
            (
                33922,
                Value::Double(vec![0.0, 0.0, 0.0, 500_000.0, 5_300_000.0, 0.0]),
            ),
            (34735, Value::Short(vec![1, 1, 0, 1, 3072, 0, 1, 32610])),
        ],
        &data,
    )
}

/// The byte every sample of tile `k` of [`packbits_tiled`] repeats: 0x41 to 0x47, heights from
/// 12.08 to 51,015.3.
pub fn tile_byte(k: u32) -> u8 {
    0x41 + (k % 7) as u8
}

/// The height of every sample of tile `k` of [`packbits_tiled`].
pub fn tile_value(k: u32) -> f32 {
    f32::from_bits(u32::from(tile_byte(k)) * 0x0101_0101)
}
