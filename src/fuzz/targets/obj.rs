//! The OBJ loader on arbitrary bytes (the `obj_loader` target).

use fragrace_emu::Mesh;

use super::{violation, Violation};
use crate::scene::parse_obj_bytes;

/// What [`obj_loader`] did.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum ObjOutcome {
    Rejected,
    /// Accepted: a valid mesh of this many triangles, which round-trips.
    Parsed {
        triangles: usize,
    },
}

/// The mesh as OBJ text ([`crate::scene::obj::obj_text`]).
pub fn write_obj(mesh: &Mesh) -> String {
    crate::scene::obj::obj_text(mesh)
}

/// The OBJ target: never panics; an accepted mesh is valid, has triangles, and parses back
/// identical from [`write_obj`]'s text.
pub fn obj_loader(data: &[u8]) -> Result<ObjOutcome, Violation> {
    const T: &str = "obj_loader";
    let Ok(mesh) = parse_obj_bytes(data) else {
        return Ok(ObjOutcome::Rejected);
    };
    if let Err(e) = mesh.validate() {
        return Err(violation(T, format!("accepted an invalid mesh: {e}")));
    }
    if mesh.indices.is_empty() {
        return Err(violation(T, "accepted a mesh with no triangle"));
    }
    let text = write_obj(&mesh);
    match parse_obj_bytes(text.as_bytes()) {
        Ok(back) if back == mesh => {}
        Ok(back) => {
            return Err(violation(
                T,
                format!("round trip changed the mesh: {mesh:?} became {back:?}"),
            ))
        }
        Err(e) => {
            return Err(violation(
                T,
                format!("round trip refused: {e}; text:\n{text}"),
            ))
        }
    }
    Ok(ObjOutcome::Parsed {
        triangles: mesh.indices.len(),
    })
}
