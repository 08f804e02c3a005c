//! The few characters the pictures print (the legend's level numbers, the scale bar's
//! length, the north arrow's `N`): a 5-pixel-high bitmap font drawn at twice its size, so
//! that pictures need no font file and come out the same byte for byte everywhere.

use super::Image;

/// A glyph's rows, top first, each in the low `width` bits (most significant bit left).
struct Glyph {
    width: i64,
    rows: [u8; 5],
}

const fn g(width: i64, rows: [u8; 5]) -> Glyph {
    Glyph { width, rows }
}

/// The glyph of `c`, if the font has it.
fn glyph(c: char) -> Option<Glyph> {
    Some(match c {
        '0' => g(3, [7, 5, 5, 5, 7]),
        '1' => g(3, [2, 6, 2, 2, 7]),
        '2' => g(3, [7, 1, 7, 4, 7]),
        '3' => g(3, [7, 1, 7, 1, 7]),
        '4' => g(3, [5, 5, 7, 1, 1]),
        '5' => g(3, [7, 4, 7, 1, 7]),
        '6' => g(3, [7, 4, 7, 5, 7]),
        '7' => g(3, [7, 1, 1, 1, 1]),
        '8' => g(3, [7, 5, 7, 5, 7]),
        '9' => g(3, [7, 5, 7, 1, 7]),
        '.' => g(1, [0, 0, 0, 0, 1]),
        'k' => g(3, [4, 5, 6, 5, 5]),
        'm' => g(5, [0, 26, 21, 21, 21]),
        'N' => g(4, [9, 13, 11, 9, 9]),
        _ => return None,
    })
}

/// Pixels a font pixel covers, across and down.
const SCALE: i64 = 2;

/// The height of a line of text, in pixels.
pub const HEIGHT: i64 = 5 * SCALE;

/// The width of `text` in pixels (characters the font lacks take a space).
pub fn width(text: &str) -> i64 {
    let w: i64 = text
        .chars()
        .map(|c| glyph(c).map_or(3, |g| g.width) * SCALE + SCALE)
        .sum();
    (w - SCALE).max(0)
}

/// Draws `text` with its top-left corner at `(x, y)`.
pub fn draw(image: &mut Image, x: i64, y: i64, text: &str, colour: [u8; 3]) {
    let mut at = x;
    for c in text.chars() {
        let Some(g) = glyph(c) else {
            at += 4 * SCALE;
            continue;
        };
        for (gy, bits) in g.rows.iter().enumerate() {
            for gx in 0..g.width {
                if bits >> (g.width - 1 - gx) & 1 == 1 {
                    super::fill(
                        image,
                        at + SCALE * gx,
                        y + SCALE * gy as i64,
                        SCALE,
                        SCALE,
                        colour,
                    );
                }
            }
        }
        at += (g.width + 1) * SCALE;
    }
}
