//! A small RGB canvas: rectangles, lines, markers, text, and PNG encoding.

use super::font;

/// An sRGB colour.
pub type Rgb = [u8; 3];

/// White.
pub const WHITE: Rgb = [255, 255, 255];
/// Black.
pub const BLACK: Rgb = [0, 0, 0];
/// Light grey, for grid lines.
pub const GRID: Rgb = [225, 225, 225];
/// Dark grey, for text and axes.
pub const INK: Rgb = [40, 40, 40];

/// An RGB image, row-major, origin top-left.
#[derive(Debug, Clone, PartialEq)]
pub struct Canvas {
    /// Width, pixels.
    pub width: usize,
    /// Height, pixels.
    pub height: usize,
    /// Pixels, row-major.
    pub pixels: Vec<Rgb>,
}

impl Canvas {
    /// A canvas filled with `bg`.
    pub fn new(width: usize, height: usize, bg: Rgb) -> Self {
        Self {
            width,
            height,
            pixels: vec![bg; width * height],
        }
    }

    /// Sets one pixel (ignored outside the canvas).
    pub fn set(&mut self, x: i64, y: i64, c: Rgb) {
        if x >= 0 && y >= 0 && (x as usize) < self.width && (y as usize) < self.height {
            self.pixels[y as usize * self.width + x as usize] = c;
        }
    }

    /// The pixel at `(x, y)`, if inside.
    pub fn get(&self, x: usize, y: usize) -> Option<Rgb> {
        (x < self.width && y < self.height).then(|| self.pixels[y * self.width + x])
    }

    /// Fills the rectangle `[x0, x1) x [y0, y1)`.
    pub fn fill_rect(&mut self, x0: i64, y0: i64, x1: i64, y1: i64, c: Rgb) {
        for y in y0.max(0)..y1.min(self.height as i64) {
            for x in x0.max(0)..x1.min(self.width as i64) {
                self.set(x, y, c);
            }
        }
    }

    /// Outlines the rectangle `[x0, x1] x [y0, y1]`.
    pub fn stroke_rect(&mut self, x0: i64, y0: i64, x1: i64, y1: i64, c: Rgb) {
        self.line(x0, y0, x1, y0, c, 1);
        self.line(x1, y0, x1, y1, c, 1);
        self.line(x1, y1, x0, y1, c, 1);
        self.line(x0, y1, x0, y0, c, 1);
    }

    /// A line from `(x0, y0)` to `(x1, y1)` (Bresenham), `width` pixels thick (square pen).
    pub fn line(&mut self, x0: i64, y0: i64, x1: i64, y1: i64, c: Rgb, width: usize) {
        let (dx, dy) = ((x1 - x0).abs(), -(y1 - y0).abs());
        let (sx, sy) = (if x0 < x1 { 1 } else { -1 }, if y0 < y1 { 1 } else { -1 });
        let (mut x, mut y, mut err) = (x0, y0, dx + dy);
        let lo = -((width as i64 - 1) / 2);
        let hi = width as i64 / 2;
        // Bound the walk so a huge coordinate cannot spin for long.
        let steps = (dx - dy).min(1 << 16);
        for _ in 0..=steps {
            for oy in lo..=hi {
                for ox in lo..=hi {
                    self.set(x + ox, y + oy, c);
                }
            }
            if x == x1 && y == y1 {
                break;
            }
            let e2 = 2 * err;
            if e2 >= dy {
                err += dy;
                x += sx;
            }
            if e2 <= dx {
                err += dx;
                y += sy;
            }
        }
    }

    /// A filled square marker of half-size `r` centred on `(x, y)`.
    pub fn marker(&mut self, x: i64, y: i64, r: i64, c: Rgb) {
        self.fill_rect(x - r, y - r, x + r + 1, y + r + 1, c);
    }

    /// Text with its top-left corner at `(x, y)`.
    pub fn text(&mut self, text: &str, x: i64, y: i64, scale: usize, c: Rgb) {
        font::render(text, x, y, scale, |px, py| self.set(px, py, c));
    }

    /// Text centred horizontally on `cx`.
    pub fn text_centered(&mut self, text: &str, cx: i64, y: i64, scale: usize, c: Rgb) {
        let w = font::text_width(text, scale) as i64;
        self.text(text, cx - w / 2, y, scale, c);
    }

    /// Text rotated 90 degrees counter-clockwise (reading bottom to top), centred vertically on
    /// `cy`, its left edge at `x`.
    pub fn text_vertical(&mut self, text: &str, x: i64, cy: i64, scale: usize, c: Rgb) {
        let w = font::text_width(text, scale) as i64;
        let y0 = cy + w / 2;
        font::render(text, 0, 0, scale, |px, py| self.set(x + py, y0 - px, c));
    }

    /// Copies `src` with its top-left corner at `(x, y)`.
    pub fn blit(&mut self, src: &Canvas, x: i64, y: i64) {
        for sy in 0..src.height {
            for sx in 0..src.width {
                self.set(x + sx as i64, y + sy as i64, src.pixels[sy * src.width + sx]);
            }
        }
    }

    /// Encodes as an 8-bit RGB PNG.
    pub fn to_png(&self) -> Result<Vec<u8>, png::EncodingError> {
        let mut out = Vec::new();
        {
            let mut enc = png::Encoder::new(&mut out, self.width as u32, self.height as u32);
            enc.set_color(png::ColorType::Rgb);
            enc.set_depth(png::BitDepth::Eight);
            let mut w = enc.write_header()?;
            let data: Vec<u8> = self.pixels.iter().flatten().copied().collect();
            w.write_image_data(&data)?;
            w.finish()?;
        }
        Ok(out)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn line_hits_both_ends_and_png_decodes_back() {
        let mut c = Canvas::new(20, 10, WHITE);
        c.line(1, 1, 18, 8, BLACK, 1);
        assert_eq!(c.get(1, 1), Some(BLACK));
        assert_eq!(c.get(18, 8), Some(BLACK));
        assert_eq!(c.get(18, 1), Some(WHITE));
        c.text("A", 0, 0, 1, [255, 0, 0]);
        let bytes = c.to_png().unwrap();
        let dec = png::Decoder::new(std::io::Cursor::new(bytes));
        let mut reader = dec.read_info().unwrap();
        let mut buf = vec![0; reader.output_buffer_size().unwrap()];
        let info = reader.next_frame(&mut buf).unwrap();
        assert_eq!((info.width, info.height), (20, 10));
        assert_eq!(&buf[(8 * 20 + 18) * 3..(8 * 20 + 18) * 3 + 3], &BLACK);
    }
}
