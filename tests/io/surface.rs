//! Surface meshes: a closed surface around a block of particles with its volume, and the
//! meshes of a dam-break run in OBJ and PLY.

use std::collections::HashMap;
use std::path::Path;
use std::process::{Command, Output};
use wgsph::io::snapshot::csv::read_snapshot_csv;
use wgsph::io::surface::reconstruct;
use wgsph::io::surface::SurfaceMesh;
use wgsph::io::surface::SurfaceParameters;

fn wgsph(args: &[&str], dir: &Path) -> Output {
    Command::new(env!("CARGO_BIN_EXE_wgsph")).args(args).current_dir(dir).output().unwrap()
}

/// Every edge is shared by exactly two triangles, in opposite directions (closed, oriented).
fn assert_closed(m: &SurfaceMesh) {
    let mut edges: HashMap<(u32, u32), i32> = HashMap::new();
    for t in &m.triangles {
        for k in 0..3 {
            let (a, b) = (t[k], t[(k + 1) % 3]);
            assert!((a as usize) < m.vertices.len() && (b as usize) < m.vertices.len());
            *edges.entry((a.min(b), a.max(b))).or_default() += if a < b { 1 } else { -1 };
        }
    }
    let mut count: HashMap<(u32, u32), u32> = HashMap::new();
    for t in &m.triangles {
        for k in 0..3 {
            let (a, b) = (t[k], t[(k + 1) % 3]);
            *count.entry((a.min(b), a.max(b))).or_default() += 1;
        }
    }
    assert!(count.values().all(|&c| c == 2), "an edge is not shared by exactly two triangles");
    assert!(edges.values().all(|&d| d == 0), "the triangles are not consistently oriented");
}

/// Enclosed volume by the divergence theorem.
fn volume(m: &SurfaceMesh) -> f64 {
    m.triangles
        .iter()
        .map(|t| {
            let [a, b, c] = t.map(|i| m.vertices[i as usize].map(|x| x as f64));
            (a[0] * (b[1] * c[2] - b[2] * c[1]) - a[1] * (b[0] * c[2] - b[2] * c[0]) + a[2] * (b[0] * c[1] - b[1] * c[0])) / 6.0
        })
        .sum()
}

#[test]
fn a_block_of_particles_gets_a_closed_surface_of_its_volume() {
    // 10 x 10 x 10 particles at spacing 0.02: a 0.2 m cube.
    let s = 0.02;
    let positions: Vec<[f64; 3]> =
        (0..1000).map(|i| [(i % 10) as f64 + 0.5, ((i / 10) % 10) as f64 + 0.5, (i / 100) as f64 + 0.5].map(|c| c * s)).collect();
    let p = SurfaceParameters { particle_radius: s / 2.0, compact_support_radius: 2.0 * s, cube_size: 0.375 * s, iso_surface_threshold: 0.6, rest_density: 1000.0 };
    let m = reconstruct(&positions, &p).unwrap();
    assert!(m.triangles.len() > 100);
    assert_closed(&m);
    let v = volume(&m);
    assert!((v / 0.008 - 1.0).abs() < 0.2, "volume {v} against 0.008");
    for a in 0..3 {
        let lo = m.vertices.iter().map(|q| q[a] as f64).fold(f64::INFINITY, f64::min);
        let hi = m.vertices.iter().map(|q| q[a] as f64).fold(f64::NEG_INFINITY, f64::max);
        assert!(lo > -s && lo < s && hi > 0.2 - s && hi < 0.2 + s, "axis {a}: {lo}..{hi}");
    }
    assert_eq!(reconstruct(&[], &p).unwrap(), SurfaceMesh::default());
}

fn read_obj(path: &Path) -> SurfaceMesh {
    let mut m = SurfaceMesh::default();
    for line in std::fs::read_to_string(path).unwrap().lines() {
        let f: Vec<&str> = line.split_whitespace().collect();
        match f.first() {
            Some(&"v") => m.vertices.push([f[1], f[2], f[3]].map(|x| x.parse().unwrap())),
            Some(&"f") => m.triangles.push([f[1], f[2], f[3]].map(|x| x.parse::<u32>().unwrap() - 1)),
            _ => {}
        }
    }
    m
}

fn read_ply(path: &Path) -> SurfaceMesh {
    use ply_rs_bw::ply::{DefaultElement, Property};
    let mut f = std::fs::File::open(path).unwrap();
    let ply = ply_rs_bw::parser::Parser::<DefaultElement>::new().read_ply(&mut f).unwrap();
    let float = |p: &Property| match p {
        Property::Float(x) => *x,
        other => panic!("{other:?}"),
    };
    SurfaceMesh {
        vertices: ply.payload["vertex"].iter().map(|v| [float(&v["x"]), float(&v["y"]), float(&v["z"])]).collect(),
        triangles: ply.payload["face"]
            .iter()
            .map(|f| match &f["vertex_indices"] {
                Property::ListUInt(l) => [l[0], l[1], l[2]],
                other => panic!("{other:?}"),
            })
            .collect(),
    }
}

#[test]
fn a_dam_break_run_writes_surface_meshes_around_its_particles() {
    let dir = tempfile::tempdir().unwrap();
    for (format, out) in [("obj", "o"), ("ply", "p")] {
        let o = wgsph(
            &["run", "dam_break", "--particles", "1500", "--steps", "10", "--snapshot-every", "10", "--surface-mesh-every", "5", "--surface-mesh-format", format, "--backend", "cpu", "--out", out],
            dir.path(),
        );
        assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
        let d = dir.path().join(out);
        for step in [0, 5, 10] {
            let path = d.join(format!("surface/step_{step:06}.{format}"));
            let m = if format == "obj" { read_obj(&path) } else { read_ply(&path) };
            assert!(m.triangles.len() > 100, "{}", path.display());
            assert_closed(&m);
            if step != 5 {
                // Every particle lies within the mesh's bounding box.
                let s = read_snapshot_csv(&d.join(format!("snapshots/step_{step:06}.csv"))).unwrap();
                for a in 0..3 {
                    let lo = m.vertices.iter().map(|q| q[a] as f64).fold(f64::INFINITY, f64::min);
                    let hi = m.vertices.iter().map(|q| q[a] as f64).fold(f64::NEG_INFINITY, f64::max);
                    assert!(s.positions.iter().all(|p| p[a] > lo && p[a] < hi), "{format} step {step} axis {a}");
                }
            }
        }
        // Only the chosen format; surface meshes at 5 without a particle snapshot.
        assert!(!d.join("snapshots/step_000005.csv").exists());
    }
    let o = wgsph(&["run", "--surface-mesh-format", "stl"], dir.path());
    assert_eq!(o.status.code(), Some(2));
}
