//! Legacy VTK snapshots for ParaView and VisIt, with a `.vtk.series` index so that a run opens
//! as an animation; and the file layout the streamed writer fills in pieces.

use super::csv::refuse_non_finite;
use crate::io::atomic::write_atomic;
use crate::model::state::Snapshot;
use anyhow::Context;
use serde::{Deserialize, Serialize};
use std::io::{Seek, SeekFrom, Write};
use std::path::Path;

/// Name of the ParaView file-series index beside the VTK snapshots.
pub const VTK_SERIES_NAME: &str = "particles.vtk.series";

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
        let mut series: FileSeries =
            serde_json::from_str(&text).map_err(|e| anyhow::anyhow!("{} is not the run's file series ({e}); move it out of the way to resume", path.display()))?;
        series.files.retain(|e| super::format::step_of_name(&e.name).is_some_and(|s| s <= last_step));
        Ok(series)
    }

    /// Adds (or replaces) a step's file and rewrites the index atomically.
    pub fn add_and_write(&mut self, path: &Path, file_name: String, time: f64) -> anyhow::Result<()> {
        self.files.retain(|e| e.name != file_name);
        self.files.push(SeriesEntry { name: file_name, time });
        self.files.sort_by_key(|e| super::format::step_of_name(&e.name));
        let json = serde_json::to_string_pretty(self)?;
        write_atomic(path, |w| writeln!(w, "{json}"))
    }
}


/// The arrays of a legacy VTK snapshot in file order, with their bytes per particle: points and
/// velocity 3 doubles, the legacy cell list `1 i` (two ints), the cell type (one int), density
/// and pressure one double each.
const VTK_ARRAY_BYTES: [u64; 6] = [24, 8, 4, 24, 8, 8];

/// Where every section of a legacy binary VTK file of `n` vertex cells lies, for the layout
/// `vtkio`'s writer produces (VTK's "File Formats", legacy format 4.2: each keyword line, then
/// the big-endian binary values, then a newline).
pub(crate) struct VtkLayout {
    /// The text before each array, and after the last, and where each begins.
    texts: [String; 7],
    starts: [u64; 7],
    /// Offset of each array's first value.
    arrays: [u64; 6],
}

impl VtkLayout {
    pub(crate) fn new(n: u64, title: &str) -> Self {
        let texts = [
            format!("# vtk DataFile Version 4.2\n{title}\nBINARY\n\nDATASET UNSTRUCTURED_GRID\nPOINTS {n} double\n"),
            format!("\n\nCELLS {n} {}\n", 2 * n),
            format!("\n\nCELL_TYPES {n}\n"),
            format!("\n\nPOINT_DATA {n}\n\nVECTORS velocity double\n"),
            "\n\nSCALARS density double 1\nLOOKUP_TABLE default\n".to_string(),
            "\n\nSCALARS pressure double 1\nLOOKUP_TABLE default\n".to_string(),
            format!("\n\nCELL_DATA {n}\n\n"),
        ];
        let (mut at, mut starts, mut arrays) = (0, [0; 7], [0; 6]);
        for (i, text) in texts.iter().enumerate() {
            starts[i] = at;
            at += text.len() as u64;
            if i < arrays.len() {
                arrays[i] = at;
                at += n * VTK_ARRAY_BYTES[i];
            }
        }
        VtkLayout { texts, starts, arrays }
    }

    pub(crate) fn write_text(&self, f: &mut (impl Write + Seek)) -> std::io::Result<()> {
        for (&at, text) in self.starts.iter().zip(&self.texts) {
            f.seek(SeekFrom::Start(at))?;
            f.write_all(text.as_bytes())?;
        }
        Ok(())
    }

    /// Writes particles `first..` into each array's section.
    pub(crate) fn write_rows(&self, f: &mut (impl Write + Seek), first: u64, rows: &[[f64; 8]]) -> std::io::Result<()> {
        let vertex = vtkio::model::CellType::Vertex as i32;
        for (array, &at) in self.arrays.iter().enumerate() {
            f.seek(SeekFrom::Start(at + first * VTK_ARRAY_BYTES[array]))?;
            for (j, r) in rows.iter().enumerate() {
                let values: &[f64] = match array {
                    0 => &r[0..3],
                    3 => &r[3..6],
                    4 => &r[6..7],
                    5 => &r[7..8],
                    1 => {
                        f.write_all(&1u32.to_be_bytes())?;
                        f.write_all(&((first + j as u64) as u32).to_be_bytes())?;
                        continue;
                    }
                    _ => {
                        f.write_all(&vertex.to_be_bytes())?;
                        continue;
                    }
                };
                for &x in values {
                    f.write_all(&x.to_be_bytes())?;
                }
            }
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::FileSeries;

    /// A resumed run reads the index back and rewrites it: every time must come back to the
    /// last bit (JSON numbers parsed with correct rounding), or the resumed run's index would
    /// differ from the uninterrupted run's.
    #[test]
    fn a_series_index_keeps_its_times_to_the_last_bit() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("particles.vtk.series");
        let times = [0.0, 0.010000000474974513, 0.011999999999999999, 0.1 + 0.2, 1e-300, 123456.78901234567];
        let mut series = FileSeries::default();
        for (k, &t) in times.iter().enumerate() {
            series.add_and_write(&path, format!("step_{:06}.vtk", 10 * k), t).unwrap();
        }
        let back = FileSeries::read_up_to(&path, u64::MAX).unwrap();
        assert_eq!(back, series);
        let before = std::fs::read(&path).unwrap();
        let mut again = FileSeries::read_up_to(&path, 30).unwrap();
        assert_eq!(again.files.len(), 4);
        for (k, &t) in times.iter().enumerate().skip(4) {
            again.add_and_write(&path, format!("step_{:06}.vtk", 10 * k), t).unwrap();
        }
        assert_eq!(std::fs::read(&path).unwrap(), before);
    }
}
