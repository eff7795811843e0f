//! Import of SPlisHSPlasH JSON scenes: the subset that maps onto a wgsph scene.
//!
//! Mapped: `Configuration` (particle radius, time step, gravity, stop time, the pressure solver:
//! WCSPH with its stiffness and exponent or DFSPH with its tolerances and iteration limits, the
//! CFL-adaptive time step, the kernel), `FluidBlocks` (axis-aligned boxes with translation, scale and
//! initial velocity), the fluid parameter block (rest density and the standard viscosity), and
//! static `RigidBodies`: scaled and translated unit boxes become a tank around the fluid or an
//! obstacle box, and other meshes (OBJ or STL; a box turned by `rotationAngle`) mesh walls,
//! with the fluid inside them where `mapInvert` says so. Both layouts are read: settings at the top of `Configuration` and of
//! a fluid's block, or (SPlisHSPlasH 2.13 on) in blocks named after the solver (`"DFSPH"`) and
//! the method (`"Standard viscosity"`). Akinci et al.'s surface tension (`surfaceTensionMethod`
//! 2) becomes wgsph's surface tension and adhesion, with their coefficients. Settings of the viewer and of SPlisHSPlasH's own exports,
//! and the blocks of solvers and methods the scene does not choose, are skipped. Density and
//! volume map walls become wall particles on the same boxes, and a scene without an end time
//! gets one, each with a note for the caller to show. Everything else (another pressure solver,
//! the iteration-count time step rule, dynamic bodies, particle files, emitters, animation fields, other surface tension methods, vorticity, drag,
//! elasticity, XSPH, 2D) is refused with a message naming each such field, so that no setting
//! is silently dropped.
//!
//! Parameter names and defaults follow SPlisHSPlasH's scene file documentation
//! (doc/file_format.md of its repository).

use crate::model::scene::{
    Boundary, DfsphSettings, Domain, EquationOfState, FluidBlock, Kernel, MeshWall, Physics, PressureSolver, Scene, SceneError, SceneOrigin,
    Time, WallParticles,
};
use serde_json::{Map, Value};
use std::collections::HashMap;

/// Keys of the viewer and of SPlisHSPlasH's exports, and solver settings that only apply to
/// features refused elsewhere (other pressure solvers): skipped.
const SKIPPED_CONFIGURATION: &[&str] = &[
    "pause",
    "pauseAt",
    "cameraPosition",
    "cameraLookat",
    "numberOfStepsPerRenderUpdate",
    "renderWalls",
    "enablePartioExport",
    "enableVTKExport",
    "enableRigidBodyExport",
    "dataExportFPS",
    "particleAttributes",
    "enableStateExport",
    "stateExportFPS",
    "enableZSort",
    "velocityUpdateMethod",
    "enableRigidBodyVTKExport",
    "enableObjectSplitting",
    "colorMapType",
    "renderMaxVelocity",
    "renderMinVelocity",
];
/// The pressure solvers' own blocks in `Configuration` (SPlisHSPlasH 2.13 on): the two wgsph
/// has are read; the others hold settings of solvers that `simulationMethod` refuses.
const SOLVER_BLOCKS: &[&str] = &["WCSPH", "DFSPH", "PCISPH", "PBF", "IISPH", "Projective Fluids", "ICSPH"];
/// The keys of the blocks wgsph reads.
const WCSPH_KEYS: &[&str] = &["stiffness", "exponent"];
const DFSPH_KEYS: &[&str] = &["minIterations", "maxIterations", "maxError", "maxIterationsV", "maxErrorV", "enableDivergenceSolver"];
/// The non-pressure methods' own blocks in a fluid's parameters (SPlisHSPlasH 2.13 on), which
/// hold their coefficients; each method is chosen by its `*Method` key, which the import checks
/// (only the standard viscosity, read from its block, is imported).
const METHOD_BLOCKS: &[&str] = &[
    "Bender and Koschier 2017",
    "Peer et al. 2015",
    "Peer et al. 2016",
    "Takahashi et al. 2015 (improved)",
    "Weiler et al. 2018",
    "Bender et al. 2017",
    "Vorticity confinement",
    "Liu et al. 2021",
    "Macklin et al. 2014",
    "Gissler et al. 2017",
    "Becker & Teschner 2007",
    "He et al. 2014",
    "Jeske et al. 2023",
    "Zorilla, Ritter, et al. 2020",
    "Becker et al. 2009",
    "Peer et al. 2018",
    "Kugelstadt et al. 2021",
];
/// The end of a scene that runs until stopped (no `stopAt`), in seconds.
const END_WITHOUT_STOP_AT: f64 = 5.0;
/// The largest rotationAngle taken (radians): a turn of many thousand revolutions is a typo,
/// and beyond some 1e15 the angle keeps no precision at all.
const MAX_ROTATION_RADIANS: f64 = 1e4;
const SKIPPED_FLUID: &[&str] = &[
    "colorField",
    "colorMapType",
    "renderMinValue",
    "renderMaxValue",
    "maxEmitterParticles",
    "emitterReuseParticles",
    "emitterBoxMin",
    "emitterBoxMax",
    "emitterBoxMin0",
    "emitterBoxMin1",
    "emitterBoxMin2",
    "emitterBoxMax0",
    "emitterBoxMax1",
    "emitterBoxMax2",
];
/// A rigid body's settings of the viewer and of the boundary maps (whose walls are imported as
/// particles), its id (for joints), and those only the rigid-body solver reads for a dynamic
/// body (which is refused).
const SKIPPED_RIGID: &[&str] = &[
    "color",
    "isWall",
    "mapThickness",
    "mapResolution",
    "samplingMode",
    "invertSDF",
    "boundingBoxMin",
    "boundingBoxMax",
    "id",
    "restitution",
    "friction",
    "collisionObjectType",
    "collisionObjectScale",
    "density",
    "velocity",
];

/// What the import found wrong, collected so that one message names every problem.
struct Problems(Vec<(String, String)>);

impl Problems {
    fn add(&mut self, field: impl Into<String>, message: impl Into<String>) {
        self.0.push((field.into(), message.into()));
    }
}

fn number(v: &Value, field: &str, p: &mut Problems) -> Option<f64> {
    match v.as_f64() {
        Some(x) if x.is_finite() => Some(x),
        _ => {
            p.add(field, format!("is {v}; must be a number"));
            None
        }
    }
}

fn vec3(v: &Value, field: &str, p: &mut Problems) -> Option<[f64; 3]> {
    match v.as_array().map(|a| a.iter().filter_map(Value::as_f64).collect::<Vec<f64>>()) {
        Some(a) if a.len() == 3 && v.as_array().map(Vec::len) == Some(3) => Some([a[0], a[1], a[2]]),
        _ => {
            p.add(field, format!("is {v}; must be an array of 3 numbers"));
            None
        }
    }
}

fn boolean(v: &Value, field: &str, p: &mut Problems) -> Option<bool> {
    match v {
        Value::Bool(b) => Some(*b),
        Value::Number(n) => Some(n.as_f64() != Some(0.0)),
        _ => {
            p.add(field, format!("is {v}; must be true or false"));
            None
        }
    }
}

/// A whole number of at least 1 (an iteration limit).
fn count(v: &Value, field: &str, p: &mut Problems) -> Option<u32> {
    match v.as_u64() {
        Some(n) if n >= 1 && n <= u32::MAX as u64 => Some(n as u32),
        _ => {
            p.add(field, format!("is {v}; must be a whole number of at least 1"));
            None
        }
    }
}

/// The integer of a method selector, `default` when absent.
fn method(obj: &Map<String, Value>, key: &str, default: i64, section: &str, p: &mut Problems) -> i64 {
    match obj.get(key) {
        None => default,
        Some(v) => v.as_i64().unwrap_or_else(|| {
            p.add(format!("{section}.{key}"), format!("is {v}; must be an integer"));
            default
        }),
    }
}

fn object<'a>(v: &'a Value, field: &str, p: &mut Problems) -> Option<&'a Map<String, Value>> {
    let o = v.as_object();
    if o.is_none() {
        p.add(field, format!("must be a JSON object, not {v}"));
    }
    o
}

/// The keys of a section (`Configuration`, a fluid's parameters) to read, each with the field it
/// was read at: those at its top and those of the blocks in `read` (a block's name and the keys
/// it may hold; another key there is a problem). The other blocks in `skipped` are left out:
/// they belong to solvers or methods the scene does not choose, which their selectors check.
fn section_entries<'a>(obj: &'a Map<String, Value>, section: &str, read: &[(&str, &[&str])], skipped: &[&str], p: &mut Problems) -> Vec<(&'a str, &'a Value, String)> {
    let mut entries = Vec::new();
    for (key, v) in obj {
        let field = format!("{section}.{key}");
        match (read.iter().find(|(name, _)| name == key), v.as_object()) {
            (Some((block, allowed)), Some(o)) => {
                for (inner, w) in o {
                    if allowed.contains(&inner.as_str()) {
                        entries.push((inner.as_str(), w, format!("{field}.{inner}")));
                    } else {
                        p.add(format!("{field}.{inner}"), format!("is not a parameter of SPlisHSPlasH's {block} block that wgsph can import"));
                    }
                }
            }
            (None, Some(_)) if skipped.contains(&key.as_str()) => {}
            _ => entries.push((key.as_str(), v, field)),
        }
    }
    // A key given at the top and in a method's block (`viscosity` and `Standard
    // viscosity.viscosity`) holds two values of which one would be dropped unseen.
    for (i, (key, _, field)) in entries.iter().enumerate() {
        if let Some((_, _, first)) = entries[..i].iter().find(|(k, _, _)| k == key) {
            p.add(field.clone(), format!("gives {key} again, as {first} does; give it in one place"));
        }
    }
    entries
}

/// The fluid parameters of one fluid id.
#[derive(Clone, Copy, PartialEq, Debug)]
struct FluidParams {
    density0: f64,
    viscosity: f64,
    viscosity_boundary: f64,
    /// Akinci et al. 2013's coefficients (surfaceTensionMethod 2), 0 for no surface tension.
    surface_tension: f64,
    surface_tension_boundary: f64,
}

/// The fluid's parameters, and where each key was read (`Materials[0].Standard viscosity.viscosity`).
fn fluid_params(section: &str, obj: &Map<String, Value>, p: &mut Problems) -> (FluidParams, HashMap<String, String>) {
    let mut f = FluidParams { density0: 1000.0, viscosity: 0.01, viscosity_boundary: 0.0, surface_tension: 0.0, surface_tension_boundary: 0.0 };
    let mut viscosity_method = 1;
    let mut surface_tension_method = 0;
    // SPlisHSPlasH's defaults of Akinci et al. 2013's coefficients.
    let (mut surface_tension, mut surface_tension_boundary) = (0.05, 0.01);
    // Keys at the top of the block, and those of the "Standard viscosity", "XSPH" and "Akinci et
    // al. 2013" blocks.
    let read = [
        ("Standard viscosity", &["viscosity", "viscosityBoundary"][..]),
        ("XSPH", &["xsph", "xsphBoundary"][..]),
        ("Akinci et al. 2013", &["surfaceTension", "surfaceTensionBoundary"][..]),
    ];
    let entries = section_entries(obj, section, &read, METHOD_BLOCKS, p);
    let read_at = entries.iter().map(|(key, _, field)| (key.to_string(), field.clone())).collect();
    for (key, v, field) in entries {
        match key {
            "id" => {}
            "density0" => f.density0 = number(v, &field, p).unwrap_or(f.density0),
            "viscosity" => f.viscosity = number(v, &field, p).unwrap_or(f.viscosity),
            "viscosityBoundary" => f.viscosity_boundary = number(v, &field, p).unwrap_or(0.0),
            "xsph" | "xsphBoundary" => {
                if number(v, &field, p).is_some_and(|x| x != 0.0) {
                    p.add(&field, format!("is {v}; wgsph has no XSPH velocity filter (only 0, off, is supported)"));
                }
            }
            "viscosityMethod" => viscosity_method = method(obj, key, 1, section, p),
            "surfaceTensionMethod" => surface_tension_method = method(obj, key, 0, section, p),
            "surfaceTension" => surface_tension = number(v, &field, p).unwrap_or(surface_tension),
            "surfaceTensionBoundary" => surface_tension_boundary = number(v, &field, p).unwrap_or(surface_tension_boundary),
            "vorticityMethod" | "dragMethod" | "elasticityMethod" => {
                let m = method(obj, key, 0, section, p);
                if m != 0 {
                    p.add(&field, format!("is {m}; wgsph has no {} (only 0, none, is supported)", &key[..key.len() - "Method".len()]));
                }
            }
            "vorticity" | "drag" | "viscosityOmega" | "inertiaInverse" | "youngsModulus" | "poissonsRatio"
            | "alpha" | "elasticityMaxIter" | "elasticityMaxError" | "viscoMaxIter" | "viscoMaxError" | "viscoMaxIterOmega"
            | "viscoMaxErrorOmega" => {} // coefficients of the methods checked above
            k if SKIPPED_FLUID.contains(&k) => {}
            _ => p.add(&field, "is not a SPlisHSPlasH fluid parameter that wgsph can import"),
        }
    }
    match surface_tension_method {
        0 => {}
        // SPlisHSPlasH's "Akinci et al. 2013" is wgsph's surface tension and adhesion, its
        // coefficients gamma and beta.
        2 => (f.surface_tension, f.surface_tension_boundary) = (surface_tension, surface_tension_boundary),
        m => p.add(
            format!("{section}.surfaceTensionMethod"),
            format!("is {m}; wgsph supports 0 (none) and 2 (Akinci et al. 2013, cohesion, curvature and adhesion)"),
        ),
    }
    match viscosity_method {
        0 => f.viscosity = 0.0,
        // SPlisHSPlasH's "Standard" viscosity is Monaghan's term with the kinematic viscosity,
        // which is wgsph's viscosity with the cubic spline (Monaghan 2005, Eq. 6.3).
        1 => {}
        m => p.add(
            format!("{section}.viscosityMethod"),
            format!("is {m}; wgsph supports 0 (none) and 1 (standard, the kinematic viscosity of Monaghan's term)"),
        ),
    }
    (f, read_at)
}

/// A scene from the text of a SPlisHSPlasH JSON scene file. `name` becomes the scene's name.
pub fn scene_from_json(text: &str, name: &str, origin: &SceneOrigin) -> Result<(Scene, Vec<String>), SceneError> {
    let fail = |field: &str, message: String| SceneError { origin: origin.to_string(), field: field.into(), message };
    let root: Value = serde_json::from_str(text).map_err(|e| fail(&format!("line {}", e.line()), format!("not valid JSON: {e}")))?;
    let root = root.as_object().ok_or_else(|| fail("json", "the scene must be a JSON object".into()))?;
    let mut p = Problems(Vec::new());
    let mut notes = Vec::new();

    // Configuration.
    let empty = Map::new();
    let config = match root.get("Configuration") {
        Some(v) => object(v, "Configuration", &mut p).unwrap_or(&empty),
        None => &empty,
    };
    let (mut radius, mut dt, mut gravity, mut stop_at) = (0.025, 0.001, [0.0, -9.81, 0.0], None);
    let (mut stiffness, mut exponent) = (50000.0, 7.0);
    // DFSPH's settings and the CFL rule's, SPlisHSPlasH's defaults where absent (its errors are
    // in per cent).
    let (mut max_error, mut max_error_v, mut enable_divergence) = (0.01, 0.1, true);
    let (mut min_iterations, mut max_iterations, mut max_iterations_v) = (None, 100, 100);
    let (mut cfl_factor, mut cfl_min_dt, mut cfl_max_dt) = (0.5, 0.0001, 0.005);
    // The keys at the top of Configuration (SPlisHSPlasH before 2.13 kept every solver's there)
    // and those of the WCSPH and DFSPH blocks.
    let entries = section_entries(config, "Configuration", &[("WCSPH", WCSPH_KEYS), ("DFSPH", DFSPH_KEYS)], SOLVER_BLOCKS, &mut p);
    // Where each key was read, for the messages of a scene wgsph refuses.
    let config_read_at: HashMap<String, String> = entries.iter().map(|(key, _, field)| (key.to_string(), field.clone())).collect();
    for (key, v, field) in entries {
        match key {
            "particleRadius" => {
                // Checked here: once doubled into the spacing (and h four times it) a message
                // would name a value the file does not hold.
                match number(v, &field, &mut p) {
                    Some(r) if r > 0.0 => radius = r,
                    Some(r) => p.add(&field, format!("is {}; must be a finite number > 0", crate::model::numbers::short(r))),
                    None => {}
                }
            }
            "timeStepSize" => dt = number(v, &field, &mut p).unwrap_or(dt),
            "gravitation" => gravity = vec3(v, &field, &mut p).unwrap_or(gravity),
            "stopAt" => stop_at = number(v, &field, &mut p),
            "stiffness" => stiffness = number(v, &field, &mut p).unwrap_or(stiffness),
            "exponent" => exponent = number(v, &field, &mut p).unwrap_or(exponent),
            "maxError" => max_error = number(v, &field, &mut p).unwrap_or(max_error),
            "maxErrorV" => max_error_v = number(v, &field, &mut p).unwrap_or(max_error_v),
            "minIterations" => min_iterations = count(v, &field, &mut p).or(min_iterations),
            "maxIterations" => max_iterations = count(v, &field, &mut p).unwrap_or(max_iterations),
            "maxIterationsV" => max_iterations_v = count(v, &field, &mut p).unwrap_or(max_iterations_v),
            "enableDivergenceSolver" => enable_divergence = boolean(v, &field, &mut p).unwrap_or(enable_divergence),
            "cflFactor" => cfl_factor = number(v, &field, &mut p).unwrap_or(cfl_factor),
            "cflMinTimeStepSize" => cfl_min_dt = number(v, &field, &mut p).unwrap_or(cfl_min_dt),
            "cflMaxTimeStepSize" => cfl_max_dt = number(v, &field, &mut p).unwrap_or(cfl_max_dt),
            "sim2D" => {
                if boolean(v, &field, &mut p) == Some(true) {
                    p.add(&field, "is true; wgsph simulates in 3D only");
                }
            }
            "simulationMethod" | "cflMethod" | "boundaryHandlingMethod" | "kernel" | "gradKernel" => {}
            k if SKIPPED_CONFIGURATION.contains(&k) => {}
            _ => p.add(&field, "is not a SPlisHSPlasH configuration parameter that wgsph can import"),
        }
    }
    let solver = match method(config, "simulationMethod", 4, "Configuration", &mut p) {
        0 => PressureSolver::Wcsph,
        4 => PressureSolver::Dfsph,
        other => {
            p.add("Configuration.simulationMethod", format!("is {other}; wgsph has WCSPH (0) and DFSPH (4)"));
            PressureSolver::Wcsph
        }
    };
    let adaptive = match method(config, "cflMethod", 1, "Configuration", &mut p) {
        0 => false,
        1 => true,
        other => {
            p.add(
                "Configuration.cflMethod",
                format!("is {other}; wgsph's adaptive step follows the CFL condition alone: set it to 1 (CFL) or 0 (the fixed timeStepSize)"),
            );
            false
        }
    };
    // The maps sample the same boxes as a field instead of particles: the walls are imported as
    // wgsph's wall particles (Akinci et al. 2012's method, 0), with a note.
    match method(config, "boundaryHandlingMethod", 2, "Configuration", &mut p) {
        0 => {}
        m @ (1 | 2) => notes.push(format!(
            "Configuration.boundaryHandlingMethod is {m}{} ({}): the walls are imported as wgsph's wall particles (Akinci et al. 2012's method, 0), the same boxes and meshes sampled as particles",
            if config.contains_key("boundaryHandlingMethod") { "" } else { ", the default" },
            if m == 1 { "density maps, Koschier & Bender 2017" } else { "volume maps, Bender et al. 2019" }
        )),
        m => p.add("Configuration.boundaryHandlingMethod", format!("is {m}; SPlisHSPlasH's methods are 0 (particles), 1 (density maps) and 2 (volume maps)")),
    }
    // Kernels: 0 and 4 are the cubic spline (4 precomputed); 1 is Wendland's quintic C2 (the
    // same function as wgsph's `wendland`, support h); 2 with gradient 3 is poly6 with the spiky
    // gradient, wgsph's Mueller kernels.
    let kernel = match (method(config, "kernel", 4, "Configuration", &mut p), method(config, "gradKernel", 4, "Configuration", &mut p)) {
        (0 | 4, 0 | 4) => Kernel::CubicSpline,
        (1, 1) => Kernel::Wendland,
        (2, 3) => Kernel::Mueller,
        (k, g) => {
            p.add(
                "Configuration.kernel",
                format!("kernel {k} with gradKernel {g}; wgsph supports the cubic spline (0 or 4 for both), Wendland's quintic C2 (1 for both) and poly6 with the spiky gradient (kernel 2, gradKernel 3)"),
            );
            Kernel::CubicSpline
        }
    };
    // DFSPH has no equation of state: the scene keeps the default, which it does not use.
    let eos = if solver == PressureSolver::Dfsph {
        EquationOfState::Linear
    } else if exponent == 7.0 {
        EquationOfState::Tait
    } else if exponent == 1.0 {
        EquationOfState::Linear
    } else {
        // DFSPH has no equation of state: its stiffness and exponent are not read there.
        if solver == PressureSolver::Wcsph {
            p.add("Configuration.exponent", format!("is {exponent}; wgsph's equations of state have the exponent 7 (Tait) or 1 (linear)"));
        }
        EquationOfState::Tait
    };
    // SPlisHSPlasH runs a scene without stopAt (or with a negative one) until it is stopped; a
    // wgsph scene has an end time, which `--time` or `--steps` overrides.
    let end_time = match stop_at {
        Some(t) if t > 0.0 => t,
        Some(t) if t == 0.0 => {
            p.add("Configuration.stopAt", "is 0; must be the end time of the run in seconds (> 0), or negative to run until stopped");
            1.0
        }
        _ => {
            notes.push(format!(
                "Configuration.stopAt is {} (SPlisHSPlasH runs until stopped): the scene ends at t = {END_WITHOUT_STOP_AT} s; --time T or --steps N runs another length",
                if stop_at.is_some() { "negative" } else { "not given" }
            ));
            END_WITHOUT_STOP_AT
        }
    };

    // Fluid parameter blocks: top-level objects keyed by fluid id, or the older "Materials" list.
    // (fluid id, its parameters, the JSON section they were read from, where each key was read)
    let mut fluids: Vec<(String, FluidParams, String, HashMap<String, String>)> = Vec::new();
    let block_ids: Vec<String> = root
        .get("FluidBlocks")
        .and_then(Value::as_array)
        .map(|a| a.iter().map(|b| b.get("id").and_then(Value::as_str).unwrap_or("Fluid").to_string()).collect())
        .unwrap_or_default();
    if let Some(materials) = root.get("Materials") {
        for (i, m) in materials.as_array().map(Vec::as_slice).unwrap_or_default().iter().enumerate() {
            if let Some(o) = object(m, &format!("Materials[{i}]"), &mut p) {
                let id = o.get("id").and_then(Value::as_str).unwrap_or("Fluid").to_string();
                let (params, read_at) = fluid_params(&format!("Materials[{i}]"), o, &mut p);
                fluids.push((id, params, format!("Materials[{i}]"), read_at));
            }
        }
    }

    // Fluid blocks.
    let spacing = 2.0 * radius;
    let mut blocks = Vec::new();
    let mut block_fluid = Vec::new();
    for (key, v) in root {
        match key.as_str() {
            "Configuration" | "Materials" | "RigidBodies" | "FluidBlocks" => {}
            // The rigid-body solver's settings, which only a dynamic body (refused) uses.
            "Simulation" => {}
            "FluidModels" | "Emitters" | "AnimationFields" => {
                if v.as_array().is_none_or(|a| !a.is_empty()) {
                    p.add(key, "is not supported by wgsph (only FluidBlocks create fluid, and no field animates it)");
                }
            }
            id if block_ids.iter().any(|b| b == id) => {
                if let Some(o) = object(v, id, &mut p) {
                    let (params, read_at) = fluid_params(id, o, &mut p);
                    fluids.push((id.to_string(), params, id.to_string(), read_at));
                }
            }
            _ => p.add(key, "is not a SPlisHSPlasH scene section that wgsph can import"),
        }
    }
    let arr = |key: &str, p: &mut Problems| -> Vec<Value> {
        match root.get(key) {
            None => Vec::new(),
            Some(Value::Array(a)) => a.clone(),
            Some(v) => {
                p.add(key, format!("must be an array, not {v}"));
                Vec::new()
            }
        }
    };
    for (i, b) in arr("FluidBlocks", &mut p).iter().enumerate() {
        let section = format!("FluidBlocks[{i}]");
        let Some(o) = object(b, &section, &mut p) else { continue };
        let (mut start, mut end, mut translation, mut scale, mut velocity) = (None, None, [0.0; 3], [1.0; 3], [0.0; 3]);
        for (key, v) in o {
            let field = format!("{section}.{key}");
            match key.as_str() {
                "start" => start = vec3(v, &field, &mut p),
                "end" => end = vec3(v, &field, &mut p),
                "translation" => translation = vec3(v, &field, &mut p).unwrap_or(translation),
                "scale" => scale = vec3(v, &field, &mut p).unwrap_or(scale),
                "initialVelocity" => velocity = vec3(v, &field, &mut p).unwrap_or(velocity),
                "id" => {}
                "denseMode" => {
                    let m = method(o, key, 0, &section, &mut p);
                    if m != 0 {
                        p.add(&field, format!("is {m}; wgsph fills blocks on a regular lattice (0)"));
                    }
                }
                _ => p.add(&field, "is not a fluid block parameter that wgsph can import"),
            }
        }
        let (Some(start), Some(end)) = (start, end) else {
            p.add(&section, "needs start and end");
            continue;
        };
        // The block's corners are scaled, then translated.
        let t = |c: [f64; 3]| [c[0] * scale[0] + translation[0], c[1] * scale[1] + translation[1], c[2] * scale[2] + translation[2]];
        let (a, b) = (t(start), t(end));
        let min = [a[0].min(b[0]), a[1].min(b[1]), a[2].min(b[2])];
        let max = [a[0].max(b[0]), a[1].max(b[1]), a[2].max(b[2])];
        blocks.push(FluidBlock { min, max, jitter: 0.0, velocity, shape: Default::default() });
        block_fluid.push(o.get("id").and_then(Value::as_str).unwrap_or("Fluid").to_string());
    }
    if blocks.is_empty() {
        p.add("FluidBlocks", "has no block; wgsph imports fluid only from FluidBlocks");
    }
    // wgsph simulates one fluid: every block must use the same parameters.
    let default_fluid = FluidParams { density0: 1000.0, viscosity: 0.01, viscosity_boundary: 0.0, surface_tension: 0.0, surface_tension_boundary: 0.0 };
    let params_of = |id: &str| fluids.iter().find(|f| f.0 == id).map(|f| f.1).unwrap_or(default_fluid);
    // The JSON section the fluid's parameters come from (its id, where it has none).
    let first_fluid = block_fluid.first().and_then(|id| fluids.iter().find(|f| &f.0 == id));
    let fluid_section = first_fluid.map(|f| f.2.clone()).or_else(|| block_fluid.first().cloned()).unwrap_or_else(|| "Fluid".into());
    let fluid_read_at = first_fluid.map(|f| f.3.clone()).unwrap_or_default();
    let fluid = block_fluid.first().map(|id| params_of(id)).unwrap_or(default_fluid);
    for id in &block_fluid {
        if params_of(id) != fluid {
            p.add(id.as_str(), format!("differs from the parameters of fluid '{}'; wgsph simulates one fluid", block_fluid[0]));
        }
    }

    // Rigid bodies: static unit boxes, and other meshes.
    let mut walls: Vec<([f64; 3], [f64; 3], String)> = Vec::new();
    let mut meshes: Vec<(MeshWall, String)> = Vec::new();
    for (i, r) in arr("RigidBodies", &mut p).iter().enumerate() {
        let section = format!("RigidBodies[{i}]");
        let Some(o) = object(r, &section, &mut p) else { continue };
        let (mut translation, mut scale, mut geometry) = ([0.0; 3], [1.0; 3], None);
        let (mut axis, mut angle, mut invert) = ([1.0, 0.0, 0.0], 0.0, false);
        for (key, v) in o {
            let field = format!("{section}.{key}");
            match key.as_str() {
                "geometryFile" => geometry = v.as_str().map(str::to_string),
                "translation" => translation = vec3(v, &field, &mut p).unwrap_or(translation),
                "scale" => scale = vec3(v, &field, &mut p).unwrap_or(scale),
                "rotationAxis" => axis = vec3(v, &field, &mut p).unwrap_or(axis),
                "rotationAngle" => angle = number(v, &field, &mut p).unwrap_or(angle),
                "mapInvert" => invert = boolean(v, &field, &mut p).unwrap_or(invert),
                "isDynamic" => {
                    if boolean(v, &field, &mut p) == Some(true) {
                        p.add(&field, "is true; wgsph's walls are static");
                    }
                }
                "particleFile" => p.add(&field, "is not supported; wgsph samples the box's walls itself"),
                k if SKIPPED_RIGID.contains(&k) => {}
                _ => p.add(&field, "is not a rigid body parameter that wgsph can import"),
            }
        }
        // A turn the walls can be placed by: a finite angle about a non-zero axis.
        if !(angle.is_finite() && angle.abs() <= MAX_ROTATION_RADIANS) {
            use crate::model::numbers::short;
            p.add(format!("{section}.rotationAngle"), format!("is {}; must be a finite angle in radians, at most {} in size", short(angle), short(MAX_ROTATION_RADIANS)));
            continue;
        }
        if angle != 0.0 && !(axis.iter().all(|c| c.is_finite()) && axis.iter().any(|&c| c != 0.0)) {
            use crate::model::numbers::short3;
            p.add(format!("{section}.rotationAxis"), format!("is {}; a rotation needs a finite, non-zero axis", short3(axis)));
            continue;
        }
        let unit_box = |g: &str| g.replace('\\', "/").rsplit('/').next().is_some_and(|f| f.eq_ignore_ascii_case("UnitBox.obj"));
        match geometry {
            Some(g) if unit_box(&g) && angle == 0.0 => {
                // UnitBox.obj is the unit cube centred on the origin, scaled then translated.
                let half = [scale[0].abs() / 2.0, scale[1].abs() / 2.0, scale[2].abs() / 2.0];
                let min = [translation[0] - half[0], translation[1] - half[1], translation[2] - half[2]];
                let max = [translation[0] + half[0], translation[1] + half[1], translation[2] + half[2]];
                walls.push((min, max, section));
            }
            // Another mesh: its walls line its surface, on the side mapInvert leaves to them
            // (a mesh whose fluid is inside, a tank, when it is set). The file is read with
            // the scene, from the scene file's folder.
            Some(g) => meshes.push((
                MeshWall {
                    file: g.replace('\\', "/"),
                    scale,
                    rotation_axis: axis,
                    rotation_degrees: angle.to_degrees(),
                    translate: translation,
                    fluid_inside: invert,
                    crc32: None,
                    walls: WallParticles::default(),
                    surface: Default::default(),
                },
                section,
            )),
            None => p.add(format!("{section}.geometryFile"), "is missing"),
        }
    }

    let h = 4.0 * radius; // SPlisHSPlasH's support radius: twice the particle diameter
    let layers = (h / spacing - 1e-9).ceil().max(1.0);
    let inside = |min: [f64; 3], max: [f64; 3], b: &FluidBlock| (0..3).all(|a| b.min[a] >= min[a] - 1e-9 && b.max[a] <= max[a] + 1e-9);
    let overlaps = |min: [f64; 3], max: [f64; 3], b: &FluidBlock| (0..3).all(|a| b.min[a] < max[a] && b.max[a] > min[a]);
    let mut boundary = Vec::new();
    // The JSON section of each boundary (the planes of a tank come from its rigid body).
    let mut boundary_sections: Vec<String> = Vec::new();
    let mut tanks = 0;
    for (min, max, section) in &walls {
        if !blocks.is_empty() && blocks.iter().all(|b| inside(*min, *max, b)) {
            // A box around the fluid is a closed tank: SPlisHSPlasH samples the box's surface,
            // so the fluid stays inside it.
            tanks += 1;
            boundary.push(Boundary::Container { min: *min, max: *max, open_top: false, walls: WallParticles::default() });
            boundary_sections.push(section.clone());
            if tanks == 1 {
                // Planes on the inner faces back the wall particles up, as in the built-in scenes.
                for a in 0..3 {
                    for (point, sign) in [(*min, 1.0), (*max, -1.0)] {
                        let mut normal = [0.0; 3];
                        normal[a] = sign;
                        boundary.push(Boundary::Plane { point, normal, restitution: 0.0 });
                        boundary_sections.push(section.clone());
                    }
                }
            }
        } else if blocks.iter().any(|b| overlaps(*min, *max, b)) {
            p.add(section.as_str(), "the box neither contains every fluid block (a tank) nor stays clear of them (an obstacle)");
        } else {
            boundary.push(Boundary::Box { min: *min, max: *max, walls: WallParticles::default() });
            boundary_sections.push(section.clone());
        }
    }
    for (mesh, section) in meshes {
        boundary.push(Boundary::Mesh(mesh));
        boundary_sections.push(section);
    }

    if !p.0.is_empty() {
        let (field, message) = if p.0.len() == 1 {
            p.0.remove(0)
        } else {
            let fields: Vec<&str> = p.0.iter().map(|x| x.0.as_str()).collect();
            let all: Vec<String> = p.0.iter().map(|(f, m)| format!("{f}: {m}")).collect();
            (fields.join(", "), format!("{} problems: {}", all.len(), all.join("; ")))
        };
        return Err(fail(&field, format!("{message} (SPlisHSPlasH import)")));
    }

    // The domain holds every block and wall with a margin of wall thickness plus h.
    let margin = layers * spacing + h;
    let mut lo = [f64::INFINITY; 3];
    let mut hi = [f64::NEG_INFINITY; 3];
    for (min, max) in blocks.iter().map(|b| (b.min, b.max)).chain(walls.iter().map(|w| (w.0, w.1))) {
        for a in 0..3 {
            lo[a] = lo[a].min(min[a] - margin);
            hi[a] = hi[a].max(max[a] + margin);
        }
    }
    let mut scene = Scene {
        name: name.to_string(),
        description: format!("imported from the SPlisHSPlasH scene {origin}"),
        seed: 1,
        domain: Domain { min: lo, max: hi },
        physics: Physics {
            rest_density: fluid.density0,
            kernel,
            equation_of_state: eos,
            stiffness: (solver == PressureSolver::Wcsph).then_some(stiffness),
            viscosity: fluid.viscosity,
            // SPlisHSPlasH's boundary viscosity is a coefficient of its own; wgsph scales the
            // fluid's by boundary_friction.
            boundary_friction: if fluid.viscosity > 0.0 { fluid.viscosity_boundary / fluid.viscosity } else { 0.0 },
            gravity,
            solver,
            surface_tension: fluid.surface_tension,
            // Adhesion pulls towards wall particles: a scene without them has none to feel.
            wall_adhesion: if boundary.iter().any(|b| b.walls().is_some()) { fluid.surface_tension_boundary } else { 0.0 },
            // The DFSPH keys of a WCSPH scene are not read (as there).
            dfsph: match solver {
                PressureSolver::Dfsph => DfsphSettings {
                    density_error: max_error / 100.0,
                    divergence_error: max_error_v / 100.0,
                    max_iterations,
                    max_divergence_iterations: max_iterations_v,
                    divergence_solve: enable_divergence,
                    min_iterations: min_iterations.unwrap_or(DfsphSettings::default().min_iterations),
                    ..Default::default()
                },
                PressureSolver::Wcsph => Default::default(),
            },
            ..Physics::new(h, spacing)
        },
        time: if adaptive {
            Time {
                adaptive: true,
                // SPlisHSPlasH's rule, dt = cflFactor 0.4 (2r) / |v|max, is wgsph's
                // dt = C h / |v|max with C = 0.2 cflFactor (h = 4r). A weakly compressible
                // fluid keeps wgsph's own rule, which adds the speed of sound to |v|: without it
                // the step of a fluid at rest grows until the equation of state blows up.
                cfl_number: (solver == PressureSolver::Dfsph).then_some(cfl_factor * 0.4 * 2.0 * radius / h),
                dt_min: Some(cfl_min_dt),
                dt_max: Some(cfl_max_dt),
                ..Time::fixed(dt, end_time)
            }
        } else {
            Time::fixed(dt, end_time)
        },
        fluid: blocks,
        boundary,
        camera: None,
        limits: Default::default(),
        probe: Vec::new(),
    };
    // A scene the import built but wgsph refuses: the error names the JSON key the value came
    // from, not the wgsph field it became.
    let fluid_blocks = scene.fluid.len();
    let named = |e: SceneError| {
        let read_at = |key: &str, at: &HashMap<String, String>, section: &str| at.get(key).cloned().unwrap_or_else(|| format!("{section}.{key}"));
        let field = json_key(&e.field, &boundary_sections, &|key| read_at(key, &config_read_at, "Configuration"), &|key| read_at(key, &fluid_read_at, &fluid_section));
        let mut message = e.message.replace("physics.particle_spacing", "twice Configuration.particleRadius");
        for i in (0..fluid_blocks).rev() {
            message = message.replace(&format!("fluid[{i}]"), &format!("FluidBlocks[{i}]"));
        }
        for (j, section) in boundary_sections.iter().enumerate().rev() {
            message = message.replace(&format!("boundary[{j}]"), section);
        }
        SceneError { field, message: format!("{message} (SPlisHSPlasH import)"), ..e }
    };
    // The meshes' files are read (from the scene file's folder) and their walls taken into the
    // domain, with the margin of the boxes'.
    scene.read_meshes(origin).map_err(named)?;
    for b in &scene.boundary {
        if let (Boundary::Mesh(_), Some((min, max))) = (b, scene.wall_span(b)) {
            for a in 0..3 {
                scene.domain.min[a] = scene.domain.min[a].min(min[a] - margin);
                scene.domain.max[a] = scene.domain.max[a].max(max[a] + margin);
            }
        }
    }
    scene.validate(origin).map_err(named)?;
    Ok((scene, notes))
}

/// The SPlisHSPlasH key a field of the imported scene comes from: `boundaries` is the rigid
/// body of each boundary, `config` and `fluid` give where a key of Configuration and of the
/// fluid's parameters was read (at the top, or in a solver's or method's block).
fn json_key(field: &str, boundaries: &[String], config: &dyn Fn(&str) -> String, fluid: &dyn Fn(&str) -> String) -> String {
    let indexed = |prefix: &str| -> Option<(usize, &str)> {
        let rest = field.strip_prefix(prefix)?;
        let (index, tail) = rest.split_once(']')?;
        Some((index.parse().ok()?, tail))
    };
    if let Some((i, tail)) = indexed("fluid[") {
        let key = match tail {
            ".velocity" => ".initialVelocity",
            ".min" => ".start",
            ".max" => ".end",
            _ => "",
        };
        return format!("FluidBlocks[{i}]{key}");
    }
    if let Some((j, tail)) = indexed("boundary[") {
        let section = boundaries.get(j).cloned().unwrap_or_else(|| "RigidBodies".into());
        return if tail == ".file" { format!("{section}.geometryFile") } else { section };
    }
    match field {
        "physics.smoothing_length" | "physics.particle_spacing" => config("particleRadius"),
        "physics.stiffness" | "physics.speed_of_sound" => config("stiffness"),
        "physics.gravity" => config("gravitation"),
        "time.dt" => config("timeStepSize"),
        "time.cfl_number" => config("cflFactor"),
        "time.dt_min" => config("cflMinTimeStepSize"),
        "time.dt_max" => config("cflMaxTimeStepSize"),
        "physics.dfsph.density_error" => config("maxError"),
        "physics.dfsph.divergence_error" => config("maxErrorV"),
        "physics.dfsph.min_iterations" => format!("{}, {}", config("minIterations"), config("maxIterations")),
        "physics.dfsph.max_iterations" => config("maxIterations"),
        "physics.dfsph.max_divergence_iterations" | "physics.dfsph.min_divergence_iterations" => config("maxIterationsV"),
        "time.end_time" => config("stopAt"),
        "physics.rest_density" => fluid("density0"),
        "physics.viscosity" => fluid("viscosity"),
        "physics.boundary_friction" => fluid("viscosityBoundary"),
        "physics.surface_tension" => fluid("surfaceTension"),
        "physics.wall_adhesion" => fluid("surfaceTensionBoundary"),
        "fluid" => "FluidBlocks".into(),
        // The domain and the grid follow from the blocks and the bodies.
        "domain" => "FluidBlocks, RigidBodies (the domain around them)".into(),
        other => other.into(),
    }
}
