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
