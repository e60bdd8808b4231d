//! Text in an 8 x 8 bitmap font (the public-domain font8x8 glyphs), no system fonts needed.

use font8x8::legacy::BASIC_LEGACY;

/// Glyph cell size at scale 1, pixels.
pub const GLYPH: usize = 8;

/// The 8 rows of the glyph of `c` (bit 0 = leftmost pixel); `?` for characters outside ASCII.
pub fn glyph(c: char) -> [u8; 8] {
    let i = c as usize;
    if i < 128 {
        BASIC_LEGACY[i]
    } else {
        BASIC_LEGACY['?' as usize]
    }
}

/// Width of `text` at `scale`, pixels.
pub fn text_width(text: &str, scale: usize) -> usize {
    text.chars().count() * GLYPH * scale
}

/// Calls `set(x, y)` for every lit pixel of `text` drawn with its top-left corner at `(x, y)`,
/// each glyph pixel a `scale` x `scale` block. The font's glyphs are 7 px wide with a blank 8th
/// column, which spaces the characters.
pub fn render(text: &str, x: i64, y: i64, scale: usize, mut set: impl FnMut(i64, i64)) {
    let s = scale as i64;
    for (k, c) in text.chars().enumerate() {
        let g = glyph(c);
        let ox = x + (k * GLYPH * scale) as i64;
        for (row, bits) in g.iter().enumerate() {
            for col in 0..8 {
                if bits & (1 << col) != 0 {
                    for dy in 0..s {
                        for dx in 0..s {
                            set(ox + col as i64 * s + dx, y + row as i64 * s + dy);
                        }
                    }
                }
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn digits_have_ink_and_space_has_none() {
        let mut lit = 0;
        render("1", 0, 0, 1, |_, _| lit += 1);
        assert!(lit > 8);
        let mut none = 0;
        render(" ", 0, 0, 2, |_, _| none += 1);
        assert_eq!(none, 0);
        assert_eq!(text_width("abc", 2), 48);
        // Non-ASCII falls back to '?'.
        assert_eq!(glyph('µ'), glyph('?'));
    }
}
