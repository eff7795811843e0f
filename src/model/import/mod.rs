//! Loading a scene by name: a built-in scene, a wgsph TOML file, or a file of another
//! simulator's format, chosen by its extension from [`IMPORTERS`].

pub mod splishsplash;

use super::builtin::BUILTIN_SCENES;
use super::mesh::{open_edges, parse_mesh, MeshSurface};
use super::numbers::short3;
use super::scene::{err, Boundary, Scene, SceneError, SceneOrigin};
use std::path::{Path, PathBuf};

/// A reader of another simulator's scene format: the file's text, the scene's name (the file
/// stem) and where it came from, for error messages. Besides the scene it returns its notes:
/// one line for each setting it imported as the nearest wgsph has (a caller shows them).
pub type Importer = fn(text: &str, name: &str, origin: &SceneOrigin) -> Result<(Scene, Vec<String>), SceneError>;

/// The foreign formats, by file extension (compared without regard to case).
pub const IMPORTERS: &[(&str, Importer)] = &[("json", splishsplash::scene_from_json)];

impl Scene {
    /// A built-in name, a path to a TOML file, or a file of a format in [`IMPORTERS`]
    /// (a SPlisHSPlasH scene, `*.json`).
    pub fn load(name_or_path: &str) -> Result<Scene, SceneError> {
        Scene::load_noting(name_or_path).map(|(scene, _)| scene)
    }

    /// [`Scene::load`], with the notes of an import (what it imported as the nearest wgsph
    /// has; none for a wgsph scene).
    pub fn load_noting(name_or_path: &str) -> Result<(Scene, Vec<String>), SceneError> {
        if let Some(s) = Scene::builtin(name_or_path) {
            return Ok((s, Vec::new()));
        }
        let path = Path::new(name_or_path);
        let origin = SceneOrigin::File(path.to_path_buf());
        if !path.exists() {
            let names: Vec<_> = BUILTIN_SCENES.iter().map(|s| s.0).collect();
            return Err(err(&origin, "scene", format!("no such file, and not a built-in scene (built-in: {})", names.join(", "))));
        }
        let bytes = read_at_most(path, MAX_SCENE_FILE_BYTES).map_err(|e| err(&origin, "scene", format!("cannot read the file: {e}")))?;
        let text = String::from_utf8(bytes).map_err(|_| err(&origin, "scene", "is not UTF-8 text; a scene is a TOML (or SPlisHSPlasH JSON) text file"))?;
        let extension = path.extension().map(|e| e.to_string_lossy().to_ascii_lowercase()).unwrap_or_default();
        if let Some((_, import)) = IMPORTERS.iter().find(|(ext, _)| *ext == extension) {
            let name = path.file_stem().map(|s| s.to_string_lossy().into_owned()).unwrap_or_default();
            return import(&text, &name, &origin);
        }
        Ok((Scene::from_toml_str(&text, &origin)?, Vec::new()))
    }
}

/// The largest scene file read: far beyond any scene's text, and a bound on what a path to an
/// endless file (`/dev/zero`) costs.
pub const MAX_SCENE_FILE_BYTES: u64 = 64 << 20;
/// The largest mesh file read (a binary STL of about 20 million triangles).
pub const MAX_MESH_FILE_BYTES: u64 = 1 << 30;

/// The bytes of the file at `path`, refused past `limit`.
fn read_at_most(path: &Path, limit: u64) -> std::io::Result<Vec<u8>> {
    use std::io::Read;
    let mut bytes = Vec::new();
    std::fs::File::open(path)?.take(limit + 1).read_to_end(&mut bytes)?;
    if bytes.len() as u64 > limit {
        return Err(std::io::Error::other(format!("it is longer than {} MiB, the most read", limit >> 20)));
    }
    Ok(bytes)
}

impl Scene {
    /// Reads the files of the scene's mesh boundaries that are not read yet. A relative path is
    /// taken from the folder of the scene's file (`origin`; the working directory for a scene
    /// that is not a file) and replaced by the absolute one, so that the scene written into a
    /// run's folder finds the file from there. A mesh whose scene records its CRC-32 must still
    /// have it; one that does not records it now. A mesh must be closed (see [`super::mesh`]).
    pub fn read_meshes(&mut self, origin: &SceneOrigin) -> Result<(), SceneError> {
        let folder = match origin {
            SceneOrigin::File(p) => p.parent().map(Path::to_path_buf).unwrap_or_default(),
            _ => PathBuf::new(),
        };
        for (i, b) in self.boundary.iter_mut().enumerate() {
            let Boundary::Mesh(m) = b else { continue };
            if m.surface.triangles().is_some() {
                continue;
            }
            let field = format!("boundary[{i}].file");
            let given = Path::new(&m.file);
            let path = if given.is_absolute() { given.to_path_buf() } else { folder.join(given) };
            let bytes = read_at_most(&path, MAX_MESH_FILE_BYTES).map_err(|e| err(origin, &field, format!("'{}': cannot read the mesh file: {e}", path.display())))?;
            let crc = format!("{:08x}", crc32fast::hash(&bytes));
            if let Some(recorded) = &m.crc32 {
                if !(recorded.len() == 8 && recorded.chars().all(|c| c.is_ascii_hexdigit())) {
                    return Err(err(origin, &format!("boundary[{i}].crc32"), format!("is '{recorded}'; must be the file's CRC-32 as 8 hexadecimal digits (or left out)")));
                }
                if !recorded.eq_ignore_ascii_case(&crc) {
                    return Err(err(origin, &field, format!(
                        "'{}' has changed since this scene recorded it (CRC-32 {crc}, recorded {recorded}); the walls would not be the ones it was run with: restore the file, or remove boundary[{i}].crc32 to use it as it is",
                        path.display())));
                }
            }
            let extension = path.extension().map(|e| e.to_string_lossy().into_owned()).unwrap_or_default();
            let triangles = parse_mesh(&bytes, &extension).map_err(|e| err(origin, &field, format!("'{}' {e}", path.display())))?;
            if let Some((count, at)) = open_edges(&triangles) {
                return Err(err(origin, &field, format!(
                    "'{}' is not a closed surface: {count} of its edges belong to an odd number of triangles (one near {} in the file's coordinates); a mesh boundary must be closed so that its inside is defined (fill its holes)",
                    path.display(), short3(at))));
            }
            m.file = std::path::absolute(&path).unwrap_or(path).to_string_lossy().into_owned();
            m.crc32 = Some(crc);
            m.surface = MeshSurface::new(triangles);
        }
        Ok(())
    }
}
