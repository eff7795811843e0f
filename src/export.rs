//! Snapshot files for other programs: legacy VTK for ParaView (with a `.vtk.series` index so a
//! run opens as an animation), binary PLY for Blender and splashsurf, and the project's CSV.
//!
//! Every file is written atomically (see [`crate::output::write_atomic`]) and a snapshot holding
//! NaN or infinity is refused, as for CSV.

use crate::output::{write_atomic, write_snapshot_csv};
use crate::sim::Snapshot;
use anyhow::Context;
use serde::{Deserialize, Serialize};
use std::path::{Path, PathBuf};

pub mod stream;

/// A snapshot file format (`--format`).
#[derive(Copy, Clone, Debug, PartialEq, Eq, Hash, Serialize, Deserialize, clap::ValueEnum)]
#[serde(rename_all = "snake_case")]
pub enum SnapshotFormat {
    /// `x,y,z,vx,vy,vz,density,pressure`, one line per particle.
    Csv,
    /// Legacy binary VTK unstructured grid of vertex cells (ParaView, VisIt), with a
    /// `particles.vtk.series` index.
    Vtk,
    /// Binary little-endian PLY point cloud (Blender, splashsurf, MeshLab).
    Ply,
}

impl SnapshotFormat {
    pub fn extension(self) -> &'static str {
        match self {
            SnapshotFormat::Csv => "csv",
            SnapshotFormat::Vtk => "vtk",
            SnapshotFormat::Ply => "ply",
        }
    }
}

/// Name of the ParaView file-series index beside the VTK snapshots.
pub const VTK_SERIES_NAME: &str = "particles.vtk.series";

/// The file of a step's snapshot in a format: `DIR/snapshots/step_000123.vtk`.
pub fn snapshot_file(out: &Path, step: u64, format: SnapshotFormat) -> PathBuf {
    out.join("snapshots").join(format!("step_{step:06}.{}", format.extension()))
}

fn refuse_non_finite(path: &Path, s: &Snapshot) -> anyhow::Result<()> {
    let bad = s.non_finite_count();
    if bad > 0 {
        anyhow::bail!("refusing to write {}: {bad} particles hold NaN or infinity at step {}", path.display(), s.step);
    }
    Ok(())
}

/// Writes `s` as a legacy binary VTK file (big-endian, as the legacy format requires): the
/// particles as points with one vertex cell each, `velocity` as a vector and `density` and
/// `pressure` as scalars, all in double precision. The title line records the step and time.
pub fn write_vtk(path: &Path, s: &Snapshot) -> anyhow::Result<()> {
    use vtkio::model::*;
    refuse_non_finite(path, s)?;
    let n = s.len();
    let points: Vec<f64> = s.positions.iter().flatten().copied().collect();
    let velocities: Vec<f64> = s.velocities.iter().flatten().copied().collect();
    let vtk = Vtk {
        version: Version::new_legacy(4, 2),
        title: vtk_title(s.step, s.time),
        byte_order: ByteOrder::BigEndian,
        file_path: None,
        data: DataSet::inline(UnstructuredGridPiece {
            points: points.into(),
            cells: Cells {
                cell_verts: VertexNumbers::Legacy {
                    num_cells: n as u32,
                    vertices: (0..n as u32).flat_map(|i| [1, i]).collect(),
                },
                types: vec![CellType::Vertex; n],
            },
            data: Attributes {
                point: vec![
                    Attribute::vectors("velocity").with_data(velocities),
                    Attribute::scalars("density", 1).with_data(s.densities.clone()),
                    Attribute::scalars("pressure", 1).with_data(s.pressures.clone()),
                ],
                cell: vec![],
            },
        }),
    };
    write_atomic(path, |w| vtk.write_legacy(w).map_err(std::io::Error::from))
}

/// The title line of a VTK snapshot: `wgsph step 120 time 0.03`.
pub fn vtk_title(step: u64, time: f64) -> String {
    format!("wgsph step {step} time {time}")
}

/// The vertex properties of a PLY snapshot, in file order (all `float`).
pub const PLY_PROPERTIES: [&str; 8] = ["x", "y", "z", "vx", "vy", "vz", "density", "pressure"];

/// One PLY vertex: the values of `PLY_PROPERTIES`.
#[derive(Clone, Copy, Debug, Default)]
struct PlyVertex([f32; 8]);

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
fn ply_header(step: u64, time: f64, particles: usize) -> ply_rs_bw::ply::Header {
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

/// Writes a snapshot in one format.
pub fn write_snapshot(path: &Path, format: SnapshotFormat, s: &Snapshot) -> anyhow::Result<()> {
    match format {
        SnapshotFormat::Csv => write_snapshot_csv(path, s),
        SnapshotFormat::Vtk => write_vtk(path, s),
        SnapshotFormat::Ply => write_ply(path, s),
    }
}

/// One entry of a ParaView file series.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct SeriesEntry {
    pub name: String,
    pub time: f64,
}

/// ParaView's JSON file-series index (`*.vtk.series`, ParaView 5.5 and later): the snapshot
/// files with their simulated times, so that a run opens as one animated data set.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct FileSeries {
    #[serde(rename = "file-series-version")]
    pub version: String,
    pub files: Vec<SeriesEntry>,
}

impl Default for FileSeries {
    fn default() -> Self {
        FileSeries { version: "1.0".into(), files: Vec::new() }
    }
}

impl FileSeries {
    /// Reads an index, keeping only the snapshots up to `last_step` (a resumed run rewrites the
    /// later ones).
    pub fn read_up_to(path: &Path, last_step: u64) -> anyhow::Result<FileSeries> {
        let text = std::fs::read_to_string(path).with_context(|| format!("cannot read {}", path.display()))?;
        let mut series: FileSeries = serde_json::from_str(&text).with_context(|| format!("{} is not a file series", path.display()))?;
        series.files.retain(|e| step_of_name(&e.name).is_some_and(|s| s <= last_step));
        Ok(series)
    }

    /// Adds (or replaces) a step's file and rewrites the index atomically.
    pub fn add_and_write(&mut self, path: &Path, file_name: String, time: f64) -> anyhow::Result<()> {
        self.files.retain(|e| e.name != file_name);
        self.files.push(SeriesEntry { name: file_name, time });
        self.files.sort_by_key(|e| step_of_name(&e.name));
        let json = serde_json::to_string_pretty(self)?;
        write_atomic(path, |w| writeln!(w, "{json}"))
    }
}

/// The step of a snapshot file name `step_000123.ext`.
pub fn step_of_name(name: &str) -> Option<u64> {
    name.strip_prefix("step_")?.split('.').next()?.parse().ok()
}

/// Writes every snapshot file a run asked for, and keeps the VTK series index up to date.
pub struct SnapshotWriter {
    out: PathBuf,
    formats: Vec<SnapshotFormat>,
    series: FileSeries,
}

impl SnapshotWriter {
    /// Formats are de-duplicated, in the order given.
    pub fn new(out: &Path, formats: &[SnapshotFormat]) -> Self {
        let mut fs: Vec<SnapshotFormat> = Vec::new();
        for &f in formats {
            if !fs.contains(&f) {
                fs.push(f);
            }
        }
        SnapshotWriter { out: out.to_path_buf(), formats: fs, series: FileSeries::default() }
    }

    /// A writer continuing a run that stopped after `last_step`: the series index keeps the
    /// snapshots written up to it.
    pub fn resume(out: &Path, formats: &[SnapshotFormat], last_step: u64) -> anyhow::Result<Self> {
        let mut w = SnapshotWriter::new(out, formats);
        let index = w.series_path();
        if w.formats.contains(&SnapshotFormat::Vtk) && index.exists() {
            w.series = FileSeries::read_up_to(&index, last_step)?;
        }
        Ok(w)
    }

    pub fn series_path(&self) -> PathBuf {
        self.out.join("snapshots").join(VTK_SERIES_NAME)
    }

    /// Writes the backend's current state in every format through its streamed path, without
    /// one host copy of every array; returns the path of the first format's file and the
    /// largest speed, or `None` where the backend has no streamed path.
    pub fn write_streamed(&mut self, backend: &mut dyn crate::sim::Backend) -> Option<anyhow::Result<(PathBuf, f64)>> {
        let step = backend.steps_done();
        let files: Vec<(SnapshotFormat, PathBuf)> = self.formats.iter().map(|&f| (f, snapshot_file(&self.out, step, f))).collect();
        let written = backend.write_snapshot_streamed(&files)?;
        Some(written.and_then(|s| {
            for (f, path) in &files {
                if *f == SnapshotFormat::Vtk {
                    self.add_to_series(path, s.time)?;
                }
                log::info!("wrote {}", path.display());
            }
            let (_, first) = files.into_iter().next().ok_or_else(|| anyhow::anyhow!("no snapshot format chosen"))?;
            Ok((first, s.max_speed))
        }))
    }

    fn add_to_series(&mut self, vtk_file: &Path, time: f64) -> anyhow::Result<()> {
        let name = vtk_file.file_name().expect("a file name").to_string_lossy().into_owned();
        let index = self.series_path();
        self.series.add_and_write(&index, name, time)
    }

    /// Writes `s` in every format; returns the path of the first format's file.
    pub fn write(&mut self, s: &Snapshot) -> anyhow::Result<PathBuf> {
        let mut first = None;
        for f in self.formats.clone() {
            let path = snapshot_file(&self.out, s.step, f);
            write_snapshot(&path, f, s)?;
            if f == SnapshotFormat::Vtk {
                self.add_to_series(&path, s.time)?;
            }
            log::info!("wrote {}", path.display());
            first.get_or_insert(path);
        }
        first.ok_or_else(|| anyhow::anyhow!("no snapshot format chosen"))
    }
}
