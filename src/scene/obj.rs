//! Wavefront OBJ input (plain or gzip), robust against any byte input.
//!
//! Parsing is done by `tobj`, after a pre-pass of ours over the text. The pre-pass exists
//! because `tobj` alone is not enough for this project:
//! - its errors carry no line number, and it reports a bad face index only as "out of
//!   bounds"; the pre-pass checks vertex lines and face indices first and says where;
//! - it renumbers vertices in order of first use and drops unreferenced ones; `oit.py` (the
//!   llvmpipe reference) keeps file order and normalises over *all* vertices, so the pre-pass
//!   makes `tobj` keep file order (see [`parse_obj_bytes`]), which keeps bounds, radius and
//!   camera identical to the reference's;
//! - texture and normal indices are not used (a fragment's colour comes from its primitive
//!   id), and `tobj` can overflow on absurd ones (`f 1/-9999999999999999999/1`), a panic in
//!   a debug or fuzz build; the pre-pass keeps only the position index of each face vertex.
//!
//! Groups, objects, smoothing groups, texture coordinates, lines and points are ignored; all
//! faces go into one mesh in file order, polygons triangulated as fans `(v0, vi, vi+1)`, so
//! triangle `i` has the primitive id `oit.py` gives it. What the renderer needs besides
//! positions, the `vn` normals, `usemtl` materials and `mtllib` files, is gathered by the same
//! pre-pass into [`ObjExtras`] ([`load_obj_with_extras`]), apart from the [`Mesh`], which
//! stays the peer's.

use std::borrow::Cow;
use std::fmt::Write as _;
use std::io::Read;
use std::path::Path;

use fragrace_emu::geometry::{Mesh, MeshError};
use glam::Vec3;
use sha2::{Digest, Sha256};

use super::SceneError;

/// The first two bytes of every gzip member (RFC 1952).
const GZIP_MAGIC: [u8; 2] = [0x1f, 0x8b];

/// The "path" in the errors of [`parse_obj_bytes`], which has no file.
const MEMORY: &str = "<memory>";

/// The mesh as OBJ text: `v` lines in order (every vertex, used or not: loading normalises
/// over all of them) with the shortest floats that read back to the same `f32`, then 1-based
/// `f` lines. [`parse_obj_bytes`] reads it back to the same mesh.
pub fn obj_text(mesh: &Mesh) -> String {
    let mut s = String::new();
    for p in &mesh.positions {
        let _ = writeln!(s, "v {} {} {}", p.x, p.y, p.z);
    }
    for t in &mesh.indices {
        let _ = writeln!(s, "f {} {} {}", t[0] + 1, t[1] + 1, t[2] + 1);
    }
    s
}

/// Whether `bytes` start like gzip data. Detection is by content, not by file name, so that
/// a gzip file without `.gz` (or fetched to a temporary name) still loads.
pub fn is_gzip(bytes: &[u8]) -> bool {
    bytes.starts_with(&GZIP_MAGIC)
}

/// SHA-256 (lowercase hex) of a file's raw bytes, as stored in case files next to the mesh
/// path so that a replay can tell it is looking at the same model.
pub fn content_hash(bytes: &[u8]) -> String {
    Sha256::digest(bytes)
        .iter()
        .fold(String::with_capacity(64), |mut s, b| {
            let _ = write!(s, "{b:02x}");
            s
        })
}

/// Loads an OBJ file, plain or gzip (detected by its magic bytes). A name ending in `.gz`
/// whose data is not gzip is an error: it is almost always a broken download.
pub fn load_obj(path: impl AsRef<Path>) -> Result<Mesh, SceneError> {
    load_obj_with_hash(path).map(|(mesh, _)| mesh)
}

/// [`load_obj`] and the [`content_hash`] of the file's bytes, reading the file once.
pub fn load_obj_with_hash(path: impl AsRef<Path>) -> Result<(Mesh, String), SceneError> {
    load_obj_with_extras(path).map(|(mesh, _, hash)| (mesh, hash))
}

/// [`load_obj_with_hash`] and what the renderer reads besides positions ([`ObjExtras`]).
pub fn load_obj_with_extras(
    path: impl AsRef<Path>,
) -> Result<(Mesh, ObjExtras, String), SceneError> {
    let path = path.as_ref();
    let bytes = std::fs::read(path).map_err(|source| match source.kind() {
        std::io::ErrorKind::NotFound => SceneError::NotFound {
            path: path.to_owned(),
        },
        _ => SceneError::Io {
            path: path.to_owned(),
            source,
        },
    })?;
    let named_gz = path
        .extension()
        .is_some_and(|e| e.eq_ignore_ascii_case("gz"));
    if named_gz && !is_gzip(&bytes) {
        return Err(SceneError::NotGzip {
            path: path.to_owned(),
        });
    }
    let (mesh, extras) = parse(&bytes, path)?;
    Ok((mesh, extras, content_hash(&bytes)))
}

/// Parses OBJ data (plain or gzip) from memory. Never panics, whatever the bytes: this is
/// the entry point of the OBJ fuzz target. Errors name the source `<memory>`.
pub fn parse_obj_bytes(bytes: &[u8]) -> Result<Mesh, SceneError> {
    parse(bytes, Path::new(MEMORY)).map(|(mesh, _)| mesh)
}

/// [`parse_obj_bytes`] with the [`ObjExtras`] (normals, materials) of the data.
pub fn parse_obj_bytes_with_extras(bytes: &[u8]) -> Result<(Mesh, ObjExtras), SceneError> {
    parse(bytes, Path::new(MEMORY))
}

fn parse(bytes: &[u8], path: &Path) -> Result<(Mesh, ObjExtras), SceneError> {
    let data: Cow<[u8]> = if is_gzip(bytes) {
        let mut out = Vec::new();
        flate2::read::MultiGzDecoder::new(bytes)
            .read_to_end(&mut out)
            .map_err(|source| SceneError::CorruptGzip {
                path: path.to_owned(),
                source,
            })?;
        Cow::Owned(out)
    } else {
        Cow::Borrowed(bytes)
    };
    // Lossy: a stray Latin-1 byte in a comment or group name must not reject a model; a bad
    // byte inside a number still fails that number's parse, with its line.
    let text = String::from_utf8_lossy(&data);
    // A UTF-8 byte order mark would hide the first line's keyword.
    let mut pre = prepass(text.strip_prefix('\u{feff}').unwrap_or(&text), path)?;
    if pre.faces == 0 {
        return Err(SceneError::EmptyMesh {
            name: path.display().to_string(),
        });
    }
    let (models, _materials) =
        tobj::load_obj_buf(&mut pre.text.as_bytes(), &tobj::GPU_LOAD_OPTIONS, |_| {
            Err(tobj::LoadError::OpenFileFailed)
        })
        .map_err(|source| SceneError::Obj {
            path: path.to_owned(),
            source,
        })?;
    let mesh = assemble(&models, pre.vertices, path)?;
    mesh.validate().map_err(|e| match e {
        // Unreachable after the pre-pass (which checks every coordinate with its line), kept
        // so that a disagreement with tobj is an error, not a NaN on screen.
        MeshError::NonFinite { index, value } => SceneError::NonFiniteVertex {
            path: path.to_owned(),
            line: 0,
            vertex: index + 1,
            value,
        },
        source => SceneError::InvalidMesh {
            name: path.display().to_string(),
            source,
        },
    })?;
    if mesh.indices.is_empty() {
        return Err(SceneError::EmptyMesh {
            name: path.display().to_string(),
        });
    }
    let extras = std::mem::take(&mut pre.extras).finish(mesh.indices.len(), path);
    Ok((mesh, extras))
}

/// The text handed to tobj: only `v` lines (colours dropped) and `f` lines with absolute,
/// checked, position-only indices, preceded by one "identity" polygon `f 1 2 ... n`.
struct Prepass {
    text: String,
    /// Number of `v` lines.
    vertices: usize,
    /// Number of faces with at least three vertices (not counting the identity polygon).
    faces: usize,
    extras: ExtrasBuilder,
}

/// What an OBJ file says besides its triangles' positions: shading normals (`vn`), each
/// triangle's material (`usemtl`) and the material libraries (`mtllib`) to read them from.
/// Never a reason to refuse a file: what is unusable is left out with a warning.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct ObjExtras {
    /// The file's `vn` normals and, per triangle, the normal of each corner; `None` when
    /// the file has none (or unusable ones, with a warning).
    pub normals: Option<(Vec<Vec3>, Vec<[u32; 3]>)>,
    /// Per triangle, an index into `material_names`, or `u32::MAX` before any `usemtl`.
    pub triangle_material: Vec<u32>,
    /// The names given to `usemtl`, in order of first use.
    pub material_names: Vec<String>,
    /// The files named by `mtllib` lines, as written (relative to the OBJ's folder).
    pub mtllibs: Vec<String>,
    /// What was left out, and why.
    pub warnings: Vec<String>,
}

/// [`ObjExtras`] as the pre-pass gathers them.
#[derive(Default)]
struct ExtrasBuilder {
    normals: Vec<Vec3>,
    /// Per triangle, the `vn` index (from 1; 0: none) of each corner.
    corners: Vec<[u32; 3]>,
    triangle_material: Vec<u32>,
    material_names: Vec<String>,
    current_material: u32,
    mtllibs: Vec<String>,
    /// The first reason the normals cannot be used (with its line).
    bad_normals: Option<String>,
}

impl ExtrasBuilder {
    fn finish(self, triangles: usize, path: &Path) -> ObjExtras {
        let mut warnings = Vec::new();
        let with_normals = self.corners.iter().filter(|c| c[0] != 0).count();
        let mut bad = self.bad_normals;
        let defined = self.normals.len() as u32;
        if bad.is_none() && self.corners.iter().flatten().any(|&i| i > defined) {
            bad = Some(format!("a face names a normal past the {defined} defined"));
        }
        if bad.is_none() && with_normals > 0 && with_normals < self.corners.len() {
            bad = Some(format!(
                "{with_normals} of {} triangles have vn normals",
                self.corners.len()
            ));
        }
        let normals = match bad {
            Some(why) => {
                warnings.push(format!(
                    "{}: vn normals not used ({why}); smooth normals are computed instead",
                    path.display()
                ));
                None
            }
            None if with_normals > 0 && self.corners.len() == triangles => Some((
                self.normals,
                self.corners
                    .iter()
                    .map(|c| c.map(|i| i - 1))
                    .collect::<Vec<_>>(),
            )),
            None => None,
        };
        let mut triangle_material = self.triangle_material;
        if triangle_material.len() != triangles {
            warnings.push(format!(
                "{}: usemtl materials not used (faces and triangles disagree); one default material",
                path.display()
            ));
            triangle_material = vec![u32::MAX; triangles];
        }
        ObjExtras {
            normals,
            triangle_material,
            material_names: self.material_names,
            mtllibs: self.mtllibs,
            warnings,
        }
    }
}

/// The identity polygon's vertices: `1..=n`, padded to three by repeating the last one.
fn identity_polygon(vertices: usize) -> impl Iterator<Item = usize> {
    (1..=vertices.max(3)).map(move |i| i.min(vertices))
}

fn prepass(text: &str, path: &Path) -> Result<Prepass, SceneError> {
    let malformed = |line: usize, reason: String| SceneError::MalformedObj {
        path: path.to_owned(),
        line,
        reason,
    };
    let mut vlines = String::new();
    let mut flines = String::new();
    let mut vertices = 0usize;
    let mut faces = 0usize;
    // Positive indices may refer forward (tobj and oit.py both allow it): the largest one
    // and its line are checked at the end.
    let (mut max_index, mut max_line) = (0usize, 0usize);
    let mut face = Vec::new();
    let mut face_normals: Vec<u32> = Vec::new();
    let mut ex = ExtrasBuilder {
        current_material: u32::MAX,
        ..ExtrasBuilder::default()
    };
    for (n, line) in text.lines().enumerate() {
        let lineno = n + 1;
        let mut words = line.split_whitespace();
        match words.next() {
            Some("v") => {
                // Up to 7 words are kept: more is an error whatever they are.
                let mut words_buf = [""; 7];
                let mut count = 0;
                for w in words {
                    if count < words_buf.len() {
                        words_buf[count] = w;
                    }
                    count += 1;
                }
                let words = &words_buf[..count.min(words_buf.len())];
                let coord = |i: usize| -> Result<f32, SceneError> {
                    words[i].parse::<f32>().map_err(|_| {
                        malformed(lineno, format!("bad vertex coordinate {:?}", words[i]))
                    })
                };
                if count < 3 {
                    return Err(malformed(
                        lineno,
                        format!("a vertex needs 3 coordinates, found {count}"),
                    ));
                }
                let mut p = [coord(0)?, coord(1)?, coord(2)?];
                let kept = match count {
                    3 => 3,
                    4 => {
                        // Homogeneous w, divided out as tobj does.
                        let w = coord(3)?;
                        if w == 0.0 {
                            return Err(malformed(lineno, "vertex weight w is 0".into()));
                        }
                        p = p.map(|c| c / w);
                        4
                    }
                    // x y z r g b: a vertex colour, not used.
                    6 => 3,
                    k => {
                        return Err(malformed(
                            lineno,
                            format!("a vertex has 3, 4 (w) or 6 (rgb) values, found {k}"),
                        ))
                    }
                };
                if !p.iter().all(|c| c.is_finite()) {
                    return Err(SceneError::NonFiniteVertex {
                        path: path.to_owned(),
                        line: lineno,
                        vertex: vertices + 1,
                        value: p,
                    });
                }
                vertices += 1;
                vlines.push('v');
                for w in &words[..kept] {
                    vlines.push(' ');
                    vlines.push_str(w);
                }
                vlines.push('\n');
            }
            Some("vn") => {
                let n: Vec<f32> = words.filter_map(|w| w.parse().ok()).collect();
                match n[..] {
                    [x, y, z] if x.is_finite() && y.is_finite() && z.is_finite() => {
                        ex.normals.push(Vec3::new(x, y, z))
                    }
                    _ => {
                        ex.bad_normals
                            .get_or_insert(format!("line {lineno}: not 3 finite numbers"));
                        ex.normals.push(Vec3::ZERO);
                    }
                }
            }
            Some("usemtl") => {
                let name = line.trim_start()[6..].trim().to_string();
                ex.current_material = match ex.material_names.iter().position(|m| *m == name) {
                    Some(i) => i as u32,
                    None => {
                        ex.material_names.push(name);
                        (ex.material_names.len() - 1) as u32
                    }
                };
            }
            Some("mtllib") => {
                let names = line.trim_start()[6..].trim();
                if !names.is_empty() {
                    ex.mtllibs.push(names.to_string());
                }
            }
            Some("f") => {
                face.clear();
                face_normals.clear();
                for token in words {
                    let index = face_index(token)
                        .ok_or_else(|| malformed(lineno, format!("bad face vertex {token:?}")))?;
                    face_normals.push(normal_index(token, ex.normals.len()).unwrap_or_else(
                        |bad| {
                            if bad {
                                ex.bad_normals.get_or_insert(format!(
                                    "line {lineno}: normal index out of range ({} defined)",
                                    ex.normals.len()
                                ));
                            }
                            0
                        },
                    ));
                    let out_of_range = || SceneError::FaceIndexOutOfRange {
                        path: path.to_owned(),
                        line: lineno,
                        index,
                        vertices,
                    };
                    let absolute = match index {
                        0 => return Err(out_of_range()),
                        // Relative: -1 is the last vertex defined so far.
                        i if i < 0 => {
                            let back =
                                usize::try_from(i.unsigned_abs()).map_err(|_| out_of_range())?;
                            vertices.checked_sub(back).ok_or_else(out_of_range)? + 1
                        }
                        i => {
                            // Mesh indices are u32.
                            let i = u32::try_from(i).map_err(|_| out_of_range())? as usize;
                            if i > max_index {
                                (max_index, max_line) = (i, lineno);
                            }
                            i
                        }
                    };
                    face.push(absolute);
                }
                // One or two vertices: a point or a line, not a surface (tobj and oit.py
                // drop them too).
                if face.len() >= 3 {
                    faces += 1;
                    for i in 1..face.len() - 1 {
                        ex.corners
                            .push([face_normals[0], face_normals[i], face_normals[i + 1]]);
                        ex.triangle_material.push(ex.current_material);
                    }
                    flines.push('f');
                    for i in &face {
                        let _ = write!(flines, " {i}");
                    }
                    flines.push('\n');
                }
            }
            _ => {}
        }
    }
    if max_index > vertices {
        return Err(SceneError::FaceIndexOutOfRange {
            path: path.to_owned(),
            line: max_line,
            index: max_index as i64,
            vertices,
        });
    }
    let mut text = vlines;
    if vertices > 0 {
        text.push('f');
        for i in identity_polygon(vertices) {
            let _ = write!(text, " {i}");
        }
        text.push('\n');
    }
    text.push_str(&flines);
    Ok(Prepass {
        text,
        vertices,
        faces,
        extras: ex,
    })
}

/// The normal index (from 1, absolute) of a face vertex `v//vn` or `v/vt/vn`: `Ok(0)` when it
/// has none, `Err(true)` when it names no normal defined so far (relative) or at all.
fn normal_index(token: &str, defined: usize) -> Result<u32, bool> {
    let Some(n) = token.split('/').nth(2).filter(|n| !n.is_empty()) else {
        return Ok(0);
    };
    let i: i64 = n.parse().map_err(|_| true)?;
    let absolute = if i < 0 { defined as i64 + 1 + i } else { i };
    // Forward references are checked at the end ([`ExtrasBuilder::finish`] sees the count).
    u32::try_from(absolute).ok().filter(|&a| a >= 1).ok_or(true)
}

/// The position index of one face vertex `v`, `v/vt`, `v//vn` or `v/vt/vn`; texture and
/// normal indices must be integers (or empty) but are otherwise ignored.
fn face_index(token: &str) -> Option<i64> {
    let mut parts = token.split('/');
    let v = parts.next()?.parse::<i64>().ok()?;
    let mut extra = 0;
    for part in parts {
        extra += 1;
        if extra > 2 || !(part.is_empty() || part.parse::<i64>().is_ok()) {
            return None;
        }
    }
    Some(v)
}

/// One mesh from tobj's models. tobj numbers vertices in order of first use; the identity
/// polygon uses every vertex first, in file order, so its numbering *is* file order. That is
/// checked (cheaply) rather than assumed, and its fan triangles are then dropped.
fn assemble(models: &[tobj::Model], vertices: usize, path: &Path) -> Result<Mesh, SceneError> {
    let internal = |what: &str| SceneError::MalformedObj {
        path: path.to_owned(),
        line: 0,
        reason: format!("internal: tobj {what}; please report this file"),
    };
    let [model] = models else {
        return Err(internal("returned several models"));
    };
    let m = &model.mesh;
    if m.positions.len() != 3 * vertices || m.indices.len() % 3 != 0 {
        return Err(internal("did not keep every vertex"));
    }
    let identity: Vec<u32> = identity_polygon(vertices).map(|i| (i - 1) as u32).collect();
    let skip = identity.len() - 2;
    let fan_ok = m.indices.len() >= 3 * skip
        && m.indices[..3 * skip]
            .chunks_exact(3)
            .enumerate()
            .all(|(k, t)| t == [identity[0], identity[k + 1], identity[k + 2]]);
    if !fan_ok {
        return Err(internal("renumbered the vertices"));
    }
    Ok(Mesh {
        positions: m.positions.chunks_exact(3).map(Vec3::from_slice).collect(),
        normals: None,
        indices: m.indices[3 * skip..]
            .chunks_exact(3)
            .map(|t| [t[0], t[1], t[2]])
            .collect(),
    })
}
