//! Text in pictures (panel titles, legend labels): the public-domain 8x8 bitmap font of the
//! `font8x8` crate, ASCII only, scaled by whole pixels.

use super::picture::Canvas;

/// Width and height of a glyph at scale 1, in pixels.
pub const GLYPH: u32 = 8;

/// The width in pixels of `text` at `scale`.
pub fn width(text: &str, scale: u32) -> u32 {
    text.chars().count() as u32 * GLYPH * scale
}

/// Draws `text` with its top left corner at `(x, y)`, each glyph pixel a `scale` x `scale`
/// square of `color`; characters outside ASCII are drawn as `?`, pixels outside the canvas
/// are left out.
pub fn draw(canvas: &mut Canvas, x: i64, y: i64, text: &str, scale: u32, color: [u8; 3]) {
    let s = i64::from(scale);
    for (i, ch) in text.chars().enumerate() {
        let code = if ch.is_ascii() {
            ch as usize
        } else {
            '?' as usize
        };
        let glyph = font8x8::legacy::BASIC_LEGACY[code];
        let gx = x + i as i64 * 8 * s;
        for (row, bits) in glyph.iter().enumerate() {
            for col in 0..8 {
                // Bit 0 is the leftmost pixel.
                if bits & (1 << col) != 0 {
                    canvas.fill(gx + col * s, y + row as i64 * s, scale, scale, color);
                }
            }
        }
    }
}

/// `text` cut (with `...`) to fit `max_width` pixels at `scale`.
pub fn fit(text: &str, scale: u32, max_width: u32) -> String {
    let fits = (max_width / (GLYPH * scale)) as usize;
    if text.chars().count() <= fits {
        text.to_string()
    } else if fits > 3 {
        let mut s: String = text.chars().take(fits - 3).collect();
        s.push_str("...");
        s
    } else {
        text.chars().take(fits).collect()
    }
}

/// `text` broken at spaces into lines of at most `max_width` pixels at `scale` (a word
/// longer than a line is cut by [`fit`]).
pub fn wrap(text: &str, scale: u32, max_width: u32) -> Vec<String> {
    let fits = (max_width / (GLYPH * scale)).max(1) as usize;
    let mut lines: Vec<String> = Vec::new();
    let mut line = String::new();
    for word in text.split(' ') {
        let len = line.chars().count();
        if len > 0 && len + 1 + word.chars().count() > fits {
            lines.push(std::mem::take(&mut line));
        }
        if !line.is_empty() {
            line.push(' ');
        }
        line.push_str(word);
    }
    if !line.is_empty() || lines.is_empty() {
        lines.push(line);
    }
    lines.iter().map(|l| fit(l, scale, max_width)).collect()
}
