//! Binary PLY point clouds for Blender, splashsurf and MeshLab.

use super::csv::refuse_non_finite;
use crate::io::atomic::write_atomic;
use crate::model::state::Snapshot;
use std::path::Path;

/// The vertex properties of a PLY snapshot, in file order (all `float`).
pub const PLY_PROPERTIES: [&str; 8] = ["x", "y", "z", "vx", "vy", "vz", "density", "pressure"];

/// One PLY vertex: the values of `PLY_PROPERTIES`.
#[derive(Clone, Copy, Debug, Default)]
pub(crate) struct PlyVertex(pub [f32; 8]);

impl ply_rs_bw::ply::PropertyAccess for PlyVertex {
    fn new() -> Self {
        PlyVertex::default()
    }
    fn get_float(&self, name: &str) -> Option<f32> {
        PLY_PROPERTIES.iter().position(|&p| p == name).map(|i| self.0[i])
    }
}

/// Writes `s` as a binary little-endian PLY point cloud with the float vertex properties
/// `x y z vx vy vz density pressure` (single precision: what Blender and splashsurf read) and
/// header comments `step N` and `time T`.
pub fn write_ply(path: &Path, s: &Snapshot) -> anyhow::Result<()> {
    use ply_rs_bw::ply::Ply;
    refuse_non_finite(path, s)?;
    let mut ply = Ply::<PlyVertex>::new();
    ply.header = ply_header(s.step, s.time, s.len());
    let vertices: Vec<PlyVertex> = (0..s.len())
        .map(|i| {
            let (p, v) = (s.positions[i], s.velocities[i]);
            PlyVertex([p[0], p[1], p[2], v[0], v[1], v[2], s.densities[i], s.pressures[i]].map(|x| x as f32))
        })
        .collect();
    ply.payload.insert("vertex".into(), vertices);
    let writer = ply_rs_bw::writer::Writer::<PlyVertex>::new();
    write_atomic(path, |mut w| writer.write_ply(&mut w, &mut ply).map(|_| ()))
}

/// The header of a PLY snapshot of `particles` vertices (shared by the streamed writer, so that
/// both write the same bytes).
pub(crate) fn ply_header(step: u64, time: f64, particles: usize) -> ply_rs_bw::ply::Header {
    use ply_rs_bw::ply::{Addable, ElementDef, Encoding, Header, PropertyDef, PropertyType, ScalarType};
    let mut header = Header::new();
    header.encoding = Encoding::BinaryLittleEndian;
    header.comments.push("wgsph particle snapshot".into());
    header.comments.push(format!("step {step}"));
    header.comments.push(format!("time {time}"));
    let mut vertex = ElementDef::new("vertex".into());
    vertex.count = particles;
    for p in PLY_PROPERTIES {
        vertex.properties.add(PropertyDef::new(p.into(), PropertyType::Scalar(ScalarType::Float)));
    }
    header.elements.add(vertex);
    header
}

