//! PNG heightfields, in four codings:
//!
//! * **grey**, 8 or 16 bits: the raw value, scaled by `z_scale` / `z_offset`;
//! * **grey palette**, 8 bits or fewer: the palette entry's grey level, accepted only when
//!   every entry has R = G = B;
//! * **Terrain-RGB** (Mapbox), 8-bit RGB(A): `h = -10000 + (R·65536 + G·256 + B) · 0.1`;
//! * **Terrarium**, 8-bit RGB(A): `h = R·256 + G + B/256 - 32768`.
//!
//! Colour files cannot say which colour coding they use, so the caller must say
//! ([`super::ColorEncoding`]). A pixel with alpha 0 is a void. Decoding is the `png` crate's,
//! with its memory limit set from fmrh's size limits.

use std::fs::File;
use std::io::BufReader;
use std::path::Path;

use png::{BitDepth, ColorType, Decoder, Transformations};

use super::{finish, ColorEncoding, IngestOptions};
use crate::error::{Error, Result};
use crate::heightfield::{check_dimensions, Heightfield, Metadata, MAX_SAMPLES};

fn png_error(path: &Path, e: png::DecodingError) -> Error {
    match e {
        png::DecodingError::IoError(io) => {
            Error::input(path, format!("truncated or unreadable: {io}"))
        }
        png::DecodingError::LimitsExceeded => Error::TooLarge {
            what: path.display().to_string(),
            detail: "the PNG needs more memory than fmrh allows".into(),
        },
        other => Error::input(path, other.to_string()),
    }
}

/// Reads a PNG heightfield.
pub fn read(path: &Path, options: &IngestOptions) -> Result<Heightfield> {
    let file = File::open(path).map_err(|e| Error::io(path, e))?;
    let mut decoder = Decoder::new_with_limits(
        BufReader::new(file),
        png::Limits {
            bytes: usize::try_from(MAX_SAMPLES * 8).unwrap_or(usize::MAX),
        },
    );
    decoder.set_transformations(Transformations::IDENTITY);
    let mut reader = decoder.read_info().map_err(|e| png_error(path, e))?;
    let info = reader.info();
    let (width, height) = (info.width, info.height);
    check_dimensions(u64::from(width), u64::from(height))
        .map_err(|e| Error::input(path, e.to_string()))?;
    super::check_declared(path, options, u64::from(width), u64::from(height))?;
    let (color, depth) = (info.color_type, info.bit_depth);
    let palette = info.palette.as_ref().map(|p| p.to_vec());
    // Row by row: the buffer grows only as image data actually decodes, so a header that
    // claims more rows than the file holds costs what the file holds, not what it claims.
    let line = reader
        .output_line_size(width)
        .ok_or_else(|| Error::input(path, "image too large to decode"))?;
    let mut buf = Vec::new();
    for _ in 0..height {
        let row = reader
            .next_row()
            .map_err(|e| png_error(path, e))?
            .ok_or_else(|| Error::input(path, "truncated: the image data ends early"))?;
        let data = row.data();
        if data.len() != line {
            return Err(Error::input(path, "a decoded row has the wrong length"));
        }
        buf.extend_from_slice(data);
    }
    // The rest of the stream up to IEND: a file cut after its last row is still truncated.
    reader.finish().map_err(|e| png_error(path, e))?;
    let (w, h) = (width as usize, height as usize);
    let mut samples = Vec::with_capacity(w * h);

    match (color, depth) {
        (ColorType::Grayscale, BitDepth::Sixteen) | (ColorType::GrayscaleAlpha, BitDepth::Sixteen) => {
            let step = if color == ColorType::Grayscale { 2 } else { 4 };
            for row in buf.chunks_exact(line).take(h) {
                for px in row.chunks_exact(step).take(w) {
                    let alpha_zero = step == 4 && px[2] == 0 && px[3] == 0;
                    let raw = u16::from_be_bytes([px[0], px[1]]);
                    samples.push(if alpha_zero { f32::NAN } else { options.height(f64::from(raw)) });
                }
            }
        }
        (ColorType::Grayscale, BitDepth::Eight) | (ColorType::GrayscaleAlpha, BitDepth::Eight) => {
            let step = if color == ColorType::Grayscale { 1 } else { 2 };
            for row in buf.chunks_exact(line).take(h) {
                for px in row.chunks_exact(step).take(w) {
                    let alpha_zero = step == 2 && px[1] == 0;
                    samples.push(if alpha_zero { f32::NAN } else { options.height(f64::from(px[0])) });
                }
            }
        }
        (ColorType::Indexed, _) => {
            let palette = palette.ok_or_else(|| Error::input(path, "palette image without a PLTE chunk"))?;
            let greys: Vec<u8> = palette
                .chunks_exact(3)
                .map(|c| (c[0] == c[1] && c[1] == c[2]).then_some(c[0]))
                .collect::<Option<Vec<u8>>>()
                .ok_or_else(|| {
                    Error::unsupported(path, "colour palette: only grey palettes (R = G = B) are heightfields")
                })?;
            let bits = depth as usize;
            for row in buf.chunks_exact(line).take(h) {
                for x in 0..w {
                    let bit = x * bits;
                    let index = (row[bit / 8] >> (8 - bits - bit % 8)) & ((1u16 << bits) - 1) as u8;
                    let grey = *greys.get(usize::from(index)).ok_or_else(|| {
                        Error::input(path, format!("pixel uses palette entry {index}, past the palette's end"))
                    })?;
                    samples.push(options.height(f64::from(grey)));
                }
            }
        }
        (ColorType::Rgb, BitDepth::Eight) | (ColorType::Rgba, BitDepth::Eight) => {
            let encoding = options.color_encoding.ok_or_else(|| {
                Error::InvalidArgument(format!(
                    "{}: an RGB PNG does not say how it encodes height; give --color-encoding terrain-rgb or terrarium",
                    path.display()
                ))
            })?;
            let step = if color == ColorType::Rgb { 3 } else { 4 };
            for row in buf.chunks_exact(line).take(h) {
                for px in row.chunks_exact(step).take(w) {
                    if step == 4 && px[3] == 0 {
                        samples.push(f32::NAN);
                        continue;
                    }
                    let (r, g, b) = (f64::from(px[0]), f64::from(px[1]), f64::from(px[2]));
                    let metres = match encoding {
                        ColorEncoding::TerrainRgb => -10000.0 + (r * 65536.0 + g * 256.0 + b) * 0.1,
                        ColorEncoding::Terrarium => r * 256.0 + g + b / 256.0 - 32768.0,
                    };
                    samples.push(options.height(metres));
                }
            }
        }
        (color, depth) => {
            return Err(Error::unsupported(
                path,
                format!("{color:?} at {depth:?} bits: fmrh reads grey (8/16-bit), grey palettes and 8-bit RGB(A)"),
            ))
        }
    }
    if samples.len() != w * h {
        return Err(Error::input(
            path,
            "image data is shorter than its header says",
        ));
    }
    let units = matches!(
        (color, options.color_encoding),
        (ColorType::Rgb | ColorType::Rgba, Some(_))
    )
    .then(|| "metres".to_string());
    finish(
        path,
        width,
        height,
        samples,
        Metadata {
            units,
            ..Metadata::default()
        },
    )
}
