//! Surface meshes of the fluid: marching cubes over an SPH density field of the particles, by
//! splashsurf_lib (Löschner et al., splashsurf), written as OBJ or PLY triangle meshes.

use crate::io::atomic::write_atomic;
use crate::model::params::Params;
use crate::model::state::Snapshot;
use serde::{Deserialize, Serialize};
use splashsurf_lib::nalgebra::Vector3;
use std::path::{Path, PathBuf};

/// The file format of surface meshes (`--surface-mesh-format`).
#[derive(Copy, Clone, Debug, Default, PartialEq, Eq, Hash, Serialize, Deserialize, clap::ValueEnum)]
#[serde(rename_all = "snake_case")]
pub enum MeshFormat {
    /// Wavefront OBJ (text): `v x y z` and `f a b c` lines.
    #[default]
    Obj,
    /// Binary little-endian PLY: float vertices and triangle faces.
    Ply,
}

impl MeshFormat {
    pub fn extension(self) -> &'static str {
        match self {
            MeshFormat::Obj => "obj",
            MeshFormat::Ply => "ply",
        }
    }
}

/// A triangle mesh.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct SurfaceMesh {
    pub vertices: Vec<[f32; 3]>,
    pub triangles: Vec<[u32; 3]>,
}

/// How the surface is reconstructed, in the scene's length unit.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct SurfaceParameters {
    /// Radius of a particle: half the particle spacing (its volume is (2r)^3).
    pub particle_radius: f64,
    /// Support radius of the kernel of the density field.
    pub compact_support_radius: f64,
    /// Edge of the marching-cubes cells.
    pub cube_size: f64,
    /// The surface is where the density field is this fraction of the rest density.
    pub iso_surface_threshold: f64,
    pub rest_density: f64,
}

impl SurfaceParameters {
    /// The defaults for a scene: r = spacing / 2, the scene's h as support radius (splashsurf
    /// recommends about 4r, which is h in the built-in scenes), cubes of 0.75 r and the
    /// threshold 0.6 that splashsurf uses by default.
    pub fn for_scene(params: &Params, particle_spacing: f64) -> Self {
        let r = particle_spacing / 2.0;
        SurfaceParameters {
            particle_radius: r,
            compact_support_radius: params.h,
            cube_size: 0.75 * r,
            iso_surface_threshold: 0.6,
            rest_density: params.rest_density,
        }
    }
}

/// Reconstructs the fluid surface around `positions`.
pub fn reconstruct(positions: &[[f64; 3]], p: &SurfaceParameters) -> anyhow::Result<SurfaceMesh> {
    if positions.is_empty() {
        return Ok(SurfaceMesh::default());
    }
    let points: Vec<Vector3<f32>> = positions.iter().map(|q| Vector3::new(q[0] as f32, q[1] as f32, q[2] as f32)).collect();
    let mut parameters =
        splashsurf_lib::Parameters::<f32>::new(p.particle_radius as f32, p.compact_support_radius as f32, p.cube_size as f32);
    parameters.rest_density = p.rest_density as f32;
    parameters.iso_surface_threshold = p.iso_surface_threshold as f32;
    // Threads would make the order of vertices and triangles vary from run to run; one thread
    // gives the same mesh (and so the same files and pictures) for the same particles.
    parameters.enable_multi_threading = false;
    let reconstruction = splashsurf_lib::reconstruct_surface::<i64, f32>(&points, &parameters)
        .map_err(|e| anyhow::anyhow!("surface reconstruction failed: {e}"))?;
    let mesh = reconstruction.mesh;
    anyhow::ensure!(mesh.vertices.len() <= u32::MAX as usize, "the surface mesh has more vertices than u32 indices address");
    Ok(SurfaceMesh {
        vertices: mesh.vertices.iter().map(|v| [v.x, v.y, v.z]).collect(),
        triangles: mesh.triangles.iter().map(|t| [t[0] as u32, t[1] as u32, t[2] as u32]).collect(),
    })
}

/// Unit normals at the vertices of `mesh`: area-weighted means of the adjacent triangles' normals
/// (splashsurf_lib's `TriMesh3d::vertex_normals`), oriented by the triangles' winding. A vertex
/// with no triangle of non-zero area gets the zero vector.
pub fn vertex_normals(mesh: &SurfaceMesh) -> Vec<[f32; 3]> {
    let tri_mesh = splashsurf_lib::mesh::TriMesh3d::<f32> {
        vertices: mesh.vertices.iter().map(|v| Vector3::new(v[0], v[1], v[2])).collect(),
        triangles: mesh.triangles.iter().map(|t| t.map(|i| i as usize)).collect(),
    };
    // The sequential version: its sums are in a fixed order, so pictures repeat exactly.
    tri_mesh
        .vertex_normals()
        .iter()
        .map(|n| if n.iter().all(|c| c.is_finite()) { [n.x, n.y, n.z] } else { [0.0; 3] })
        .collect()
}

/// The mesh file of a step: `DIR/surface/step_000123.obj`.
pub fn mesh_file(out: &Path, step: u64, format: MeshFormat) -> PathBuf {
    out.join("surface").join(format!("step_{step:06}.{}", format.extension()))
}

/// Writes a mesh as OBJ (with the step and time in a comment) or binary PLY, atomically.
pub fn write_mesh(path: &Path, format: MeshFormat, mesh: &SurfaceMesh, step: u64, time: f64) -> anyhow::Result<()> {
    match format {
        MeshFormat::Obj => write_atomic(path, |w| {
            writeln!(w, "# wgsph surface mesh, step {step}, time {time}")?;
            for v in &mesh.vertices {
                writeln!(w, "v {} {} {}", v[0], v[1], v[2])?;
            }
            for t in &mesh.triangles {
                // OBJ indices start at 1.
                writeln!(w, "f {} {} {}", t[0] + 1, t[1] + 1, t[2] + 1)?;
            }
            Ok(())
        }),
        MeshFormat::Ply => write_mesh_ply(path, mesh, step, time),
    }
}

/// One element of a PLY mesh: a vertex or a face.
#[derive(Clone, Debug, Default)]
struct PlyItem {
    position: [f32; 3],
    indices: Vec<u32>,
}

impl ply_rs_bw::ply::PropertyAccess for PlyItem {
    fn new() -> Self {
        PlyItem::default()
    }
    fn get_float(&self, name: &str) -> Option<f32> {
        ["x", "y", "z"].iter().position(|&p| p == name).map(|i| self.position[i])
    }
    fn get_list_uint(&self, name: &str) -> Option<&[u32]> {
        (name == "vertex_indices").then_some(self.indices.as_slice())
    }
}

fn write_mesh_ply(path: &Path, mesh: &SurfaceMesh, step: u64, time: f64) -> anyhow::Result<()> {
    use ply_rs_bw::ply::{Addable, ElementDef, Encoding, Ply, PropertyDef, PropertyType, ScalarType};
    let mut ply = Ply::<PlyItem>::new();
    ply.header.encoding = Encoding::BinaryLittleEndian;
    ply.header.comments.push("wgsph surface mesh".into());
    ply.header.comments.push(format!("step {step}"));
    ply.header.comments.push(format!("time {time}"));
    let mut vertex = ElementDef::new("vertex".into());
    for p in ["x", "y", "z"] {
        vertex.properties.add(PropertyDef::new(p.into(), PropertyType::Scalar(ScalarType::Float)));
    }
    ply.header.elements.add(vertex);
    let mut face = ElementDef::new("face".into());
    face.properties.add(PropertyDef::new("vertex_indices".into(), PropertyType::List(ScalarType::UChar, ScalarType::UInt)));
    ply.header.elements.add(face);
    ply.payload.insert("vertex".into(), mesh.vertices.iter().map(|&position| PlyItem { position, indices: vec![] }).collect());
    ply.payload.insert("face".into(), mesh.triangles.iter().map(|t| PlyItem { position: [0.0; 3], indices: t.to_vec() }).collect());
    let writer = ply_rs_bw::writer::Writer::<PlyItem>::new();
    write_atomic(path, |mut w| writer.write_ply(&mut w, &mut ply).map(|_| ()))
}

/// Reconstructs and writes the surface of a snapshot; returns the file written.
pub fn write_snapshot_surface(out: &Path, s: &Snapshot, p: &SurfaceParameters, format: MeshFormat) -> anyhow::Result<PathBuf> {
    let mesh = reconstruct(&s.positions, p)?;
    let path = mesh_file(out, s.step, format);
    write_mesh(&path, format, &mesh, s.step, s.time)?;
    log::info!("wrote {} ({} triangles)", path.display(), mesh.triangles.len());
    Ok(path)
}
