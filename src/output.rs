//! Pictures: RGBA images, per-pixel heatmaps (depth complexity, errors, hazards), written
//! as PNG atomically (a temporary file renamed into place).

use std::path::Path;

/// Writes an RGBA float image (row-major, top row first) as an 8-bit PNG.
pub fn write_rgba(
    path: &Path,
    width: u32,
    height: u32,
    pixels: &[[f32; 4]],
) -> std::io::Result<()> {
    let mut buf = Vec::with_capacity(pixels.len() * 4);
    for p in pixels {
        for c in p.iter().take(3) {
            buf.push((c.clamp(0.0, 1.0) * 255.0).round() as u8);
        }
        buf.push(255);
    }
    write_png(path, width, height, buf)
}

/// A heatmap of per-pixel values: 0 is black, the maximum white-hot (inferno-like ramp).
pub fn write_heatmap(path: &Path, width: u32, height: u32, values: &[u32]) -> std::io::Result<()> {
    let max = values.iter().copied().max().unwrap_or(0).max(1) as f32;
    let mut buf = Vec::with_capacity(values.len() * 4);
    for &v in values {
        let t = v as f32 / max;
        let c = if v == 0 { [0.0, 0.0, 0.0] } else { ramp(t) };
        buf.extend(c.iter().map(|x| (x * 255.0).round() as u8));
        buf.push(255);
    }
    write_png(path, width, height, buf)
}

/// Black -> purple -> red -> yellow -> white.
fn ramp(t: f32) -> [f32; 3] {
    let stops = [
        [0.1, 0.0, 0.3],
        [0.7, 0.1, 0.4],
        [0.95, 0.4, 0.1],
        [1.0, 0.85, 0.2],
        [1.0, 1.0, 1.0],
    ];
    let x = t.clamp(0.0, 1.0) * (stops.len() - 1) as f32;
    let i = (x.floor() as usize).min(stops.len() - 2);
    let f = x - i as f32;
    let (a, b) = (stops[i], stops[i + 1]);
    [
        a[0] + (b[0] - a[0]) * f,
        a[1] + (b[1] - a[1]) * f,
        a[2] + (b[2] - a[2]) * f,
    ]
}

fn write_png(path: &Path, width: u32, height: u32, rgba: Vec<u8>) -> std::io::Result<()> {
    let img = image::RgbaImage::from_raw(width, height, rgba)
        .ok_or_else(|| std::io::Error::other("image buffer does not match its size"))?;
    let tmp = path.with_extension("png.tmp");
    img.save_with_format(&tmp, image::ImageFormat::Png)
        .map_err(std::io::Error::other)?;
    std::fs::rename(&tmp, path)
}

/// Writes bytes atomically: a temporary file in the same directory, synced, then renamed.
pub fn write_atomic(path: &Path, bytes: &[u8]) -> std::io::Result<()> {
    use std::io::Write;
    let tmp = path.with_extension(format!("{}.tmp", std::process::id()));
    {
        let mut f = std::fs::File::create(&tmp)?;
        f.write_all(bytes)?;
        f.sync_all()?;
    }
    std::fs::rename(&tmp, path)
}

/// A line plot of several series over the same x (0..n), as a PNG (no plotting crate: axes,
/// one colour per series, a legend of coloured swatches in series order).
pub fn write_plot(path: &Path, _title: &str, series: &[(String, Vec<f64>)]) -> std::io::Result<()> {
    let (w, h) = (800u32, 400u32);
    let (ml, mr, mt, mb) = (40i64, 150i64, 20i64, 30i64);
    let mut buf = vec![255u8; (w * h * 4) as usize];
    let mut put = |x: i64, y: i64, c: [u8; 3]| {
        if x >= 0 && y >= 0 && (x as u32) < w && (y as u32) < h {
            let i = ((y as u32 * w + x as u32) * 4) as usize;
            buf[i..i + 3].copy_from_slice(&c);
        }
    };
    let (pw, ph) = (w as i64 - ml - mr, h as i64 - mt - mb);
    for x in 0..=pw {
        put(ml + x, mt + ph, [0, 0, 0]);
    }
    for y in 0..=ph {
        put(ml, mt + y, [0, 0, 0]);
    }
    let ymax = series
        .iter()
        .flat_map(|s| s.1.iter().copied())
        .fold(0.0f64, f64::max)
        .max(1e-9);
    let palette = [
        [228, 26, 28],
        [55, 126, 184],
        [77, 175, 74],
        [152, 78, 163],
        [255, 127, 0],
        [166, 86, 40],
        [247, 129, 191],
        [153, 153, 153],
    ];
    for (si, (_, ys)) in series.iter().enumerate() {
        let c = palette[si % palette.len()];
        let n = ys.len().max(2) - 1;
        let pt = |i: usize| {
            (
                ml + (i as i64 * pw) / n as i64,
                mt + ph - ((ys[i] / ymax) * ph as f64) as i64,
            )
        };
        for i in 1..ys.len() {
            let (a, b) = (pt(i - 1), pt(i));
            let steps = (b.0 - a.0).abs().max((b.1 - a.1).abs()).max(1);
            for t in 0..=steps {
                put(
                    a.0 + (b.0 - a.0) * t / steps,
                    a.1 + (b.1 - a.1) * t / steps,
                    c,
                );
            }
        }
        for dy in 0..8 {
            for dx in 0..20 {
                put(w as i64 - mr + 10 + dx, mt + 14 * si as i64 + dy, c);
            }
        }
    }
    write_png(path, w, h, buf)
}

/// An output that cannot be written, named.
#[derive(Debug, thiserror::Error)]
#[error("{}: cannot write {what} there: {cause}", path.display())]
pub struct OutputError {
    pub path: std::path::PathBuf,
    pub what: &'static str,
    pub cause: std::io::Error,
}

/// Checks, before any computation, that a file can be written at `path` (its directory
/// exists and takes a new file), by creating and removing a probe file beside it.
pub fn check_writable(path: &Path, what: &'static str) -> Result<(), OutputError> {
    let err = |cause| OutputError {
        path: path.to_path_buf(),
        what,
        cause,
    };
    if path.is_dir() {
        return Err(err(std::io::Error::other("it is a directory")));
    }
    let dir = match path.parent() {
        Some(d) if !d.as_os_str().is_empty() => d,
        _ => Path::new("."),
    };
    probe(dir).map_err(err)
}

/// Checks, before any computation, that files can be written in directory `dir` (created
/// if missing).
pub fn check_dir(dir: &Path, what: &'static str) -> Result<(), OutputError> {
    let err = |cause| OutputError {
        path: dir.to_path_buf(),
        what,
        cause,
    };
    std::fs::create_dir_all(dir).map_err(err)?;
    probe(dir).map_err(err)
}

fn probe(dir: &Path) -> std::io::Result<()> {
    let p = dir.join(format!(".fragrace-probe-{}", std::process::id()));
    std::fs::File::create(&p)?;
    std::fs::remove_file(&p)
}
