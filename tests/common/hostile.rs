//! Hostile inputs built in code: files whose headers claim far more than they hold. Shared by
//! the malformed-input tests and the peak-memory test.

// Each test file that includes this uses a subset of it.
#![allow(dead_code)]

/// A USGS ASCII DEM (the 1024-byte record layout of `src/ingest/usgs_dem.rs`) with 30 m
/// resolution and one profile per `(y, elevations)`: profile `i` is column `i + 1`, its first
/// elevation at northing `y`.
pub fn usgs_dem(profiles: &[(f64, Vec<i32>)]) -> Vec<u8> {
    fn put(buf: &mut [u8], at: usize, s: &str) {
        buf[at..at + s.len()].copy_from_slice(s.as_bytes());
    }
    let mut a = vec![b' '; 1024];
    put(&mut a, 156, &format!("{:6}", 1)); // UTM
    put(&mut a, 162, &format!("{:6}", 10)); // zone
    put(&mut a, 528, &format!("{:6}", 2)); // metres
    put(&mut a, 534, &format!("{:6}", 2));
    for (i, r) in [30.0, 30.0, 1.0].iter().enumerate() {
        put(&mut a, 816 + 12 * i, &format!("{r:12.6E}"));
    }
    put(&mut a, 858, &format!("{:6}", profiles.len()));
    let mut out = a;
    for (c, (y, elevations)) in profiles.iter().enumerate() {
        assert!(elevations.len() <= 146, "one record per profile here");
        let mut p = vec![b' '; 1024];
        put(&mut p, 0, &format!("{:6}", 1));
        put(&mut p, 6, &format!("{:6}", c + 1));
        put(&mut p, 12, &format!("{:6}", elevations.len()));
        put(&mut p, 18, &format!("{:6}", 1));
        put(
            &mut p,
            24,
            &format!("{:24.15E}", 500_000.0 + 30.0 * c as f64),
        );
        put(&mut p, 48, &format!("{y:24.15E}"));
        put(&mut p, 72, &format!("{:24.15E}", 0.0));
        for (k, e) in elevations.iter().enumerate() {
            put(&mut p, 144 + 6 * k, &format!("{e:6}"));
        }
        out.extend(p);
    }
    out
}

/// The size bomb of issue 13: `n` one-elevation profiles whose northings alternate between
/// 0 and (2^20 - 1) · 30 m, so the profiles' bounding box is 2^20 rows tall.
pub fn usgs_dem_bomb(n: usize) -> Vec<u8> {
    let profiles: Vec<(f64, Vec<i32>)> = (0..n)
        .map(|i| {
            let y = if i % 2 == 0 {
                0.0
            } else {
                ((1u64 << 20) - 1) as f64 * 30.0
            };
            (y, vec![100])
        })
        .collect();
    usgs_dem(&profiles)
}

/// A PNG chunk: length, kind, body, CRC.
pub fn png_chunk(kind: &[u8; 4], body: &[u8]) -> Vec<u8> {
    let mut c = (body.len() as u32).to_be_bytes().to_vec();
    c.extend(kind);
    c.extend(body);
    let mut h = crc32fast::Hasher::new();
    h.update(kind);
    h.update(body);
    c.extend(h.finalize().to_be_bytes());
    c
}
