//! `--set KEY=VALUE`: a field of a scene changed from the command line, by its dotted path in
//! the scene file (`time.dt`, `physics.viscosity`, `fluid.0.velocity`: a number indexes an array
//! of blocks), with the value written as in TOML (`1e-4`, `[0, -9.81, 0]`, `true`, `"tait"`;
//! a bare word is taken as a string, so `physics.kernel=cubic_spline` works). The changed scene
//! is read and validated like a file, so a wrong key or value gets the file's error.

use super::scene::{Scene, SceneError, SceneOrigin};

/// One `--set KEY=VALUE`.
#[derive(Clone, Debug, PartialEq)]
pub struct Override {
    pub key: String,
    pub value: toml::Value,
    /// As given, for messages.
    pub text: String,
}

impl std::str::FromStr for Override {
    type Err = String;

    fn from_str(text: &str) -> Result<Self, String> {
        let (key, value) = text.split_once('=').ok_or_else(|| format!("'{text}' is not KEY=VALUE (e.g. time.dt=1e-4)"))?;
        let key = key.trim();
        if key.is_empty() || key.split('.').any(str::is_empty) {
            return Err(format!("'{text}': the key must be a dotted path of the scene file, e.g. time.dt or physics.viscosity"));
        }
        let value = value.trim();
        let parsed = toml::from_str::<toml::Table>(&format!("v = {value}")).ok().and_then(|mut t| t.remove("v"));
        let value = parsed.unwrap_or_else(|| toml::Value::String(value.to_string()));
        Ok(Override { key: key.to_string(), value, text: text.to_string() })
    }
}

impl Scene {
    /// The scene with the overrides applied in order, validated as a scene file is. `origin`
    /// is the scene's own, for messages.
    pub fn with_overrides(&self, overrides: &[Override], origin: &SceneOrigin) -> Result<Scene, SceneError> {
        if overrides.is_empty() {
            return Ok(self.clone());
        }
        let mut tree = toml::Value::try_from(self).expect("a scene serialises");
        for o in overrides {
            let error = |message: String| SceneError { origin: format!("{origin} with --set {}", o.text), field: o.key.clone(), message };
            set_path(&mut tree, &o.key, o.value.clone()).map_err(error)?;
            // Read back after each, so that an error names the override that caused it.
            let scene: Scene = tree.clone().try_into().map_err(|e: toml::de::Error| error(e.message().to_string()))?;
            scene.validate(origin).map_err(|e| SceneError { origin: format!("{} with --set {}", e.origin, o.text), ..e })?;
        }
        Ok(tree.try_into().expect("checked above"))
    }
}

/// Sets the value at a dotted path: tables by key (a missing last key is added, for the reader
/// to accept or refuse), arrays by index.
fn set_path(tree: &mut toml::Value, key: &str, value: toml::Value) -> Result<(), String> {
    let parts: Vec<&str> = key.split('.').collect();
    let mut node = tree;
    for (i, part) in parts.iter().enumerate() {
        let last = i + 1 == parts.len();
        let walked = parts[..i].join(".");
        node = match node {
            toml::Value::Table(t) => {
                if last {
                    t.insert(part.to_string(), value);
                    return Ok(());
                }
                t.entry(part.to_string()).or_insert_with(|| toml::Value::Table(Default::default()))
            }
            toml::Value::Array(a) => {
                let len = a.len();
                let index: usize = part.parse().map_err(|_| format!("{walked} is a list of {len}: index it with a number from 0 to {}", len.saturating_sub(1)))?;
                let slot = a.get_mut(index).ok_or_else(|| format!("{walked} has {len} entries; {index} is not one (they are numbered from 0)"))?;
                if last {
                    *slot = value;
                    return Ok(());
                }
                slot
            }
            _ => return Err(format!("{walked} is a value, not a table: '{part}' cannot be set inside it")),
        };
    }
    Ok(())
}
