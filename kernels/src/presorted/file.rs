//! The stored result of preprocessing: segments, test planes and the mesh's hash, so that
//! preprocessing happens once per mesh.
//!
//! Little-endian binary: magic `FRPRESRT`, version, mesh hash, triangle count, the
//! normalized frame, the face normals, the pieces (input triangle and clip planes; the
//! input triangles themselves unless some crossed), then per
//! segment its instances (piece, flags, test planes), and last an FNV-1a checksum of everything before it. Written to a
//! temporary file in the same directory, flushed to disk, then renamed over the target:
//! an interrupted run leaves at most a temporary file, never a truncated file under the
//! target's name, and a truncated or altered file fails the checksum. A file made for
//! another mesh is refused by its hash.

use std::io::Write;
use std::path::{Path, PathBuf};

use fragrace_emu::Mesh;
use glam::DVec3;

use super::input::mesh_hash;
use super::{Frame3, Instance, Piece, Presorted, Segment, WorldClip};

const MAGIC: &[u8; 8] = b"FRPRESRT";
const VERSION: u32 = 3;

/// Why a stored result cannot be used.
#[derive(Debug, thiserror::Error)]
pub enum FileError {
    #[error("{path}: {source}")]
    Io {
        path: PathBuf,
        source: std::io::Error,
    },
    #[error(
        "{path}: not a presorted-lists file (bad magic or version {version}, expected {VERSION})"
    )]
    Format { path: PathBuf, version: u32 },
    #[error("{path}: truncated or corrupted ({what})")]
    Corrupt { path: PathBuf, what: String },
    #[error(
        "{path} was made for another mesh (mesh hash {stored:016x}, {stored_tris} triangles; \
         this mesh hashes to {actual:016x}, {actual_tris} triangles): run `presort` on this mesh"
    )]
    Mismatch {
        path: PathBuf,
        stored: u64,
        actual: u64,
        stored_tris: u32,
        actual_tris: u32,
    },
}

pub(super) fn fnv(bytes: &[u8]) -> u64 {
    let mut h: u64 = 0xcbf2_9ce4_8422_2325;
    for &b in bytes {
        h ^= u64::from(b);
        h = h.wrapping_mul(0x0000_0100_0000_01b3);
    }
    h
}

/// The file's bytes.
pub fn encode(p: &Presorted) -> Vec<u8> {
    let mut b: Vec<u8> = Vec::new();
    b.extend_from_slice(MAGIC);
    b.extend_from_slice(&VERSION.to_le_bytes());
    b.extend_from_slice(&p.mesh_hash.to_le_bytes());
    b.extend_from_slice(&p.triangles.to_le_bytes());
    for c in p.frame.center.to_array() {
        b.extend_from_slice(&c.to_le_bytes());
    }
    b.extend_from_slice(&p.frame.radius.to_le_bytes());
    b.extend_from_slice(&(p.dirs.len() as u32).to_le_bytes());
    for d in &p.dirs {
        for c in d.to_array() {
            b.extend_from_slice(&c.to_le_bytes());
        }
    }
    b.extend_from_slice(&(p.pieces.len() as u32).to_le_bytes());
    for pc in &p.pieces {
        b.extend_from_slice(&pc.tri.to_le_bytes());
        b.extend_from_slice(&(pc.clips.len() as u32).to_le_bytes());
        for c in &pc.clips {
            for x in c.plane {
                b.extend_from_slice(&x.to_le_bytes());
            }
            b.extend_from_slice(&u32::from(c.nonneg).to_le_bytes());
        }
    }
    for s in &p.segments {
        encode_segment(s, &mut b);
    }
    let sum = fnv(&b);
    b.extend_from_slice(&sum.to_le_bytes());
    b
}

/// Appends a segment's bytes: its instance count, then per instance its piece, flags
/// (back, last) and test planes.
pub(super) fn encode_segment(s: &Segment, b: &mut Vec<u8>) {
    b.extend_from_slice(&(s.instances.len() as u32).to_le_bytes());
    for i in &s.instances {
        b.extend_from_slice(&i.piece.to_le_bytes());
        let flags = u32::from(i.back) | (u32::from(i.last) << 1);
        b.extend_from_slice(&flags.to_le_bytes());
        b.extend_from_slice(&(i.planes.len() as u32).to_le_bytes());
        for pl in &i.planes {
            for c in pl {
                b.extend_from_slice(&c.to_le_bytes());
            }
        }
    }
}

/// Whether `path` names a gzip file (ends in `.gz`): [`save`] compresses it.
fn is_gz_name(path: &Path) -> bool {
    path.extension()
        .is_some_and(|e| e.eq_ignore_ascii_case("gz"))
}

/// The most bytes a gzip-compressed file may expand to (1 GiB): far above any mesh this
/// tool presorts (the 4K-triangle bunny's lists take 1.1 MB), and a bound on what a corrupt
/// or hostile file can make [`load`] allocate.
pub const MAX_EXPANDED: u64 = 1 << 30;

/// The file's bytes: as stored, or expanded when they start with gzip's magic number.
fn read_bytes(path: &Path) -> Result<Vec<u8>, FileError> {
    use std::io::Read as _;
    let io = |source| FileError::Io {
        path: path.to_path_buf(),
        source,
    };
    let stored = std::fs::read(path).map_err(io)?;
    if !stored.starts_with(&[0x1f, 0x8b]) {
        return Ok(stored);
    }
    let mut bytes = Vec::new();
    flate2::read::GzDecoder::new(stored.as_slice())
        .take(MAX_EXPANDED + 1)
        .read_to_end(&mut bytes)
        .map_err(|e| FileError::Corrupt {
            path: path.to_path_buf(),
            what: format!("gzip: {e}"),
        })?;
    if bytes.len() as u64 > MAX_EXPANDED {
        return Err(FileError::Corrupt {
            path: path.to_path_buf(),
            what: format!("expands past {MAX_EXPANDED} bytes"),
        });
    }
    Ok(bytes)
}

/// Writes `p` to `path` atomically (temporary file, sync, rename), gzip-compressed when
/// `path` ends in `.gz` ([`load`] reads both).
pub fn save(p: &Presorted, path: &Path) -> Result<(), FileError> {
    let io = |source| FileError::Io {
        path: path.to_path_buf(),
        source,
    };
    let bytes = if is_gz_name(path) {
        let mut gz = flate2::write::GzEncoder::new(Vec::new(), flate2::Compression::best());
        gz.write_all(&encode(p)).map_err(io)?;
        gz.finish().map_err(io)?
    } else {
        encode(p)
    };
    write_atomic(path, &bytes)
}

/// Writes `bytes` to `path` atomically: a temporary file in the same directory, synced,
/// then renamed over `path` (an interrupted write leaves at most the temporary file).
pub(super) fn write_atomic(path: &Path, bytes: &[u8]) -> Result<(), FileError> {
    let io = |source| FileError::Io {
        path: path.to_path_buf(),
        source,
    };
    let name = path
        .file_name()
        .map(|n| n.to_string_lossy().into_owned())
        .unwrap_or_default();
    let tmp = path.with_file_name(format!(".{name}.tmp-{}", std::process::id()));
    let write = || -> std::io::Result<()> {
        let mut f = std::fs::File::create(&tmp)?;
        f.write_all(bytes)?;
        f.sync_all()?;
        std::fs::rename(&tmp, path)
    };
    write().map_err(|e| {
        let _ = std::fs::remove_file(&tmp);
        io(e)
    })
}

pub(super) struct Reader<'a> {
    b: &'a [u8],
    at: usize,
    path: &'a Path,
}

impl<'a> Reader<'a> {
    pub(super) fn new(b: &'a [u8], at: usize, path: &'a Path) -> Reader<'a> {
        Reader { b, at, path }
    }
    /// Bytes read so far.
    pub(super) fn at(&self) -> usize {
        self.at
    }
    fn take(&mut self, n: usize) -> Result<&[u8], FileError> {
        let end = self.at.checked_add(n).filter(|&e| e <= self.b.len());
        let Some(end) = end else {
            return Err(FileError::Corrupt {
                path: self.path.to_path_buf(),
                what: format!("ends at byte {} reading {n} more", self.b.len()),
            });
        };
        let s = &self.b[self.at..end];
        self.at = end;
        Ok(s)
    }
    pub(super) fn u32(&mut self) -> Result<u32, FileError> {
        Ok(u32::from_le_bytes(
            self.take(4)?.try_into().expect("4 bytes"),
        ))
    }
    pub(super) fn u64(&mut self) -> Result<u64, FileError> {
        Ok(u64::from_le_bytes(
            self.take(8)?.try_into().expect("8 bytes"),
        ))
    }
    fn f64(&mut self) -> Result<f64, FileError> {
        Ok(f64::from_bits(self.u64()?))
    }
    fn f32(&mut self) -> Result<f32, FileError> {
        Ok(f32::from_bits(self.u32()?))
    }

    /// A segment ([`encode_segment`]) of pieces below `npieces`.
    pub(super) fn segment(&mut self, npieces: u32) -> Result<Segment, FileError> {
        let n = self.u32()? as usize;
        let mut instances = Vec::with_capacity(n.min(self.b.len() / 12));
        for _ in 0..n {
            let piece = self.u32()?;
            if piece >= npieces {
                return Err(FileError::Corrupt {
                    path: self.path.to_path_buf(),
                    what: format!("piece {piece} of {npieces}"),
                });
            }
            let flags = self.u32()?;
            let np = self.u32()? as usize;
            let mut planes = Vec::with_capacity(np.min(64));
            for _ in 0..np {
                planes.push([self.f32()?, self.f32()?, self.f32()?, self.f32()?]);
            }
            instances.push(Instance {
                piece,
                back: flags & 1 != 0,
                last: flags & 2 != 0,
                planes,
            });
        }
        Ok(Segment { instances })
    }
}

/// Decodes a file's bytes (no mesh check).
pub fn decode(bytes: &[u8], path: &Path) -> Result<Presorted, FileError> {
    let corrupt = |what: String| FileError::Corrupt {
        path: path.to_path_buf(),
        what,
    };
    if bytes.len() < 12 || &bytes[..8] != MAGIC {
        return Err(FileError::Format {
            path: path.to_path_buf(),
            version: 0,
        });
    }
    let (body, sum) = bytes.split_at(bytes.len().saturating_sub(8).max(12));
    let mut r = Reader {
        b: body,
        at: 8,
        path,
    };
    let version = r.u32()?;
    if version != VERSION {
        return Err(FileError::Format {
            path: path.to_path_buf(),
            version,
        });
    }
    if sum.len() != 8 || fnv(body) != u64::from_le_bytes(sum.try_into().expect("8 bytes")) {
        return Err(corrupt("checksum mismatch".into()));
    }
    let mesh_hash = r.u64()?;
    let triangles = r.u32()?;
    let center = DVec3::new(r.f64()?, r.f64()?, r.f64()?);
    let radius = r.f64()?;
    let nd = r.u32()? as usize;
    if !super::partition::FACE_COUNTS.contains(&(nd as u32)) {
        return Err(corrupt(format!("{nd} partitions")));
    }
    let mut dirs = Vec::with_capacity(nd);
    for _ in 0..nd {
        dirs.push(DVec3::new(r.f64()?, r.f64()?, r.f64()?));
    }
    let npieces = r.u32()?;
    let mut pieces = Vec::with_capacity((npieces as usize).min(body.len() / 8));
    for _ in 0..npieces {
        let tri = r.u32()?;
        if tri >= triangles {
            return Err(corrupt(format!("piece of triangle {tri} of {triangles}")));
        }
        let nc = r.u32()? as usize;
        let mut clips = Vec::with_capacity(nc.min(64));
        for _ in 0..nc {
            let plane = [r.f32()?, r.f32()?, r.f32()?, r.f32()?];
            let nonneg = match r.u32()? {
                0 => false,
                1 => true,
                v => return Err(corrupt(format!("clip side {v} (0 or 1)"))),
            };
            clips.push(WorldClip { plane, nonneg });
        }
        pieces.push(Piece { tri, clips });
    }
    let mut segments = Vec::with_capacity(nd);
    for _ in 0..nd {
        segments.push(r.segment(npieces)?);
    }
    if r.at != body.len() {
        return Err(corrupt(format!("{} trailing bytes", body.len() - r.at)));
    }
    Ok(Presorted {
        mesh_hash,
        triangles,
        pieces,
        frame: Frame3 { center, radius },
        dirs,
        segments,
        stats: Vec::new(),
        split: Default::default(),
    })
}

/// Reads `path` (plain or gzip-compressed, up to [`MAX_EXPANDED`] bytes expanded) and
/// checks that it was made from `mesh`.
pub fn load(path: &Path, mesh: &Mesh) -> Result<Presorted, FileError> {
    let bytes = read_bytes(path)?;
    let p = decode(&bytes, path)?;
    let actual = mesh_hash(mesh);
    if p.mesh_hash != actual || p.triangles as usize != mesh.indices.len() {
        return Err(FileError::Mismatch {
            path: path.to_path_buf(),
            stored: p.mesh_hash,
            actual,
            stored_tris: p.triangles,
            actual_tris: mesh.indices.len() as u32,
        });
    }
    Ok(p)
}
