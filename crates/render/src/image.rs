//! An RGB8 canvas: pixels, panels, captions, PNG.

use std::io;
use std::path::Path;

use ab_glyph::{point, Font, FontRef, PxScale, ScaleFont};

/// The bundled font: an ASCII subset (plus a few symbols: degree, plus-minus, times,
/// alpha, beta, gamma, epsilon) of DejaVu Sans, 11 KB, under the Bitstream Vera licence
/// (`assets/LICENSE-DejaVu.txt`): captions need no system font.
pub const FONT_TTF: &[u8] = include_bytes!("../assets/DejaVuSans-ascii.ttf");

/// An RGB image, 8 bits per channel, rows from the top.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct Image {
    width: u32,
    height: u32,
    data: Vec<u8>,
}

impl Image {
    /// An image filled with `colour`.
    pub fn new(width: u32, height: u32, colour: [u8; 3]) -> Image {
        let data = colour.iter().copied().cycle().take(width as usize * height as usize * 3).collect();
        Image { width, height, data }
    }

    /// Wraps RGB bytes, rows from the top (e.g. a plotters bitmap buffer); `None` if the
    /// length is not `width * height * 3`.
    pub fn from_rgb(width: u32, height: u32, data: Vec<u8>) -> Option<Image> {
        (data.len() == width as usize * height as usize * 3).then_some(Image { width, height, data })
    }

    /// Width in pixels.
    pub fn width(&self) -> u32 {
        self.width
    }

    /// Height in pixels.
    pub fn height(&self) -> u32 {
        self.height
    }

    /// The RGB bytes, rows from the top.
    pub fn as_rgb(&self) -> &[u8] {
        &self.data
    }

    /// The colour of pixel `(x, y)` (`y` from the top). Panics when out of bounds.
    pub fn pixel(&self, x: u32, y: u32) -> [u8; 3] {
        assert!(x < self.width && y < self.height, "pixel ({x}, {y}) outside {}x{}", self.width, self.height);
        let i = (y as usize * self.width as usize + x as usize) * 3;
        [self.data[i], self.data[i + 1], self.data[i + 2]]
    }

    /// Sets pixel `(x, y)`; ignored when out of bounds.
    pub fn set_pixel(&mut self, x: i64, y: i64, colour: [u8; 3]) {
        if x >= 0 && y >= 0 && (x as u32) < self.width && (y as u32) < self.height {
            let i = (y as usize * self.width as usize + x as usize) * 3;
            self.data[i..i + 3].copy_from_slice(&colour);
        }
    }

    /// Blends `colour` over pixel `(x, y)` with opacity `a` in `[0, 1]`; ignored when out
    /// of bounds.
    pub fn blend_pixel(&mut self, x: i64, y: i64, colour: [u8; 3], a: f32) {
        if x >= 0 && y >= 0 && (x as u32) < self.width && (y as u32) < self.height {
            let i = (y as usize * self.width as usize + x as usize) * 3;
            let a = a.clamp(0.0, 1.0);
            for c in 0..3 {
                let v = f32::from(self.data[i + c]) * (1.0 - a) + f32::from(colour[c]) * a;
                self.data[i + c] = v.round() as u8;
            }
        }
    }

    /// Fills the rectangle of size `w x h` with top-left corner `(x, y)`, clipped.
    pub fn fill_rect(&mut self, x: i64, y: i64, w: u32, h: u32, colour: [u8; 3]) {
        for yy in y..y + i64::from(h) {
            for xx in x..x + i64::from(w) {
                self.set_pixel(xx, yy, colour);
            }
        }
    }

    /// Copies `other` with its top-left corner at `(x, y)`, clipped.
    pub fn blit(&mut self, other: &Image, x: i64, y: i64) {
        for yy in 0..other.height {
            for xx in 0..other.width {
                self.set_pixel(x + i64::from(xx), y + i64::from(yy), other.pixel(xx, yy));
            }
        }
    }

    /// The average of each `factor x factor` block (supersampling resolve); the size
    /// must be a multiple of `factor`.
    pub fn downsample(&self, factor: u32) -> Image {
        let f = factor.max(1);
        let (w, h) = (self.width / f, self.height / f);
        let mut out = Image::new(w, h, [0; 3]);
        let n = f * f;
        for y in 0..h {
            for x in 0..w {
                let mut sum = [0u32; 3];
                for dy in 0..f {
                    for dx in 0..f {
                        let p = self.pixel(x * f + dx, y * f + dy);
                        (0..3).for_each(|c| sum[c] += u32::from(p[c]));
                    }
                }
                out.set_pixel(i64::from(x), i64::from(y), sum.map(|s| ((s + n / 2) / n) as u8));
            }
        }
        out
    }

    /// The width in pixels of `text` at `size` pixels (em height) in the bundled font.
    pub fn text_width(text: &str, size: f32) -> f32 {
        let font = font();
        let scaled = font.as_scaled(PxScale::from(size));
        let mut width = 0.0;
        let mut last = None;
        for c in text.chars() {
            let id = scaled.glyph_id(c);
            if let Some(prev) = last {
                width += scaled.kern(prev, id);
            }
            width += scaled.h_advance(id);
            last = Some(id);
        }
        width
    }

    /// Draws `text` in the bundled font, `size` pixels high, with the top of its line at
    /// `y` and starting at `x` (anti-aliased); returns the width drawn.
    pub fn draw_text(&mut self, x: f32, y: f32, size: f32, colour: [u8; 3], text: &str) -> f32 {
        let font = font();
        let scale = PxScale::from(size);
        let scaled = font.as_scaled(scale);
        let baseline = y + scaled.ascent();
        let mut pen = x;
        let mut last = None;
        for c in text.chars() {
            let id = scaled.glyph_id(c);
            if let Some(prev) = last {
                pen += scaled.kern(prev, id);
            }
            let glyph = id.with_scale_and_position(scale, point(pen, baseline));
            if let Some(outline) = font.outline_glyph(glyph) {
                let b = outline.px_bounds();
                outline.draw(|gx, gy, coverage| {
                    let px = b.min.x as i64 + i64::from(gx);
                    let py = b.min.y as i64 + i64::from(gy);
                    self.blend_pixel(px, py, colour, coverage);
                });
            }
            pen += scaled.h_advance(id);
            last = Some(id);
        }
        pen - x
    }

    /// Draws `text` centred horizontally on `cx`.
    pub fn draw_text_centred(&mut self, cx: f32, y: f32, size: f32, colour: [u8; 3], text: &str) {
        let w = Image::text_width(text, size);
        self.draw_text(cx - 0.5 * w, y, size, colour, text);
    }

    /// The image encoded as PNG (RGB8, best compression, adaptive filters: deterministic).
    pub fn to_png(&self) -> io::Result<Vec<u8>> {
        let mut bytes = Vec::new();
        let mut encoder = png::Encoder::new(&mut bytes, self.width, self.height);
        encoder.set_color(png::ColorType::Rgb);
        encoder.set_depth(png::BitDepth::Eight);
        encoder.set_compression(png::Compression::Best);
        encoder.set_adaptive_filter(png::AdaptiveFilterType::Adaptive);
        let mut writer = encoder.write_header().map_err(io::Error::other)?;
        writer.write_image_data(&self.data).map_err(io::Error::other)?;
        writer.finish().map_err(io::Error::other)?;
        Ok(bytes)
    }

    /// Writes the image as a PNG file (through a temporary file in the same folder, then
    /// a rename: never a partial file).
    pub fn write_png(&self, path: &Path) -> io::Result<()> {
        let bytes = self.to_png()?;
        let tmp = path.with_extension("png.tmp");
        std::fs::write(&tmp, bytes)?;
        std::fs::rename(&tmp, path)
    }
}

fn font() -> FontRef<'static> {
    FontRef::try_from_slice(FONT_TTF).expect("the bundled font parses")
}

/// The viridis colour map at `t` in `[0, 1]` (clamped; NaN maps to 0): dark blue, green,
/// yellow. Piecewise linear through 9 samples of matplotlib's table.
pub fn viridis(t: f64) -> [u8; 3] {
    const STOPS: [[f64; 3]; 9] = [
        [68.0, 1.0, 84.0],
        [71.0, 44.0, 122.0],
        [59.0, 81.0, 139.0],
        [44.0, 113.0, 142.0],
        [33.0, 144.0, 141.0],
        [39.0, 173.0, 129.0],
        [92.0, 200.0, 99.0],
        [170.0, 220.0, 50.0],
        [253.0, 231.0, 37.0],
    ];
    let t = if t.is_nan() { 0.0 } else { t.clamp(0.0, 1.0) } * 8.0;
    let i = (t.floor() as usize).min(7);
    let f = t - i as f64;
    let (a, b) = (STOPS[i], STOPS[i + 1]);
    std::array::from_fn(|c| (a[c] + (b[c] - a[c]) * f).round() as u8)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn png_round_trips() {
        let mut img = Image::new(7, 5, [10, 20, 30]);
        img.set_pixel(3, 2, [255, 0, 0]);
        let bytes = img.to_png().unwrap();
        let decoder = png::Decoder::new(bytes.as_slice());
        let mut reader = decoder.read_info().unwrap();
        let mut buf = vec![0; reader.output_buffer_size()];
        let info = reader.next_frame(&mut buf).unwrap();
        assert_eq!((info.width, info.height, info.color_type), (7, 5, png::ColorType::Rgb));
        assert_eq!(&buf[..info.buffer_size()], img.as_rgb());
    }

    #[test]
    fn text_is_drawn_inside_its_box() {
        let mut img = Image::new(120, 30, [255; 3]);
        let w = img.draw_text(4.0, 4.0, 16.0, [0; 3], "voxreg 1.0");
        assert!((w - Image::text_width("voxreg 1.0", 16.0)).abs() < 1e-3 && w > 40.0 && w < 110.0);
        let mut inked = 0;
        for y in 0..30 {
            for x in 0..120 {
                if img.pixel(x, y) != [255; 3] {
                    inked += 1;
                    assert!(
                        x >= 3 && f64::from(x) <= 6.0 + f64::from(w) && (3..26).contains(&y),
                        "({x}, {y})"
                    );
                }
            }
        }
        assert!(inked > 50, "{inked}");
    }

    #[test]
    fn downsample_averages_blocks_and_viridis_spans_its_ends() {
        let mut img = Image::new(4, 2, [0; 3]);
        img.fill_rect(0, 0, 1, 2, [200; 3]);
        let small = img.downsample(2);
        assert_eq!((small.width(), small.height()), (2, 1));
        assert_eq!(small.pixel(0, 0), [100; 3]);
        assert_eq!(small.pixel(1, 0), [0; 3]);
        assert_eq!(viridis(0.0), [68, 1, 84]);
        assert_eq!(viridis(1.0), [253, 231, 37]);
        assert_eq!(viridis(f64::NAN), viridis(-3.0));
    }
}
