//! `--turntable N`: N views around the scene (the camera's azimuth stepped by 360/N degrees),
//! written as one animated GIF (a path ending in `.gif`) or as numbered PNGs
//! (`NAME-000.png`, `NAME-001.png`, ... beside the path given), both encoded by the `image`
//! crate. Hazards that depend on the view show as they come and go.

use std::path::{Path, PathBuf};

use super::picture::Canvas;
use super::RenderError;

/// The azimuths (degrees) of `n` views starting at `start`, evenly around the circle.
pub fn azimuths(start: f32, n: u32) -> Vec<f32> {
    (0..n)
        .map(|i| start + 360.0 * i as f32 / n as f32)
        .collect()
}

/// Whether `path` asks for an animated GIF (else numbered PNGs).
pub fn is_gif(path: &Path) -> bool {
    path.extension()
        .is_some_and(|e| e.eq_ignore_ascii_case("gif"))
}

/// The file of frame `i` when frames are numbered PNGs: `DIR/STEM-iii.png`.
pub fn frame_path(path: &Path, i: usize) -> PathBuf {
    let stem = path
        .file_stem()
        .map(|s| s.to_string_lossy().into_owned())
        .unwrap_or_else(|| "frame".into());
    path.with_file_name(format!("{stem}-{i:03}.png"))
}

/// Writes `frames` as an animated GIF (looping, `delay_ms` per frame) or numbered PNGs, as
/// [`is_gif`] says; returns the files written.
pub fn write(path: &Path, frames: &[Canvas], delay_ms: u32) -> Result<Vec<PathBuf>, RenderError> {
    let io = |path: &Path| {
        let path = path.to_path_buf();
        move |source| RenderError::Io { path, source }
    };
    if is_gif(path) {
        let tmp = path.with_extension("gif.tmp");
        {
            let file = std::fs::File::create(&tmp).map_err(io(path))?;
            let mut enc =
                image::codecs::gif::GifEncoder::new_with_speed(std::io::BufWriter::new(file), 10);
            enc.set_repeat(image::codecs::gif::Repeat::Infinite)
                .map_err(|e| io(path)(std::io::Error::other(e)))?;
            let delay = image::Delay::from_numer_denom_ms(delay_ms, 1);
            for f in frames {
                enc.encode_frame(image::Frame::from_parts(f.to_image(), 0, 0, delay))
                    .map_err(|e| io(path)(std::io::Error::other(e)))?;
            }
        }
        std::fs::rename(&tmp, path).map_err(io(path))?;
        Ok(vec![path.to_path_buf()])
    } else {
        let mut written = Vec::with_capacity(frames.len());
        for (i, f) in frames.iter().enumerate() {
            let p = frame_path(path, i);
            f.write_png(&p).map_err(io(&p))?;
            written.push(p);
        }
        Ok(written)
    }
}
