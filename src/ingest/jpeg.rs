//! Baseline JPEG heightfields: grey images, or colour images whose chroma is neutral
//! (R = G = B), read as their luma.
//!
//! JPEG is lossy, and its standard lets decoders differ by a unit in the last place. The inverse
//! DCT is an implementation choice, and two conforming decoders may return different pixels.
//! fmrh's DEMs are compared against files decoded by libjpeg(-turbo) with its default
//! accurate-integer IDCT ("islow"). So this reader implements exactly that arithmetic: the
//! Loeffler–Ligtenberg–Moschytz IDCT with 13-bit constants, 2 extra bits between passes and the
//! same output range table. It reproduces libjpeg's pixels bit for bit.
//!
//! Supported: baseline and extended sequential Huffman (SOF0/SOF1), 8-bit samples, 1 or 3
//! components, any sampling factors, interleaved or per-component scans, restart intervals.
//! A colour image is accepted only when every chroma sample decodes to exactly 128 (neutral).
//! The heights are then the luma, which libjpeg's colour conversion returns unchanged as R, G
//! and B. Progressive, arithmetic-coded, 12-bit and lossless JPEGs are reported as unsupported.

use std::path::Path;

use super::{finish, read_limited, IngestOptions};
use crate::error::{Error, Result};
use crate::heightfield::{check_dimensions, Heightfield, Metadata, MAX_SAMPLES};

/// Natural (row-major) index of the k-th coefficient in zig-zag order.
const ZIGZAG: [usize; 64] = [
    0, 1, 8, 16, 9, 2, 3, 10, 17, 24, 32, 25, 18, 11, 4, 5, 12, 19, 26, 33, 40, 48, 41, 34, 27, 20,
    13, 6, 7, 14, 21, 28, 35, 42, 49, 56, 57, 50, 43, 36, 29, 22, 15, 23, 30, 37, 44, 51, 58, 59,
    52, 45, 38, 31, 39, 46, 53, 60, 61, 54, 47, 55, 62, 63,
];

enum Failure {
    Malformed(String),
    Unsupported(String),
    /// The declared size is past the ingest limits (`super::limits`).
    Limit(Error),
}

type Decoding<T> = std::result::Result<T, Failure>;

fn malformed<T>(msg: impl Into<String>) -> Decoding<T> {
    Err(Failure::Malformed(msg.into()))
}

/// Reads a JPEG heightfield.
pub fn read(path: &Path, options: &IngestOptions) -> Result<Heightfield> {
    let bytes = read_limited(path, MAX_SAMPLES * 4)?;
    let input_bytes = bytes.len() as u64;
    let declared = |w: u32, h: u32| {
        options
            .limits
            .check_declared(path, u64::from(w), u64::from(h), input_bytes)
            .map_err(Failure::Limit)
    };
    let (width, height, luma) = decode(&bytes, &declared).map_err(|f| match f {
        Failure::Malformed(m) => Error::input(path, m),
        Failure::Unsupported(m) => Error::unsupported(path, m),
        Failure::Limit(e) => e,
    })?;
    let samples = luma
        .into_iter()
        .map(|v| options.height(f64::from(v)))
        .collect();
    finish(path, width, height, samples, Metadata::default())
}

#[derive(Clone, Default)]
struct Huffman {
    maxcode: [i32; 17],
    mincode: [i32; 17],
    valptr: [usize; 17],
    values: Vec<u8>,
}

impl Huffman {
    fn new(counts: &[u8; 16], values: &[u8]) -> Decoding<Huffman> {
        let mut h = Huffman {
            values: values.to_vec(),
            ..Huffman::default()
        };
        let (mut code, mut k) = (0i32, 0usize);
        for len in 1..=16 {
            let n = i32::from(counts[len - 1]);
            h.valptr[len] = k;
            h.mincode[len] = code;
            code += n;
            k += n as usize;
            if code > 1 << len {
                return malformed("Huffman table has more codes than its lengths allow");
            }
            h.maxcode[len] = if n > 0 { code - 1 } else { -1 };
            code <<= 1;
        }
        Ok(h)
    }
}

struct Component {
    id: u8,
    h: usize,
    v: usize,
    quant: usize,
    dc: usize,
    ac: usize,
    pred: i32,
}

struct BitReader<'a> {
    data: &'a [u8],
    pos: usize,
    bits: u32,
    count: u32,
}

impl BitReader<'_> {
    fn bit(&mut self) -> Decoding<u32> {
        if self.count == 0 {
            let Some(&byte) = self.data.get(self.pos) else {
                return malformed("entropy-coded data runs past the end of the file");
            };
            if byte == 0xFF {
                match self.data.get(self.pos + 1) {
                    Some(0x00) => self.pos += 2,
                    _ => return malformed("entropy-coded data ends inside a block"),
                }
            } else {
                self.pos += 1;
            }
            self.bits = u32::from(byte);
            self.count = 8;
        }
        self.count -= 1;
        Ok((self.bits >> self.count) & 1)
    }

    fn receive(&mut self, n: u32) -> Decoding<i32> {
        let mut v = 0i32;
        for _ in 0..n {
            v = (v << 1) | self.bit()? as i32;
        }
        Ok(v)
    }

    fn decode(&mut self, table: &Huffman) -> Decoding<u8> {
        let mut code = self.bit()? as i32;
        for len in 1..=16 {
            if code <= table.maxcode[len] {
                let i = table.valptr[len] + (code - table.mincode[len]) as usize;
                return table
                    .values
                    .get(i)
                    .copied()
                    .map_or_else(|| malformed("Huffman code past the table"), Ok);
            }
            code = (code << 1) | self.bit()? as i32;
        }
        malformed("invalid Huffman code")
    }

    /// Skips to the byte after the restart marker that must come next.
    fn restart(&mut self) -> Decoding<()> {
        self.count = 0;
        match (self.data.get(self.pos), self.data.get(self.pos + 1)) {
            (Some(0xFF), Some(m)) if (0xD0..=0xD7).contains(m) => {
                self.pos += 2;
                Ok(())
            }
            _ => malformed("missing restart marker"),
        }
    }
}

/// `(v << 1) | bit`-built magnitude category `s` to its signed value (T.81 F.2.2.1).
fn extend(v: i32, s: u32) -> i32 {
    if s == 0 {
        0
    } else if v < 1 << (s - 1) {
        v - (1 << s) + 1
    } else {
        v
    }
}

const CONST_BITS: u32 = 13;
const PASS1_BITS: u32 = 2;
const FIX_0_298631336: i64 = 2446;
const FIX_0_390180644: i64 = 3196;
const FIX_0_541196100: i64 = 4433;
const FIX_0_765366865: i64 = 6270;
const FIX_0_899976223: i64 = 7373;
const FIX_1_175875602: i64 = 9633;
const FIX_1_501321110: i64 = 12299;
const FIX_1_847759065: i64 = 15137;
const FIX_1_961570560: i64 = 16069;
const FIX_2_053119869: i64 = 16819;
const FIX_2_562915447: i64 = 20995;
const FIX_3_072711026: i64 = 25172;

fn descale(x: i64, n: u32) -> i64 {
    (x + (1 << (n - 1))) >> n
}

/// libjpeg's post-IDCT range limit: the value plus 128, clamped, indexed modulo 1024 exactly
/// as its table is laid out (so even wild values map as libjpeg maps them).
fn range_limit(x: i64) -> u8 {
    let i = (x & 1023) as u32;
    match i {
        0..=127 => (i + 128) as u8,
        128..=511 => 255,
        512..=895 => 0,
        _ => (i - 896) as u8,
    }
}

/// One 1-D pass of the islow IDCT over `v[0..8]` (already dequantized, or the workspace).
/// Returns the eight outputs before descaling.
fn idct_1d(v: [i64; 8]) -> [i64; 8] {
    // Even part.
    let (z2, z3) = (v[2], v[6]);
    let z1 = (z2 + z3) * FIX_0_541196100;
    let tmp2 = z1 + z3 * -FIX_1_847759065;
    let tmp3 = z1 + z2 * FIX_0_765366865;
    let tmp0 = (v[0] + v[4]) << CONST_BITS;
    let tmp1 = (v[0] - v[4]) << CONST_BITS;
    let (tmp10, tmp13, tmp11, tmp12) = (tmp0 + tmp3, tmp0 - tmp3, tmp1 + tmp2, tmp1 - tmp2);
    // Odd part.
    let (mut t0, mut t1, mut t2, mut t3) = (v[7], v[5], v[3], v[1]);
    let (mut z1, mut z2, mut z3, mut z4) = (t0 + t3, t1 + t2, t0 + t2, t1 + t3);
    let z5 = (z3 + z4) * FIX_1_175875602;
    t0 *= FIX_0_298631336;
    t1 *= FIX_2_053119869;
    t2 *= FIX_3_072711026;
    t3 *= FIX_1_501321110;
    z1 *= -FIX_0_899976223;
    z2 *= -FIX_2_562915447;
    z3 *= -FIX_1_961570560;
    z4 *= -FIX_0_390180644;
    z3 += z5;
    z4 += z5;
    t0 += z1 + z3;
    t1 += z2 + z4;
    t2 += z2 + z3;
    t3 += z1 + z4;
    [
        tmp10 + t3,
        tmp11 + t2,
        tmp12 + t1,
        tmp13 + t0,
        tmp13 - t0,
        tmp12 - t1,
        tmp11 - t2,
        tmp10 - t3,
    ]
}

/// Dequantizes and inverse-transforms one block (coefficients and table in natural order).
fn idct_islow(coef: &[i32; 64], quant: &[u16; 64], out: &mut [u8; 64]) {
    let mut ws = [0i64; 64];
    for c in 0..8 {
        let col: [i64; 8] =
            std::array::from_fn(|k| i64::from(coef[k * 8 + c]) * i64::from(quant[k * 8 + c]));
        let r = idct_1d(col);
        for k in 0..8 {
            // libjpeg keeps the workspace in `int`.
            ws[k * 8 + c] = i64::from(descale(r[k], CONST_BITS - PASS1_BITS) as i32);
        }
    }
    for r in 0..8 {
        let row: [i64; 8] = std::array::from_fn(|k| ws[r * 8 + k]);
        let o = idct_1d(row);
        for k in 0..8 {
            out[r * 8 + k] = range_limit(descale(o[k], CONST_BITS + PASS1_BITS + 3));
        }
    }
}

fn u16_at(data: &[u8], at: usize) -> Decoding<usize> {
    match data.get(at..at + 2) {
        Some(b) => Ok(usize::from(u16::from_be_bytes([b[0], b[1]]))),
        None => malformed("truncated segment"),
    }
}

/// Decodes to `(width, height, luma)`.
fn decode(
    data: &[u8],
    declared: &dyn Fn(u32, u32) -> Decoding<()>,
) -> Decoding<(u32, u32, Vec<u8>)> {
    if data.get(..2) != Some(&[0xFF, 0xD8]) {
        return malformed("not a JPEG (no start-of-image marker)");
    }
    let mut quant = [[0u16; 64]; 4];
    let mut dc_tables: [Option<Huffman>; 4] = Default::default();
    let mut ac_tables: [Option<Huffman>; 4] = Default::default();
    let mut components: Vec<Component> = Vec::new();
    let (mut width, mut height) = (0usize, 0usize);
    let mut restart_interval = 0usize;
    let mut planes: Vec<Vec<u8>> = Vec::new(); // per component: blocks_w*8 x blocks_h*8
    let mut blocks: Vec<(usize, usize)> = Vec::new(); // per component: blocks across, down
    let (mut hmax, mut vmax) = (1usize, 1usize);
    let mut pos = 2;
    loop {
        // Next marker, skipping fill bytes.
        while data.get(pos) == Some(&0xFF) && data.get(pos + 1) == Some(&0xFF) {
            pos += 1;
        }
        let (Some(&0xFF), Some(&marker)) = (data.get(pos), data.get(pos + 1)) else {
            return malformed(format!("expected a marker at byte {pos}"));
        };
        pos += 2;
        match marker {
            0xD8 | 0x01 | 0xD0..=0xD7 => continue,
            0xD9 => break,
            _ => {}
        }
        let len = u16_at(data, pos)?;
        let Some(seg) = data.get(pos + 2..pos + len).filter(|_| len >= 2) else {
            return malformed(format!(
                "segment {marker:#04x} at byte {pos} runs past the end"
            ));
        };
        match marker {
            0xC0 | 0xC1 => {
                if !components.is_empty() {
                    return malformed("two frame headers");
                }
                if seg.len() < 6 || seg[0] != 8 {
                    return Err(Failure::Unsupported(format!(
                        "{}-bit samples: only 8-bit JPEG",
                        seg.first().copied().unwrap_or(0)
                    )));
                }
                height = u16_at(seg, 1)?;
                width = u16_at(seg, 3)?;
                let n = usize::from(seg[5]);
                if height == 0 {
                    return Err(Failure::Unsupported("height given by a DNL marker".into()));
                }
                if check_dimensions(width as u64, height as u64).is_err() {
                    return malformed(format!("{width} x {height} pixels"));
                }
                declared(width as u32, height as u32)?;
                if n != 1 && n != 3 || seg.len() < 6 + 3 * n {
                    return Err(Failure::Unsupported(format!(
                        "{n} components: grey (1) or YCbCr (3) only"
                    )));
                }
                for c in seg[6..6 + 3 * n].chunks_exact(3) {
                    let (h, v) = (usize::from(c[1] >> 4), usize::from(c[1] & 15));
                    if !(1..=4).contains(&h) || !(1..=4).contains(&v) || c[2] > 3 {
                        return malformed("bad component sampling factors or table");
                    }
                    components.push(Component {
                        id: c[0],
                        h,
                        v,
                        quant: usize::from(c[2]),
                        dc: 0,
                        ac: 0,
                        pred: 0,
                    });
                }
                // Every 8x8 block of every component costs at least 2 bits of entropy-coded
                // data (a DC and an end-of-block code): refuse a frame the file cannot hold
                // before its planes are allocated.
                let blocks_min = (width.div_ceil(8) * height.div_ceil(8)) as u64;
                if blocks_min / 4 > data.len() as u64 {
                    return malformed("the frame is larger than the file can hold");
                }
                hmax = components.iter().map(|c| c.h).max().unwrap_or(1);
                vmax = components.iter().map(|c| c.v).max().unwrap_or(1);
                let (mcux, mcuy) = (width.div_ceil(8 * hmax), height.div_ceil(8 * vmax));
                for c in &components {
                    let (bw, bh) = (mcux * c.h, mcuy * c.v);
                    blocks.push((bw, bh));
                    planes.push(vec![0u8; bw * 8 * bh * 8]);
                }
            }
            0xC2 | 0xC3 | 0xC5..=0xC7 | 0xC9..=0xCB | 0xCD..=0xCF => {
                return Err(Failure::Unsupported(
                    "progressive, lossless or arithmetic-coded JPEG: baseline only".into(),
                ));
            }
            0xDB => {
                let mut s = seg;
                while !s.is_empty() {
                    let (precision, id) = (s[0] >> 4, usize::from(s[0] & 15));
                    let size = if precision == 0 { 64 } else { 128 };
                    if id > 3 || s.len() < 1 + size {
                        return malformed("bad quantization table");
                    }
                    for k in 0..64 {
                        quant[id][ZIGZAG[k]] = if precision == 0 {
                            u16::from(s[1 + k])
                        } else {
                            u16::from_be_bytes([s[1 + 2 * k], s[2 + 2 * k]])
                        };
                    }
                    s = &s[1 + size..];
                }
            }
            0xC4 => {
                let mut s = seg;
                while !s.is_empty() {
                    if s.len() < 17 {
                        return malformed("bad Huffman table");
                    }
                    let (class, id) = (s[0] >> 4, usize::from(s[0] & 15));
                    let counts: [u8; 16] = std::array::from_fn(|i| s[1 + i]);
                    let total: usize = counts.iter().map(|&c| usize::from(c)).sum();
                    if id > 3 || class > 1 || total > 256 || s.len() < 17 + total {
                        return malformed("bad Huffman table");
                    }
                    let table = Huffman::new(&counts, &s[17..17 + total])?;
                    if class == 0 {
                        dc_tables[id] = Some(table);
                    } else {
                        ac_tables[id] = Some(table);
                    }
                    s = &s[17 + total..];
                }
            }
            0xDD => restart_interval = u16_at(seg, 0)?,
            0xDA => {
                if components.is_empty() {
                    return malformed("scan before the frame header");
                }
                let n = usize::from(*seg.first().unwrap_or(&0));
                if n == 0 || n > components.len() || seg.len() < 1 + 2 * n + 3 {
                    return malformed("bad scan header");
                }
                let mut scan = Vec::with_capacity(n);
                for c in seg[1..1 + 2 * n].chunks_exact(2) {
                    let Some(i) = components.iter().position(|k| k.id == c[0]) else {
                        return malformed("scan names an unknown component");
                    };
                    let (dc, ac) = (usize::from(c[1] >> 4), usize::from(c[1] & 15));
                    if dc > 3 || ac > 3 || dc_tables[dc].is_none() || ac_tables[ac].is_none() {
                        return malformed("scan uses a missing Huffman table");
                    }
                    components[i].dc = dc;
                    components[i].ac = ac;
                    components[i].pred = 0;
                    scan.push(i);
                }
                let mut reader = BitReader {
                    data,
                    pos: pos + len,
                    bits: 0,
                    count: 0,
                };
                decode_scan(
                    &mut reader,
                    &mut components,
                    &scan,
                    &blocks,
                    &mut planes,
                    &quant,
                    &dc_tables,
                    &ac_tables,
                    (width, height, hmax, vmax),
                    restart_interval,
                )?;
                // Skip to the next marker.
                pos = reader.pos;
                while pos + 1 < data.len()
                    && !(data[pos] == 0xFF
                        && data[pos + 1] != 0
                        && !(0xD0..=0xD7).contains(&data[pos + 1]))
                {
                    pos += 1;
                }
                continue;
            }
            _ => {} // APPn, COM and others: skipped.
        }
        pos += len;
    }
    if planes.is_empty() {
        return malformed("no image data");
    }
    // Chroma must be neutral; the luma is then the image.
    for p in planes.iter().skip(1) {
        if p.iter().any(|&v| v != 128) {
            return Err(Failure::Unsupported(
                "colour JPEG: only grey (neutral chroma) images are heightfields".into(),
            ));
        }
    }
    let stride = blocks[0].0 * 8;
    let mut luma = Vec::with_capacity(width * height);
    for y in 0..height {
        luma.extend_from_slice(&planes[0][y * stride..y * stride + width]);
    }
    Ok((width as u32, height as u32, luma))
}

#[allow(clippy::too_many_arguments)]
fn decode_scan(
    reader: &mut BitReader,
    components: &mut [Component],
    scan: &[usize],
    blocks: &[(usize, usize)],
    planes: &mut [Vec<u8>],
    quant: &[[u16; 64]; 4],
    dc_tables: &[Option<Huffman>; 4],
    ac_tables: &[Option<Huffman>; 4],
    (width, height, hmax, vmax): (usize, usize, usize, usize),
    restart_interval: usize,
) -> Decoding<()> {
    // A single-component scan covers that component's own blocks; an interleaved one, MCUs.
    let units: Vec<(usize, usize)> = if scan.len() == 1 {
        let c = &components[scan[0]];
        let (bw, bh) = (
            (width * c.h).div_ceil(hmax).div_ceil(8),
            (height * c.v).div_ceil(vmax).div_ceil(8),
        );
        (0..bh).flat_map(|y| (0..bw).map(move |x| (x, y))).collect()
    } else {
        let (mx, my) = (width.div_ceil(8 * hmax), height.div_ceil(8 * vmax));
        (0..my).flat_map(|y| (0..mx).map(move |x| (x, y))).collect()
    };
    let mut coef = [0i32; 64];
    let mut out = [0u8; 64];
    for (n, &(ux, uy)) in units.iter().enumerate() {
        if restart_interval > 0 && n > 0 && n % restart_interval == 0 {
            reader.restart()?;
            for &i in scan {
                components[i].pred = 0;
            }
        }
        for &i in scan {
            let (h, v) = if scan.len() == 1 {
                (1, 1)
            } else {
                (components[i].h, components[i].v)
            };
            for by in 0..v {
                for bx in 0..h {
                    let (dc, ac) = (
                        dc_tables[components[i].dc]
                            .as_ref()
                            .expect("checked by the scan header"),
                        ac_tables[components[i].ac]
                            .as_ref()
                            .expect("checked by the scan header"),
                    );
                    coef.fill(0);
                    let t = u32::from(reader.decode(dc)?);
                    if t > 11 {
                        return malformed("DC difference out of range");
                    }
                    let diff = extend(reader.receive(t)?, t);
                    // libjpeg keeps coefficients as 16-bit.
                    components[i].pred = (components[i].pred + diff) as i16 as i32;
                    coef[0] = components[i].pred;
                    let mut k = 1;
                    while k < 64 {
                        let rs = reader.decode(ac)?;
                        let (r, s) = (usize::from(rs >> 4), u32::from(rs & 15));
                        if s == 0 {
                            if r == 15 {
                                k += 16;
                                continue;
                            }
                            break;
                        }
                        k += r;
                        if k > 63 {
                            return malformed("AC coefficients past the block");
                        }
                        coef[ZIGZAG[k]] = extend(reader.receive(s)?, s) as i16 as i32;
                        k += 1;
                    }
                    idct_islow(&coef, &quant[components[i].quant], &mut out);
                    let (bxx, byy) = if scan.len() == 1 {
                        (ux, uy)
                    } else {
                        (ux * h + bx, uy * v + by)
                    };
                    let (bw, bh) = blocks[i];
                    if bxx >= bw || byy >= bh {
                        continue;
                    }
                    let stride = bw * 8;
                    for r in 0..8 {
                        let at = (byy * 8 + r) * stride + bxx * 8;
                        planes[i][at..at + 8].copy_from_slice(&out[r * 8..r * 8 + 8]);
                    }
                }
            }
        }
    }
    Ok(())
}
