//! Pictures made of images and words: the depth-complexity image with its legend bar, and
//! `check`'s three panels (truth, algorithm, difference) with their titles.

use std::path::Path;

use super::text;

/// An 8-bit RGB picture being drawn (row-major, top row first).
#[derive(Clone, Debug, PartialEq)]
pub struct Canvas {
    pub width: u32,
    pub height: u32,
    pub pixels: Vec<[u8; 3]>,
}

/// Picture colours.
pub const WHITE: [u8; 3] = [255, 255, 255];
pub const BLACK: [u8; 3] = [0, 0, 0];
const INK: [u8; 3] = [20, 20, 20];

impl Canvas {
    pub fn new(width: u32, height: u32, background: [u8; 3]) -> Canvas {
        Canvas {
            width,
            height,
            pixels: vec![background; width as usize * height as usize],
        }
    }

    /// An RGBA float image (alpha ignored), each channel rounded to 8 bits as
    /// [`crate::output::write_rgba`] does.
    pub fn from_rgba(width: u32, height: u32, image: &[[f32; 4]]) -> Canvas {
        Canvas {
            width,
            height,
            pixels: image.iter().map(|p| [0, 1, 2].map(|c| to8(p[c]))).collect(),
        }
    }

    /// Fills a `w` x `h` rectangle at `(x, y)` (clipped to the canvas).
    pub fn fill(&mut self, x: i64, y: i64, w: u32, h: u32, color: [u8; 3]) {
        let x0 = x.clamp(0, i64::from(self.width)) as u32;
        let y0 = y.clamp(0, i64::from(self.height)) as u32;
        let x1 = (x + i64::from(w)).clamp(0, i64::from(self.width)) as u32;
        let y1 = (y + i64::from(h)).clamp(0, i64::from(self.height)) as u32;
        for yy in y0..y1 {
            let row = (yy * self.width) as usize;
            self.pixels[row + x0 as usize..row + x1 as usize].fill(color);
        }
    }

    /// Copies `other` with its top left corner at `(x, y)` (clipped).
    pub fn blit(&mut self, other: &Canvas, x: u32, y: u32) {
        for yy in 0..other.height.min(self.height.saturating_sub(y)) {
            let w = other.width.min(self.width.saturating_sub(x)) as usize;
            let src = (yy * other.width) as usize;
            let dst = ((y + yy) * self.width + x) as usize;
            self.pixels[dst..dst + w].copy_from_slice(&other.pixels[src..src + w]);
        }
    }

    pub fn get(&self, x: u32, y: u32) -> [u8; 3] {
        self.pixels[(y * self.width + x) as usize]
    }

    /// As an `image` crate buffer (opaque RGBA).
    pub fn to_image(&self) -> image::RgbaImage {
        let raw: Vec<u8> = self
            .pixels
            .iter()
            .flat_map(|p| [p[0], p[1], p[2], 255])
            .collect();
        image::RgbaImage::from_raw(self.width, self.height, raw).expect("size matches")
    }

    /// Writes a PNG atomically (a temporary file renamed into place).
    pub fn write_png(&self, path: &Path) -> std::io::Result<()> {
        let tmp = path.with_extension("png.tmp");
        self.to_image()
            .save_with_format(&tmp, image::ImageFormat::Png)
            .map_err(std::io::Error::other)?;
        std::fs::rename(&tmp, path)
    }
}

fn to8(c: f32) -> u8 {
    (c.clamp(0.0, 1.0) * 255.0).round() as u8
}

/// The colour scale of depth complexity and differences: black, purple, red, yellow,
/// white, for `t` in [0, 1] (the heatmaps' ramp).
pub fn ramp(t: f32) -> [u8; 3] {
    const STOPS: [[f32; 3]; 5] = [
        [0.1, 0.0, 0.3],
        [0.7, 0.1, 0.4],
        [0.95, 0.4, 0.1],
        [1.0, 0.85, 0.2],
        [1.0, 1.0, 1.0],
    ];
    let x = t.clamp(0.0, 1.0) * (STOPS.len() - 1) as f32;
    let i = (x.floor() as usize).min(STOPS.len() - 2);
    let f = x - i as f32;
    let (a, b) = (STOPS[i], STOPS[i + 1]);
    [0, 1, 2].map(|c| to8(a[c] + (b[c] - a[c]) * f))
}

/// The colour of `count` fragments in a depth-complexity image whose largest count is `max`:
/// black for none, then [`ramp`] from 1 (dark purple) to `max` (white).
pub fn count_color(count: u32, max: u32) -> [u8; 3] {
    if count == 0 {
        BLACK
    } else if max <= 1 {
        ramp(1.0)
    } else {
        ramp((count - 1) as f32 / (max - 1) as f32)
    }
}

/// Pixels of the legend beside a depth-complexity image.
const LEGEND_BAR: u32 = 16;

/// A depth-complexity image (fragments per pixel, row-major, top row first) with a legend
/// bar on its right: the colour scale from 1 (bottom) to the largest count (top), labelled,
/// and black for none.
pub fn depth_complexity(width: u32, height: u32, counts: &[u32]) -> Canvas {
    let max = counts.iter().copied().max().unwrap_or(0);
    let scale = if height >= 160 { 2 } else { 1 };
    let glyph = text::GLYPH * scale;
    let label_w = text::width(&max.max(1).to_string(), scale).max(text::width("0", scale));
    let legend_w = 8 + LEGEND_BAR + 6 + label_w + 8;
    let title = text::wrap("fragments per pixel", 1, label_w + LEGEND_BAR + 6);
    let title_h = title.len() as u32 * (text::GLYPH + 2) + 6;
    let mut c = Canvas::new(width + legend_w, height.max(4 * glyph + title_h), WHITE);
    let img = Canvas {
        width,
        height,
        pixels: counts.iter().map(|&n| count_color(n, max)).collect(),
    };
    c.blit(&img, 0, 0);
    // The bar: 1 at the bottom, max at the top, above a black "0" swatch.
    let (bx, top) = (width + 8, title_h);
    let zero_h = glyph;
    let bar_h = c.height.saturating_sub(top + zero_h + 8 + glyph / 2).max(2);
    for i in 0..bar_h {
        let t = 1.0 - i as f32 / (bar_h - 1).max(1) as f32;
        let n = 1 + (t * (max.max(1) - 1) as f32).round() as u32;
        c.fill(
            i64::from(bx),
            i64::from(top + i),
            LEGEND_BAR,
            1,
            count_color(n, max.max(1)),
        );
    }
    let zero_y = top + bar_h + 4;
    c.fill(i64::from(bx), i64::from(zero_y), LEGEND_BAR, zero_h, BLACK);
    let lx = i64::from(bx + LEGEND_BAR + 6);
    text::draw(
        &mut c,
        lx,
        i64::from(top),
        &max.max(1).to_string(),
        scale,
        INK,
    );
    if max > 2 && bar_h > 3 * glyph {
        let mid = 1 + (max - 1) / 2;
        let t = (mid - 1) as f32 / (max - 1) as f32;
        let y = top + ((1.0 - t) * (bar_h - 1) as f32) as u32;
        text::draw(
            &mut c,
            lx,
            i64::from(y.saturating_sub(glyph / 2)),
            &mid.to_string(),
            scale,
            INK,
        );
    }
    if max > 1 {
        text::draw(&mut c, lx, i64::from(top + bar_h - glyph), "1", scale, INK);
    }
    text::draw(&mut c, lx, i64::from(zero_y), "0", scale, INK);
    for (i, line) in title.iter().enumerate() {
        let y = 3 + i as u32 * (text::GLYPH + 2);
        text::draw(&mut c, i64::from(bx), i64::from(y), line, 1, INK);
    }
    c
}

/// One panel of a side-by-side picture: a title and an image.
pub struct Panel<'a> {
    pub title: &'a str,
    pub image: Canvas,
}

/// Panels side by side, each under its title, on white.
pub fn panels(panels: &[Panel<'_>]) -> Canvas {
    let pw = panels.iter().map(|p| p.image.width).max().unwrap_or(0);
    let ph = panels.iter().map(|p| p.image.height).max().unwrap_or(0);
    let scale = if pw >= 256 { 2 } else { 1 };
    let line_h = text::GLYPH * scale + 2;
    let titles: Vec<Vec<String>> = panels
        .iter()
        // A margin of one glyph: a title that fills its panel's width would run into the
        // next panel's title across the gap.
        .map(|p| text::wrap(p.title, scale, pw.saturating_sub(text::GLYPH * scale)))
        .collect();
    let lines = titles.iter().map(Vec::len).max().unwrap_or(1) as u32;
    let title_h = lines * line_h + 6;
    let gap = 8;
    let n = panels.len() as u32;
    let mut c = Canvas::new(n * pw + (n + 1) * gap, ph + title_h + gap, WHITE);
    for (i, (p, t)) in panels.iter().zip(&titles).enumerate() {
        let x = gap + i as u32 * (pw + gap);
        for (l, line) in t.iter().enumerate() {
            text::draw(
                &mut c,
                i64::from(x),
                4 + i64::from(l as u32 * line_h),
                line,
                scale,
                INK,
            );
        }
        c.blit(&p.image, x, title_h);
    }
    c
}

/// The difference panel of `check`: black where the oracle found no error; at an error
/// pixel, the largest channel difference of the two images on [`ramp`], from a quarter of
/// the way up (a visible purple even when the images agree to the bit: the fragments
/// differ, the composites may not) to white at a difference of 1/4 or more.
pub fn difference(
    width: u32,
    height: u32,
    truth: &[[f32; 4]],
    algo: &[[f32; 4]],
    error_mask: &[bool],
) -> Canvas {
    let pixels = (0..width as usize * height as usize)
        .map(|p| {
            if !error_mask.get(p).copied().unwrap_or(false) {
                return BLACK;
            }
            let d = (0..3)
                .map(|c| (truth[p][c] - algo[p][c]).abs())
                .fold(0.0f32, f32::max);
            ramp(0.25 + 0.75 * (4.0 * d).min(1.0))
        })
        .collect();
    Canvas {
        width,
        height,
        pixels,
    }
}

/// `check`'s picture: the truth's image, the algorithm's, and their [`difference`], titled.
pub fn compare(
    width: u32,
    height: u32,
    truth: &[[f32; 4]],
    algo: &[[f32; 4]],
    error_mask: &[bool],
    titles: [&str; 3],
) -> Canvas {
    panels(&[
        Panel {
            title: titles[0],
            image: Canvas::from_rgba(width, height, truth),
        },
        Panel {
            title: titles[1],
            image: Canvas::from_rgba(width, height, algo),
        },
        Panel {
            title: titles[2],
            image: difference(width, height, truth, algo, error_mask),
        },
    ])
}
