//! Mesh boundaries: walls lining a closed OBJ or STL surface, on the lattice of the domain's
//! corner; the fluid blocks cut by the surface; the file found from the scene's folder,
//! recorded by its CRC-32 in a run's scene, and refused with its field when it cannot be used.

use std::path::Path;
use std::process::{Command, Output};
use wgsph::model::scene::{Boundary, Scene, SceneOrigin};

fn wgsph(args: &[&str], dir: &Path) -> Output {
    Command::new(env!("CARGO_BIN_EXE_wgsph")).args(args).current_dir(dir).output().unwrap()
}

/// The unit cube 0..1, its faces as quads.
const CUBE: &str = "v 0 0 0\nv 1 0 0\nv 1 1 0\nv 0 1 0\nv 0 0 1\nv 1 0 1\nv 1 1 1\nv 0 1 1\n\
    f 1 4 3 2\nf 5 6 7 8\nf 1 2 6 5\nf 4 8 7 3\nf 1 5 8 4\nf 2 3 7 6\n";

/// A scene at spacing 0.02 (h = 0.04, two wall layers) in the domain -0.1..0.5 (on whose
/// lattice the round coordinates below are faces), with the given fluid block and boundaries.
fn scene_text(fluid: &str, boundaries: &str) -> String {
    format!(
        "name = \"meshes\"\n[domain]\nmin = [-0.1, -0.1, -0.1]\nmax = [0.5, 0.5, 0.5]\n\
         [physics]\nsmoothing_length = 0.04\nparticle_spacing = 0.02\nspeed_of_sound = 20.0\nviscosity = 0.001\n\
         [time]\ndt = 0.0004\nend_time = 1.0\n[[fluid]]\n{fluid}\njitter = 0.0\n{boundaries}"
    )
}

fn write(dir: &Path, name: &str, text: &str) -> std::path::PathBuf {
    let path = dir.join(name);
    std::fs::create_dir_all(path.parent().unwrap()).unwrap();
    std::fs::write(&path, text).unwrap();
    path
}

fn load(path: &Path) -> Result<Scene, String> {
    Scene::load(path.to_str().unwrap()).map_err(|e| e.to_string())
}

/// The distance from `p` to the box `lo..hi` (0 inside).
fn box_distance(p: [f64; 3], lo: [f64; 3], hi: [f64; 3]) -> f64 {
    (0..3).map(|a| (lo[a] - p[a]).max(p[a] - hi[a]).max(0.0).powi(2)).sum::<f64>().sqrt()
}

/// A cube mesh holding the fluid is a closed container whose walls are a distance's band: the
/// same wall particles but for those of the container's edges and corners farther than the
/// walls' depth from the box, and the same fluid.
#[test]
fn a_mesh_tank_is_lined_like_a_closed_container() {
    let dir = tempfile::tempdir().unwrap();
    write(dir.path(), "cube.obj", CUBE);
    let fluid = "min = [0.0, 0.0, 0.0]\nmax = [0.4, 0.2, 0.2]";
    let (lo, hi) = ([0.0; 3], [0.4, 0.3, 0.2]);
    let mesh = load(&write(dir.path(), "mesh.toml", &scene_text(fluid, "[[boundary]]\ntype = \"mesh\"\nfile = \"cube.obj\"\nscale = [0.4, 0.3, 0.2]\nfluid_inside = true\n"))).unwrap();
    let tank = load(&write(dir.path(), "tank.toml", &scene_text(fluid, "[[boundary]]\ntype = \"container\"\nmin = [0.0, 0.0, 0.0]\nmax = [0.4, 0.3, 0.2]\nopen_top = false\n"))).unwrap();
    let (m, t) = (mesh.initial_state(), tank.initial_state());
    assert_eq!(m.fluid_positions, t.fluid_positions);
    assert_eq!(mesh.fluid_particle_count(), t.fluid_positions.len() as u64);
    let key = |p: &[f64; 3]| p.map(|c| (c / 0.01).round() as i64);
    let mut expected: Vec<[i64; 3]> = t.wall_positions.iter().filter(|p| box_distance(**p, lo, hi) < 0.04).map(key).collect();
    let mut got: Vec<[i64; 3]> = m.wall_positions.iter().map(key).collect();
    expected.sort_unstable();
    got.sort_unstable();
    assert_eq!(got, expected);
    assert!(t.wall_positions.len() > m.wall_positions.len());
    // Every wall particle's mass is its lattice cell's at the fluid's rest density.
    assert!(m.wall_masses.iter().all(|&w| (w - 1000.0 * 0.02f64.powi(3)).abs() < 1e-12));
    assert!(m.wall_boundaries.iter().all(|&b| b == 0));
}

/// A solid mesh (a cube turned 45 degrees about y, standing in the fluid block) takes the
/// fluid's place: no fluid particle starts inside it or nearer than half a spacing to its
/// surface, and its walls fill its inside to the walls' depth. The count computed without
/// creating the particles is theirs.
#[test]
fn a_solid_mesh_cuts_the_fluid_around_it() {
    let dir = tempfile::tempdir().unwrap();
    write(dir.path(), "cube.obj", CUBE);
    // The cube 0.12 on a side, turned about its corner at the file's origin and moved into the
    // block.
    let boundaries = "[[boundary]]\ntype = \"container\"\nmin = [0.0, 0.0, 0.0]\nmax = [0.4, 0.4, 0.4]\n\
        [[boundary]]\ntype = \"mesh\"\nfile = \"cube.obj\"\nscale = [0.12, 0.12, 0.12]\ntranslate = [0.2, 0.06, 0.2]\n\
        rotation_axis = [0.0, 1.0, 0.0]\nrotation_degrees = 45.0\n";
    let text = scene_text("min = [0.0, 0.0, 0.0]\nmax = [0.4, 0.2, 0.4]", boundaries);
    let path = write(dir.path(), "solid.toml", &text);
    let scene = load(&path).unwrap();
    let st = scene.initial_state();
    // The cube in its own frame: turned back by 45 degrees about y around its corner at the
    // translation, it spans 0..0.12 on every axis.
    let local = |p: [f64; 3]| {
        let (x, z) = (p[0] - 0.2, p[2] - 0.2);
        let (s, c) = (-45f64).to_radians().sin_cos();
        [c * x + s * z, p[1] - 0.06, -s * x + c * z]
    };
    let (lo, hi) = ([0.0; 3], [0.12; 3]);
    let inside = |q: [f64; 3]| (0..3).all(|a| q[a] > lo[a] && q[a] < hi[a]);
    let depth = |q: [f64; 3]| (0..3).map(|a| (q[a] - lo[a]).min(hi[a] - q[a])).fold(f64::INFINITY, f64::min);
    let cut = st.fluid_positions.iter().filter(|p| inside(local(**p)) || box_distance(local(**p), lo, hi) < 0.01 - 1e-9).count();
    assert_eq!(cut, 0);
    let walls: Vec<[f64; 3]> = st.wall_positions.iter().zip(&st.wall_boundaries).filter(|(_, &b)| b == 1).map(|(p, _)| *p).collect();
    // (A lattice point on a turned face may fall on either side: it counts as on the surface.)
    let on_or_inside = |q: [f64; 3]| (0..3).all(|a| q[a] > lo[a] - 1e-9 && q[a] < hi[a] + 1e-9);
    assert!(walls.iter().all(|p| on_or_inside(local(*p)) && depth(local(*p)) < 0.04 + 1e-9));
    // The cube's 1.73e-3 m^3 holds about 216 lattice cells; its inner core farther than 0.04
    // from the faces (0.04^3) about 8: the walls are the difference, to within the lattice's
    // steps on the turned faces.
    assert!((170..=240).contains(&walls.len()), "{} wall particles", walls.len());
    // The cut took the cube's volume and a shell of about half a spacing around it.
    let full = 20 * 10 * 20;
    let removed = full - st.fluid_positions.len();
    assert!((216..=400).contains(&removed), "{removed} fluid particles cut");
    assert_eq!(scene.fluid_particle_count(), st.fluid_positions.len() as u64);
}

/// The file is read from the scene file's folder; the scene keeps its absolute path and its
/// CRC-32, so that the scene written into a run's folder loads from anywhere and refuses a file
/// changed since. A file that cannot be used is refused naming the field and why; a probe in
/// the solid is refused; `--set` of another file reads that one.
#[test]
fn a_mesh_file_is_found_recorded_and_checked() {
    let dir = tempfile::tempdir().unwrap();
    let mesh_path = write(dir.path(), "meshes/cube.obj", CUBE);
    let boundaries = "[[boundary]]\ntype = \"container\"\nmin = [0.0, 0.0, 0.0]\nmax = [0.4, 0.4, 0.4]\n\
        [[boundary]]\ntype = \"mesh\"\nfile = \"../meshes/cube.obj\"\nscale = [0.1, 0.1, 0.1]\ntranslate = [0.2, 0.0, 0.2]\n";
    let fluid = "min = [0.0, 0.0, 0.0]\nmax = [0.16, 0.2, 0.4]";
    let path = write(dir.path(), "scenes/s.toml", &scene_text(fluid, boundaries));
    let scene = load(&path).unwrap();
    let Boundary::Mesh(m) = &scene.boundary[1] else { panic!("a mesh") };
    assert!(Path::new(&m.file).is_absolute() && m.file.ends_with("cube.obj"), "{}", m.file);
    assert_eq!(m.crc32.as_deref(), Some(format!("{:08x}", crc32fast::hash(CUBE.as_bytes())).as_str()));
    // Written and read back from another folder: the same scene.
    let copy = write(dir.path(), "elsewhere/scene.toml", &scene.to_toml());
    assert_eq!(load(&copy).unwrap(), scene);

    // A changed file: the recorded scene refuses it; the user's scene (no CRC) takes it.
    std::fs::write(&mesh_path, format!("{CUBE}# edited\n")).unwrap();
    let e = load(&copy).unwrap_err();
    assert!(e.contains("boundary[1].file") && e.contains("has changed") && e.contains("boundary[1].crc32"), "{e}");
    assert!(load(&path).is_ok());
    // A recorded CRC that is not one is named as such, not as a changed file.
    let bad_crc = write(dir.path(), "elsewhere/bad_crc.toml", &scene.to_toml().replace(m.crc32.as_deref().unwrap(), "abc"));
    let e = load(&bad_crc).unwrap_err();
    assert!(e.contains("boundary[1].crc32: is 'abc'; must be the file's CRC-32 as 8 hexadecimal digits"), "{e}");

    let refused = |mesh: &str, file_text: Option<&str>| {
        if let Some(t) = file_text {
            write(dir.path(), &format!("meshes/{mesh}"), t);
        }
        let text = scene_text(fluid, &boundaries.replace("cube.obj", mesh));
        load(&write(dir.path(), "scenes/bad.toml", &text)).unwrap_err()
    };
    let e = refused("missing.obj", None);
    assert!(e.contains("boundary[1].file") && e.contains("missing.obj") && e.contains("cannot read the mesh file"), "{e}");
    let open = CUBE.replace("f 2 3 7 6\n", "");
    let e = refused("open.obj", Some(&open));
    assert!(e.contains("boundary[1].file") && e.contains("not a closed surface") && e.contains("4 of its edges"), "{e}");
    let e = refused("cube.ply", Some(CUBE));
    assert!(e.contains("boundary[1].file") && e.contains("'ply'"), "{e}");
    let e = refused("broken.obj", Some("v 0 0 0\nf 1 2 3\n"));
    assert!(e.contains("boundary[1].file") && e.contains("line 2") && e.contains("past the last vertex"), "{e}");
    let e = load(&write(dir.path(), "scenes/zero.toml", &scene_text(fluid, &boundaries.replace("scale = [0.1, 0.1, 0.1]", "scale = [0.1, 0.0, 0.1]")))).unwrap_err();
    assert!(e.contains("boundary[1].scale") && e.contains("non-zero"), "{e}");
    // A mesh whose walls reach out of the domain.
    let e = load(&write(dir.path(), "scenes/out.toml", &scene_text(fluid, &boundaries.replace("translate = [0.2, 0.0, 0.2]", "translate = [0.45, 0.0, 0.2]")))).unwrap_err();
    assert!(e.contains("boundary[1]") && e.contains("outside the domain"), "{e}");
    // A plate thinner than the wall spacing would hold no wall particle: refused, and taken
    // with walls of a finer spacing.
    let plate = boundaries.replace("scale = [0.1, 0.1, 0.1]\ntranslate = [0.2, 0.0, 0.2]", "scale = [0.1, 0.005, 0.1]\ntranslate = [0.2, 0.1, 0.2]");
    assert_ne!(plate, boundaries);
    let e = load(&write(dir.path(), "scenes/plate.toml", &scene_text(fluid, &plate))).unwrap_err();
    assert!(e.contains("boundary[1]") && e.contains("no lattice point of the wall spacing 0.02"), "{e}");
    let fine = scene_text(fluid, &format!("{plate}spacing = 0.004\n"));
    let scene = load(&write(dir.path(), "scenes/plate.toml", &fine)).unwrap();
    assert_eq!(scene.initial_walls().wall_boundaries.iter().filter(|&&b| b == 1).count(), 25 * 25);
    // A probe inside the solid (the mesh's surface is allowed).
    let probe = |at: &str| format!("{}[[probe]]\nname = \"p\"\ntype = \"point\"\nposition = {at}\n", scene_text(fluid, boundaries));
    let e = load(&write(dir.path(), "scenes/probe.toml", &probe("[0.25, 0.05, 0.25]"))).unwrap_err();
    assert!(e.contains("probe[0] ('p').position") && e.contains("the solid of boundary[1]"), "{e}");
    assert!(load(&write(dir.path(), "scenes/probe.toml", &probe("[0.2, 0.05, 0.25]"))).is_ok());

    // --set of another file reads it (and records its CRC); the same file keeps the triangles.
    let big: String = CUBE.lines().map(|l| if l.starts_with("v ") { l.replace('1', "1.5") } else { l.to_string() } + "\n").collect();
    write(dir.path(), "meshes/big.obj", &big);
    let scene = load(&path).unwrap();
    let overrides = [format!("boundary.1.file={}", dir.path().join("meshes/big.obj").display()).parse().unwrap()];
    let other = scene.with_overrides(&overrides, &SceneOrigin::File(path.clone())).unwrap();
    let Boundary::Mesh(b) = &other.boundary[1] else { panic!("a mesh") };
    assert_eq!(b.crc32.as_deref(), Some(format!("{:08x}", crc32fast::hash(big.as_bytes())).as_str()));
    assert!(other.initial_walls().wall_positions.len() > scene.initial_walls().wall_positions.len());
}

/// A scene with a solid mesh runs from the command line on both paths, with the walls the
/// scene makes.
#[test]
fn a_mesh_scene_runs_on_both_paths() {
    let dir = tempfile::tempdir().unwrap();
    write(dir.path(), "cube.obj", CUBE);
    let boundaries = "[[boundary]]\ntype = \"container\"\nmin = [0.0, 0.0, 0.0]\nmax = [0.4, 0.4, 0.4]\n\
        [[boundary]]\ntype = \"mesh\"\nfile = \"cube.obj\"\nscale = [0.1, 0.1, 0.1]\ntranslate = [0.25, 0.0, 0.15]\nrotation_axis = [0, 1, 0]\nrotation_degrees = 30\n";
    let path = write(dir.path(), "s.toml", &scene_text("min = [0.0, 0.0, 0.0]\nmax = [0.12, 0.2, 0.4]", boundaries));
    let walls = load(&path).unwrap().initial_walls().wall_positions.len() as u64;
    for backend in ["cpu", "gpu"] {
        let out = format!("o_{backend}");
        let o = wgsph(&["run", "s.toml", "--steps", "10", "--backend", backend, "--quiet", "--out", &out], dir.path());
        assert!(o.status.success(), "{backend}: {}", String::from_utf8_lossy(&o.stderr));
        let s: serde_json::Value = serde_json::from_str(&std::fs::read_to_string(dir.path().join(&out).join("summary.json")).unwrap()).unwrap();
        assert_eq!(s["wall_particles"].as_u64(), Some(walls), "{backend}");
        assert_eq!(s["nan_count"].as_u64(), Some(0), "{backend}");
        assert_eq!(s["escaped"].as_u64(), Some(0), "{backend}");
    }
}

/// The example scene of the README loads: its pier is the cylinder file beside it, closed,
/// and its walls stand within the pier's radius of its axis, up to its height.
#[test]
fn the_pier_example_loads_with_its_mesh() {
    let path = Path::new(env!("CARGO_MANIFEST_DIR")).join("scenes/dam_break_pier.toml");
    let scene = load(&path).unwrap();
    let Boundary::Mesh(m) = &scene.boundary[1] else { panic!("boundary[1] is the pier") };
    assert!(m.file.ends_with("cylinder.obj") && Path::new(&m.file).is_absolute());
    let walls = scene.initial_walls();
    let pier: Vec<[f64; 3]> = walls.wall_positions.iter().zip(&walls.wall_boundaries).filter(|(_, &b)| b == 1).map(|(p, _)| *p).collect();
    assert!(!pier.is_empty());
    for p in &pier {
        let r = ((p[0] - 1.0).powi(2) + (p[2] - 0.2).powi(2)).sqrt();
        assert!(r < 0.06 && p[1] > 0.0 && p[1] < 0.6, "{p:?}");
    }
    // Two layers (h = 2 spacings) inside the 0.06 m radius: a ring from about 0.02 m to 0.06 m
    // around the axis, and the core of the 2 x 2 lattice points nearest the axis left out.
    assert!(!pier.iter().any(|p| ((p[0] - 1.0).powi(2) + (p[2] - 0.2).powi(2)).sqrt() < 0.015 && p[1] > 0.05 && p[1] < 0.55));
}
