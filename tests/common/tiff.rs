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
