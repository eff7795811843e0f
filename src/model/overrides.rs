//! `--set KEY=VALUE`: a field of a scene changed from the command line, by its dotted path in
//! the scene file (`time.dt`, `physics.viscosity`, `fluid.0.velocity`: a number indexes an array
//! of blocks), with the value written as in TOML (`1e-4`, `[0, -9.81, 0]`, `true`, `"tait"`;
//! a bare word is taken as a string, so `physics.kernel=cubic_spline` works); `--unset KEY`
//! removes a field (back to its default, or gone where it has none) or an entry of a list
//! (`boundary.2`). The overrides apply in order (the removals first), each read back so that a
//! wrong key or type names it; the changed scene is then validated like a file, once, so that
//! a change that takes several fields (`--set physics.solver=dfsph --unset
//! physics.speed_of_sound`) passes through no half-made scene.

use super::scene::{Boundary, Scene, SceneError, SceneOrigin};

/// One `--set KEY=VALUE`, or `--unset KEY` (no value).
#[derive(Clone, Debug, PartialEq)]
pub struct Override {
    pub key: String,
    pub value: Option<toml::Value>,
    /// As given, with its flag, for messages.
    pub text: String,
}

/// A dotted path of the scene file, checked for empty parts (`text`: the argument, for messages).
fn checked_key<'a>(key: &'a str, text: &str) -> Result<&'a str, String> {
    let key = key.trim();
    if key.is_empty() || key.split('.').any(str::is_empty) {
        return Err(format!("'{text}': the key must be a dotted path of the scene file, e.g. time.dt or physics.viscosity"));
    }
    Ok(key)
}

impl Override {
    /// `--unset KEY`.
    pub fn unset(text: &str) -> Result<Self, String> {
        let key = checked_key(text, text)?;
        Ok(Override { key: key.to_string(), value: None, text: format!("--unset {key}") })
    }
}

impl std::str::FromStr for Override {
    type Err = String;

    fn from_str(text: &str) -> Result<Self, String> {
        let (key, value) = text.split_once('=').ok_or_else(|| format!("'{text}' is not KEY=VALUE (e.g. time.dt=1e-4)"))?;
        let key = checked_key(key, text)?;
        let value = value.trim();
        // One value: a line break would let the rest of the text set other keys, or be dropped.
        if value.contains(['\n', '\r']) {
            return Err(format!("'{text}': the value holds a line break; give one value per --set"));
        }
        let parsed = toml::from_str::<toml::Table>(&format!("v = {value}")).ok().and_then(|mut t| t.remove("v"));
        // A number beyond f64 is not a string to be refused as one.
        if parsed.is_none() && value.parse::<f64>().is_ok_and(f64::is_infinite) && !value.to_ascii_lowercase().contains("inf") {
            return Err(format!("'{text}': {value} is beyond the largest number a scene holds (about 1.8e308)"));
        }
        let value = parsed.unwrap_or_else(|| toml::Value::String(value.to_string()));
        Ok(Override { key: key.to_string(), value: Some(value), text: format!("--set {text}") })
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
            let error = |message: String| SceneError { origin: format!("{origin} with {}", o.text), field: o.key.clone(), message };
            match &o.value {
                Some(value) => set_path(&mut tree, &o.key, value.clone()),
                None => unset_path(&mut tree, &o.key),
            }
            .map_err(error)?;
            // Read back after each, so that a wrong key or type names the override.
            let _: Scene = tree.clone().try_into().map_err(|e: toml::de::Error| {
                let message = super::scene::readable_parse_error(e.message());
                // A field every scene has, removed: serde's "missing field" says what, not why.
                match (&o.value, message.starts_with("missing field")) {
                    (None, true) => error(format!("is required in every scene and has no default, so it cannot be removed (--set {}=VALUE changes it)", o.key)),
                    _ => error(message),
                }
            })?;
        }
        let mut scene: Scene = tree.try_into().expect("read back above");
        // A mesh keeps the triangles already read while its file is the same; another file is
        // read (and its CRC-32 recorded) anew.
        for (i, b) in scene.boundary.iter_mut().enumerate() {
            if let Boundary::Mesh(m) = b {
                match self.boundary.get(i) {
                    Some(Boundary::Mesh(before)) if before.file == m.file => m.surface = before.surface.clone(),
                    _ => m.crc32 = None,
                }
            }
        }
        scene.read_meshes(origin).map_err(|e| SceneError { origin: format!("{} with {}", e.origin, overrides.iter().map(|o| o.text.as_str()).collect::<Vec<_>>().join(" ")), ..e })?;
        scene.validate(origin).map_err(|e| {
            // Named by the overrides of the refused field (or those within it), else by all.
            let related = |o: &&Override| e.field == o.key || e.field.starts_with(&format!("{}.", o.key)) || o.key.starts_with(&format!("{}.", e.field));
            let named: Vec<&Override> = match overrides.iter().filter(related).collect::<Vec<_>>() {
                some if !some.is_empty() => some,
                _ => overrides.iter().collect(),
            };
            let flags = named.iter().map(|o| o.text.as_str()).collect::<Vec<_>>().join(" ");
            // A field the scene must not have: say how to remove it from the command line.
            let message = match e.message.ends_with("remove it") {
                true => format!("{} (--unset {})", e.message, e.field),
                false => e.message.clone(),
            };
            SceneError { origin: format!("{} with {flags}", e.origin), message, ..e }
        })?;
        Ok(scene)
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
                // A list the scene does not have: its entries cannot be set one by one.
                let next = parts[i + 1];
                if !t.contains_key(*part) && next.parse::<usize>().is_ok() {
                    let here = parts[..=i].join(".");
                    return Err(format!("the scene has no {here} list, so it has no entry {next} to set: add its entries in a scene file ([[{part}]] tables)"));
                }
                t.entry(part.to_string()).or_insert_with(|| toml::Value::Table(Default::default()))
            }
            toml::Value::Array(a) => {
                let len = a.len();
                let index: usize = part.parse().map_err(|_| format!("{walked} is a list of {len}: index it with a number from 0 to {}", len.saturating_sub(1)))?;
                let slot = a.get_mut(index).ok_or_else(|| format!("{walked} has {}; {index} is not one (they are numbered from 0)", entries(len)))?;
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

/// Removes the value at a dotted path: a table's key, or an array's entry (the entries after it
/// move up). An error where there is none.
fn unset_path(tree: &mut toml::Value, key: &str) -> Result<(), String> {
    let (parent, last) = match key.rsplit_once('.') {
        Some((parent, last)) => (Some(parent), last),
        None => (None, key),
    };
    let mut node = tree;
    if let Some(parent) = parent {
        for part in parent.split('.') {
            node = match node {
                toml::Value::Table(t) => t.get_mut(part),
                toml::Value::Array(a) => part.parse::<usize>().ok().and_then(|i| a.get_mut(i)),
                _ => None,
            }
            .ok_or_else(|| format!("the scene has no {parent}, so it has no {last} to remove"))?;
        }
    }
    match node {
        toml::Value::Table(t) => t.remove(last).map(|_| ()).ok_or_else(|| "is not set in the scene, so there is nothing to remove (a field at its default, or a name no scene has: see docs/scenes.md)".to_string()),
        toml::Value::Array(a) => {
            let len = a.len();
            let index = last.parse::<usize>().ok().filter(|&i| i < len).ok_or_else(|| format!("{} has {}; '{last}' is not one (they are numbered from 0)", parent.unwrap_or(""), entries(len)))?;
            a.remove(index);
            Ok(())
        }
        _ => Err(format!("{} is a value, not a table: '{last}' cannot be removed from it", parent.unwrap_or(""))),
    }
}

/// "1 entry", "3 entries".
fn entries(n: usize) -> String {
    format!("{n} {}", if n == 1 { "entry" } else { "entries" })
}
