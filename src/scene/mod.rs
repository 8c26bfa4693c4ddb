//! Scene input: the meshes fragrace renders, and the camera that looks at them.
//!
//! A [`Scene`] is always *normalised* the way the llvmpipe reference harness
//! (`../shared/peers/llvmpipe/oit.py`) normalises its models: bounding box centred at the
//! origin, largest extent 1. With the same [`Camera`], fragrace and llvmpipe then see the
//! same image, so fragment counts, EPRs and timings can be compared side by side.
//!
//! Scenes come from three places:
//! - [`Scene::builtin`]: procedural and shipped scenes, so that every command runs with no
//!   files and a case file can name its scene with a short string ([`builtin_names`]);
//! - [`Scene::from_obj`]: a Wavefront OBJ file, plain or gzip ([`obj`]);
//! - [`Scene::from_mesh`]: any mesh built in code (tests, fuzzers).

pub mod builtin;
pub mod camera;
pub mod file;
pub mod material;
pub mod obj;
pub mod surface;

use std::path::{Path, PathBuf};

use fragrace_emu::geometry::{Mesh, MeshError};
use glam::Mat4;

pub use camera::{camera, camera_rig, normalise, Camera, CameraRig, Projection};
pub use material::Material;
pub use obj::{
    content_hash, load_obj, load_obj_with_extras, load_obj_with_hash, parse_obj_bytes, ObjExtras,
};
pub use surface::Surface;

/// Everything that can go wrong while getting a scene. Each variant says *what* is wrong and
/// *where* (file and line when there is one), because a scene error is usually a user's typo
/// or a broken download, and the message is all they will see.
#[derive(Debug, thiserror::Error)]
pub enum SceneError {
    #[error("{}: file not found", path.display())]
    NotFound { path: PathBuf },
    #[error("{}: cannot read: {source}", path.display())]
    Io {
        path: PathBuf,
        source: std::io::Error,
    },
    #[error("{}: the name ends in .gz but the data is not gzip (no 1f 8b magic bytes)", path.display())]
    NotGzip { path: PathBuf },
    #[error("{}: corrupt or truncated gzip data: {source}", path.display())]
    CorruptGzip {
        path: PathBuf,
        source: std::io::Error,
    },
    #[error("{}:{line}: malformed OBJ: {reason}", path.display())]
    MalformedObj {
        path: PathBuf,
        line: usize,
        reason: String,
    },
    /// An error reported by `tobj` itself (the pre-pass in [`obj`] catches the known ones
    /// first, with a line number; this is the safety net).
    #[error("{}: malformed OBJ: {source}", path.display())]
    Obj {
        path: PathBuf,
        source: tobj::LoadError,
    },
    #[error("{}:{line}: face index {index} is out of range ({vertices} vertices are defined{})",
        path.display(), if *index < 0 { " before this line" } else { "" })]
    FaceIndexOutOfRange {
        path: PathBuf,
        line: usize,
        index: i64,
        vertices: usize,
    },
    #[error("{}:{line}: vertex {vertex} has a non-finite coordinate {value:?}", path.display())]
    NonFiniteVertex {
        path: PathBuf,
        line: usize,
        vertex: usize,
        value: [f32; 3],
    },
    #[error("{name}: the mesh has no triangles")]
    EmptyMesh { name: String },
    #[error("{name}: all vertices coincide, so the mesh has no extent to frame with a camera")]
    DegenerateMesh { name: String },
    #[error("{name}: invalid mesh: {source}")]
    InvalidMesh { name: String, source: MeshError },
    #[error("bad material: {reason}")]
    BadMaterial { reason: String },
    #[error("{}: {reason}", path.display())]
    SceneFile { path: PathBuf, reason: String },
    #[error("bad camera: {reason}")]
    BadCamera { reason: String },
    #[error("unknown built-in scene {name:?}; the built-in scenes are: {}", builtin_names().join(", "))]
    UnknownBuiltin { name: String },
    #[error("built-in scene {name:?}: bad parameters; usage: {usage}")]
    BuiltinParams { name: String, usage: &'static str },
}

/// A mesh ready to draw: normalised (bounding box centred at the origin, largest extent 1)
/// with the radius of its bounding sphere about the origin, which the camera needs to frame
/// it.
#[derive(Clone, Debug)]
pub struct Scene {
    /// The built-in name (with its parameters, e.g. `coplanar-stack:16`), the OBJ path, or
    /// the name given to [`Scene::from_mesh`]. A case file stores this to find the scene
    /// again.
    pub name: String,
    pub mesh: Mesh,
    pub radius: f32,
    /// The scene's objects: consecutive ranges of the mesh's triangles (empty: the whole
    /// mesh is one object). `object-grid` and scenes of several OBJ files have several.
    pub objects: Vec<std::ops::Range<u32>>,
    /// Normals and materials for the renderer (OBJ files, scene files); `None`: the mesh's
    /// own normals or smooth ones, default materials ([`Scene::surface`]).
    pub surface: Option<Surface>,
}

/// One object of a scene being assembled: a mesh, its surface and where it is placed.
#[derive(Clone, Debug)]
pub struct Part {
    pub name: String,
    pub mesh: Mesh,
    pub surface: Surface,
    /// Model matrix, applied to the mesh's own coordinates before the scene is normalised.
    pub placement: Mat4,
}

/// The names [`Scene::builtin`] accepts (without parameters; see [`builtin::USAGE`]).
pub fn builtin_names() -> &'static [&'static str] {
    builtin::NAMES
}

impl Scene {
    /// A built-in scene by name: `cubes`, `coplanar-stack[:N]`, `spheres`, `hairball`,
    /// `bunny`, `teapot`, `random-triangles[:SEED[:N]]`. Every built-in is deterministic and
    /// bit-identical on every platform, so a case file naming one replays exactly.
    pub fn builtin(name: &str) -> Result<Scene, SceneError> {
        let (mesh, objects) = builtin::mesh_and_objects(name)?;
        Ok(Scene {
            objects,
            ..Scene::from_mesh(name, mesh)?
        })
    }

    /// Loads an OBJ file (plain or gzip) and normalises it, with its normals and the
    /// materials of its MTL files ([`Part::from_obj`]). The scene's name is the path.
    pub fn from_obj(path: impl AsRef<Path>) -> Result<Scene, SceneError> {
        let part = Part::from_obj(path.as_ref(), 0)?;
        let surface = part.surface;
        Ok(Scene {
            surface: Some(surface),
            ..Scene::from_mesh(part.name, part.mesh)?
        })
    }

    /// A scene of several placed parts, one object each, normalised together. Its name is
    /// the parts' names joined by `+`.
    pub fn from_parts(parts: Vec<Part>) -> Result<Scene, SceneError> {
        let name = parts
            .iter()
            .map(|p| p.name.as_str())
            .collect::<Vec<_>>()
            .join("+");
        let mut mesh = Mesh::default();
        let mut surface: Option<Surface> = None;
        let mut objects = Vec::with_capacity(parts.len());
        for (i, mut part) in parts.into_iter().enumerate() {
            if part.placement != Mat4::IDENTITY {
                for p in &mut part.mesh.positions {
                    *p = part.placement.transform_point3(*p);
                }
                if let Some(n) = &mut part.mesh.normals {
                    let inv_t = glam::Mat3::from_mat4(part.placement).inverse().transpose();
                    for v in n {
                        *v = (inv_t * *v).normalize_or_zero();
                    }
                }
                part.surface
                    .transform_normals(glam::Mat3::from_mat4(part.placement));
            }
            let start = mesh.indices.len() as u32;
            if i == 0 {
                mesh = part.mesh;
            } else {
                mesh.append(&part.mesh);
            }
            match &mut surface {
                None => surface = Some(part.surface),
                Some(s) => s.append(part.surface),
            }
            objects.push(start..mesh.indices.len() as u32);
        }
        Ok(Scene {
            objects,
            surface,
            ..Scene::from_mesh(name, mesh)?
        })
    }

    /// The renderer's normals and materials: the scene's own, or the mesh's normals (smooth
    /// ones when it has none) and a default material per object.
    pub fn surface(&self) -> std::borrow::Cow<'_, Surface> {
        match &self.surface {
            Some(s) if s.fits(&self.mesh) => std::borrow::Cow::Borrowed(s),
            _ => std::borrow::Cow::Owned(Surface::for_objects(&self.mesh, &self.objects)),
        }
    }

    /// A scene of several meshes, one object each, `parts[i]` moved by `i x step` (in the
    /// meshes' own units), normalised together. Its name is the parts' names joined by `+`.
    pub fn from_objects(parts: Vec<(String, Mesh)>, step: glam::Vec3) -> Result<Scene, SceneError> {
        let name = parts
            .iter()
            .map(|(n, _)| n.as_str())
            .collect::<Vec<_>>()
            .join("+");
        let mut mesh = Mesh::default();
        let mut objects = Vec::with_capacity(parts.len());
        for (i, (_, mut part)) in parts.into_iter().enumerate() {
            for p in &mut part.positions {
                *p += step * i as f32;
            }
            let start = mesh.indices.len() as u32;
            if i == 0 {
                mesh = part;
            } else {
                mesh.append(&part);
            }
            objects.push(start..mesh.indices.len() as u32);
        }
        Ok(Scene {
            objects,
            ..Scene::from_mesh(name, mesh)?
        })
    }

    /// Normalises a mesh into a scene. The mesh must be valid, have at least one triangle and
    /// a non-zero extent: anything else cannot be framed by the camera (the view matrix would
    /// be NaN), so it is refused here rather than producing an empty or garbage image later.
    pub fn from_mesh(name: impl Into<String>, mut mesh: Mesh) -> Result<Scene, SceneError> {
        let name = name.into();
        mesh.validate().map_err(|source| SceneError::InvalidMesh {
            name: name.clone(),
            source,
        })?;
        if mesh.indices.is_empty() {
            return Err(SceneError::EmptyMesh { name });
        }
        let radius = normalise(&mut mesh.positions);
        if radius <= 0.0 {
            return Err(SceneError::DegenerateMesh { name });
        }
        Ok(Scene {
            name,
            mesh,
            radius,
            objects: Vec::new(),
            surface: None,
        })
    }

    /// The view-projection matrix (OpenGL clip space) of `camera` looking at this scene in a
    /// `width` x `height` viewport; the same matrix `oit.py` would use.
    pub fn view_proj(&self, camera: &Camera, width: u32, height: u32) -> Mat4 {
        camera.view_proj(self.radius, width, height)
    }
}

impl Part {
    /// An OBJ file as object number `index` of a scene: its mesh, its `vn` normals (smooth
    /// ones when it has none) and its MTL materials (faces without one take
    /// [`Material::default_for`]`(index)`), not moved.
    pub fn from_obj(path: &Path, index: usize) -> Result<Part, SceneError> {
        let (mesh, extras, _) = obj::load_obj_with_extras(path)?;
        let dir = path.parent().unwrap_or(Path::new("."));
        let surface = Surface::from_obj(&mesh, &extras, dir, Material::default_for(index))?;
        Ok(Part {
            name: path.display().to_string(),
            mesh,
            surface,
            placement: Mat4::IDENTITY,
        })
    }
}

/// The reference harness's integer hash (`hash32` in `oit.py`'s shaders, a "lowbias32"
/// variant), used to colour triangles by primitive id.
pub fn hash32(mut x: u32) -> u32 {
    x ^= x >> 16;
    x = x.wrapping_mul(0x7feb_352d);
    x ^= x >> 15;
    x = x.wrapping_mul(0x846c_a68b);
    x ^= x >> 16;
    x
}

/// The colour of a triangle, exactly as `oit.py`'s `prim_color()`: each RGB channel is a
/// byte of `hash32(prim_id)` mapped to `0.2 + 0.8 * c` (never black, so a lost fragment
/// shows), alpha 1. Kernels use it so their images compare with llvmpipe's.
pub fn prim_color(prim_id: u32) -> [f32; 4] {
    let h = hash32(prim_id);
    let channel = |shift: u32| 0.2 + 0.8 * (((h >> shift) & 255) as f32 / 255.0);
    [channel(0), channel(8), channel(16), 1.0]
}

/// [`prim_color`] packed as GLSL `packUnorm4x8` does (red in the low byte): the value the
/// reference shaders store in their colour buffers, for bit-exact comparisons.
pub fn prim_color_rgba8(prim_id: u32) -> u32 {
    prim_color(prim_id)
        .iter()
        .enumerate()
        .map(|(i, &c)| ((c.clamp(0.0, 1.0) * 255.0).round() as u32) << (8 * i))
        .fold(0, |acc, byte| acc | byte)
}
