//! Materials: a colour and an opacity per object or per `usemtl` group, read from the `.mtl`
//! files an OBJ names (through `tobj`'s MTL parser), or given by `--color` / `--opacity` and
//! scene files.
//!
//! `Kd` is the colour; `d` the opacity (`Tr`, its complement, when `d` is absent). A missing
//! or malformed MTL file is not a reason to refuse a model: its materials become the default
//! one, with a warning naming the file. An opacity outside [0, 1] is an error, never clamped.

use std::path::{Path, PathBuf};

use super::SceneError;

/// How a surface looks: its diffuse colour (linear RGB in [0, 1]) and its opacity in [0, 1].
#[derive(Clone, Debug, PartialEq)]
pub struct Material {
    /// The `newmtl` name, the object's name, or `default`.
    pub name: String,
    pub color: [f32; 3],
    pub opacity: f32,
}

/// The opacity of a material nothing says anything about.
pub const DEFAULT_OPACITY: f32 = 0.4;

/// Colours of the objects of a scene without materials, in object order (object `i` takes
/// `PALETTE[i % len]`): light, distinct, never black.
pub const PALETTE: [[f32; 3]; 6] = [
    [0.45, 0.65, 0.90],
    [0.90, 0.45, 0.35],
    [0.40, 0.65, 0.90],
    [0.55, 0.80, 0.45],
    [0.90, 0.75, 0.35],
    [0.70, 0.50, 0.85],
];

impl Material {
    /// The default material of object `i` of a scene: a palette colour, opacity
    /// [`DEFAULT_OPACITY`].
    pub fn default_for(i: usize) -> Material {
        Material {
            name: "default".into(),
            color: PALETTE[i % PALETTE.len()],
            opacity: DEFAULT_OPACITY,
        }
    }

    /// Refuses a colour channel or an opacity outside [0, 1] (or not a number), naming the
    /// value, the range and `what` it belongs to.
    pub fn validate(&self, what: &str) -> Result<(), SceneError> {
        check_unit(what, "opacity", self.opacity)?;
        for (c, name) in self.color.iter().zip(["red", "green", "blue"]) {
            check_unit(what, &format!("colour ({name})"), *c)?;
        }
        Ok(())
    }
}

/// `value` of `field` must be in [0, 1].
pub fn check_unit(what: &str, field: &str, value: f32) -> Result<(), SceneError> {
    if (0.0..=1.0).contains(&value) {
        Ok(())
    } else {
        Err(SceneError::BadMaterial {
            reason: format!("{what}: {field} {value} is outside [0, 1]"),
        })
    }
}

/// The materials of the MTL files `names` (as written on `mtllib` lines, relative to the OBJ's
/// folder `dir`), and warnings for the files that could not be used. A later file's material
/// of the same name replaces an earlier one's.
pub fn read_mtllibs(
    dir: &Path,
    names: &[String],
) -> Result<(Vec<Material>, Vec<String>), SceneError> {
    let mut materials: Vec<Material> = Vec::new();
    let mut warnings = Vec::new();
    for name in names {
        let path = dir.join(name);
        match read_mtl(&path) {
            Ok(found) => {
                for m in found {
                    m.validate(&format!("{}: material {:?}", path.display(), m.name))?;
                    match materials.iter_mut().find(|x| x.name == m.name) {
                        Some(old) => *old = m,
                        None => materials.push(m),
                    }
                }
            }
            Err(why) => warnings.push(format!(
                "{}: {why}; its materials take the default colour and opacity",
                path.display()
            )),
        }
    }
    Ok((materials, warnings))
}

/// One MTL file's materials (`Err`: why the file cannot be used).
fn read_mtl(path: &PathBuf) -> Result<Vec<Material>, String> {
    if !path.exists() {
        return Err("material file not found".into());
    }
    let (mats, _) = tobj::load_mtl(path).map_err(|e| format!("malformed material file ({e})"))?;
    Ok(mats
        .into_iter()
        .map(|m| {
            let tr = m
                .unknown_param
                .get("Tr")
                .and_then(|t| t.trim().parse::<f32>().ok());
            let opacity = m.dissolve.or(tr.map(|t| 1.0 - t)).unwrap_or(1.0);
            Material {
                color: m.diffuse.unwrap_or(PALETTE[0]),
                name: m.name,
                opacity,
            }
        })
        .collect())
}
