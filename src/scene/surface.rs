//! What the renderer shades with, beside a scene's positions: a normal at each triangle corner
//! and a material per triangle. The mesh the algorithms draw stays position-only and in file
//! order (the peer's); a [`Surface`] is indexed by the same triangle (primitive) ids.

use glam::{Mat3, Vec3};

use super::material::{read_mtllibs, Material};
use super::obj::ObjExtras;
use super::SceneError;
use fragrace_emu::Mesh;

/// Shading data of a scene, per triangle (primitive id).
#[derive(Clone, Debug, PartialEq)]
pub struct Surface {
    /// Shading normals (not necessarily unit length; zero where undefined).
    pub normals: Vec<Vec3>,
    /// Per triangle, the index into `normals` of each corner's normal.
    pub normal_indices: Vec<[u32; 3]>,
    pub materials: Vec<Material>,
    /// Per triangle, an index into `materials`.
    pub triangle_material: Vec<u32>,
    /// What loading left out (unusable `vn` lines, missing or malformed MTL files).
    pub warnings: Vec<String>,
}

/// Area-weighted smooth vertex normals: each vertex's is the sum of its triangles'
/// (unnormalised) cross products, normalised; zero for a vertex of degenerate triangles only.
pub fn smooth_normals(mesh: &Mesh) -> Vec<Vec3> {
    let mut n = vec![Vec3::ZERO; mesh.positions.len()];
    for t in &mesh.indices {
        let [a, b, c] = t.map(|i| mesh.positions[i as usize]);
        let face = (b - a).cross(c - a);
        for &i in t {
            n[i as usize] += face;
        }
    }
    for v in &mut n {
        *v = v.normalize_or_zero();
    }
    n
}

impl Surface {
    /// One material for the whole mesh, vertex normals from the mesh (or smooth ones).
    pub fn uniform(mesh: &Mesh, material: Material) -> Surface {
        Surface {
            normals: mesh.normals.clone().unwrap_or_else(|| smooth_normals(mesh)),
            normal_indices: mesh.indices.clone(),
            materials: vec![material],
            triangle_material: vec![0; mesh.indices.len()],
            warnings: Vec::new(),
        }
    }

    /// Built-in scenes and meshes without files: the mesh's normals (or smooth ones), object
    /// `i` (a range of triangles; the whole mesh when there are none) in
    /// [`Material::default_for`]`(i)`.
    pub fn for_objects(mesh: &Mesh, objects: &[std::ops::Range<u32>]) -> Surface {
        let mut s = Surface::uniform(mesh, Material::default_for(0));
        for (i, r) in objects.iter().enumerate().skip(1) {
            s.materials.push(Material::default_for(i));
            for m in &mut s.triangle_material[r.start as usize..r.end as usize] {
                *m = i as u32;
            }
        }
        s
    }

    /// An OBJ file's surface: its `vn` normals (or smooth ones), the materials of its MTL
    /// files (read from `dir`, the OBJ's folder) by `usemtl` name. Triangles before any
    /// `usemtl`, or naming a material no file defines, take `fallback`.
    pub fn from_obj(
        mesh: &Mesh,
        extras: &ObjExtras,
        dir: &std::path::Path,
        fallback: Material,
    ) -> Result<Surface, SceneError> {
        let (library, mut warnings) = read_mtllibs(dir, &extras.mtllibs)?;
        let libraries_read = warnings.is_empty();
        let mut materials = vec![fallback.clone()];
        // usemtl index -> materials index.
        let mut map = Vec::with_capacity(extras.material_names.len());
        let mut undefined = Vec::new();
        for name in &extras.material_names {
            match library.iter().find(|m| &m.name == name) {
                Some(m) => {
                    materials.push(m.clone());
                    map.push((materials.len() - 1) as u32);
                }
                None => {
                    if !extras.mtllibs.is_empty() && libraries_read {
                        undefined.push(name.clone());
                    }
                    map.push(0);
                }
            }
        }
        if !undefined.is_empty() {
            warnings.push(format!(
                "{}: materials {undefined:?} are used but not defined; they take the default",
                dir.display()
            ));
        }
        if !extras.material_names.is_empty() && extras.mtllibs.is_empty() {
            warnings.push(format!(
                "{}: usemtl without any mtllib; every material takes the default",
                dir.display()
            ));
        }
        warnings.extend(extras.warnings.iter().cloned());
        let triangle_material = extras
            .triangle_material
            .iter()
            .map(|&m| map.get(m as usize).copied().unwrap_or(0))
            .collect();
        let (normals, normal_indices) = match &extras.normals {
            Some((n, idx)) => (n.clone(), idx.clone()),
            None => (smooth_normals(mesh), mesh.indices.clone()),
        };
        Ok(Surface {
            normals,
            normal_indices,
            materials,
            triangle_material,
            warnings,
        })
    }

    /// Every triangle in `material` (`--color` / `--opacity` of a one-object scene).
    pub fn override_material(&mut self, edit: impl Fn(&mut Material)) {
        for m in &mut self.materials {
            edit(m);
        }
    }

    /// The normals moved by a placement whose linear part is `linear` (inverse transpose).
    pub fn transform_normals(&mut self, linear: Mat3) {
        let inv_t = linear.inverse().transpose();
        for n in &mut self.normals {
            *n = (inv_t * *n).normalize_or_zero();
        }
    }

    /// Appends `other` (the surface of a mesh appended after this one's `vertices` normals'
    /// mesh: its triangles follow this surface's).
    pub fn append(&mut self, other: Surface) {
        let (nb, mb) = (self.normals.len() as u32, self.materials.len() as u32);
        self.normals.extend(other.normals);
        self.normal_indices
            .extend(other.normal_indices.into_iter().map(|t| t.map(|i| i + nb)));
        self.materials.extend(other.materials);
        self.triangle_material
            .extend(other.triangle_material.into_iter().map(|m| m + mb));
        self.warnings.extend(other.warnings);
    }

    /// Whether it fits `mesh` (one entry per triangle, indices in range).
    pub fn fits(&self, mesh: &Mesh) -> bool {
        let n = self.normals.len() as u32;
        let m = self.materials.len() as u32;
        self.normal_indices.len() == mesh.indices.len()
            && self.triangle_material.len() == mesh.indices.len()
            && self.normal_indices.iter().flatten().all(|&i| i < n)
            && self.triangle_material.iter().all(|&i| i < m)
    }
}
