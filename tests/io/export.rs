//! Snapshot exports: VTK parsed back with vtkio, PLY with a PLY parser, the ParaView series
//! index, each checked value by value against the CSV snapshot of the same step.

use crate::common;

use std::path::Path;
use std::process::{Command, Output};
use vtkio::model::{Attribute, CellType, DataSet, Piece, VertexNumbers};
use wgsph::io::snapshot::format::snapshot_file;
use wgsph::io::snapshot::csv::SNAPSHOT_HEADER;
use wgsph::io::snapshot::ply::write_ply;
use wgsph::io::snapshot::vtk::write_vtk;
use wgsph::io::snapshot::vtk::FileSeries;
use wgsph::io::snapshot::format::SnapshotFormat;
use wgsph::io::snapshot::ply::PLY_PROPERTIES;
use wgsph::io::snapshot::vtk::VTK_SERIES_NAME;
use wgsph::io::snapshot::csv::read_snapshot_csv;
use wgsph::model::state::Snapshot;

fn wgsph(args: &[&str], dir: &Path) -> Output {
    Command::new(env!("CARGO_BIN_EXE_wgsph")).args(args).current_dir(dir).output().unwrap()
}

/// The particles of a legacy VTK snapshot, parsed with vtkio, and its title.
fn read_vtk(path: &Path) -> (Snapshot, String) {
    let vtk = vtkio::Vtk::import(path).unwrap_or_else(|e| panic!("{}: {e}", path.display()));
    let DataSet::UnstructuredGrid { pieces, .. } = vtk.data else { panic!("not an unstructured grid") };
    let Piece::Inline(piece) = pieces.into_iter().next().unwrap() else { panic!("not inline") };
    let points: Vec<f64> = piece.points.cast_into().unwrap();
    let n = points.len() / 3;
    assert_eq!(piece.cells.types, vec![CellType::Vertex; n]);
    let VertexNumbers::Legacy { num_cells, vertices } = piece.cells.cell_verts else { panic!("legacy cells") };
    assert_eq!(num_cells as usize, n);
    assert_eq!(vertices, (0..n as u32).flat_map(|i| [1, i]).collect::<Vec<_>>());
    let mut s = Snapshot { positions: points.chunks(3).map(|c| [c[0], c[1], c[2]]).collect(), ..Default::default() };
    for a in piece.data.point {
        let Attribute::DataArray(a) = a else { panic!("a data array") };
        let v: Vec<f64> = a.data.cast_into().unwrap();
        match a.name.as_str() {
            "velocity" => s.velocities = v.chunks(3).map(|c| [c[0], c[1], c[2]]).collect(),
            "density" => s.densities = v,
            "pressure" => s.pressures = v,
            other => panic!("unexpected array {other}"),
        }
    }
    (s, vtk.title)
}

/// The vertices of a PLY snapshot (property name -> values) and its header comments.
fn read_ply(path: &Path) -> (Vec<Vec<f32>>, Vec<String>, ply_rs_bw::ply::Encoding) {
    use ply_rs_bw::ply::{DefaultElement, Property};
    let mut f = std::fs::File::open(path).unwrap();
    let ply = ply_rs_bw::parser::Parser::<DefaultElement>::new().read_ply(&mut f).unwrap();
    let names: Vec<&String> = ply.header.elements["vertex"].properties.keys().collect();
    assert_eq!(names, PLY_PROPERTIES.to_vec());
    let rows = ply.payload["vertex"]
        .iter()
        .map(|v| {
            PLY_PROPERTIES
                .iter()
                .map(|p| match v[*p] {
                    Property::Float(x) => x,
                    ref other => panic!("{p} is {other:?}, not a float"),
                })
                .collect()
        })
        .collect();
    (rows, ply.header.comments.clone(), ply.header.encoding)
}

fn check_exports_against_csv(out: &Path, steps: &[u64], dt: f64) {
    for &step in steps {
        let csv = read_snapshot_csv(&snapshot_file(out, step, SnapshotFormat::Csv)).unwrap();
        let (vtk, title) = read_vtk(&snapshot_file(out, step, SnapshotFormat::Vtk));
        // CSV and VTK both carry full f64 values.
        assert_eq!((&vtk.positions, &vtk.velocities), (&csv.positions, &csv.velocities), "step {step}");
        assert_eq!((&vtk.densities, &vtk.pressures), (&csv.densities, &csv.pressures), "step {step}");
        assert_eq!(title, wgsph::io::snapshot::vtk::vtk_title(step, step as f64 * dt));
        let (rows, comments, encoding) = read_ply(&snapshot_file(out, step, SnapshotFormat::Ply));
        assert_eq!(encoding, ply_rs_bw::ply::Encoding::BinaryLittleEndian);
        assert!(comments.contains(&format!("step {step}")), "{comments:?}");
        assert!(comments.contains(&format!("time {}", step as f64 * dt)), "{comments:?}");
        assert_eq!(rows.len(), csv.len());
        for (i, r) in rows.iter().enumerate() {
            let p = csv.positions[i];
            let v = csv.velocities[i];
            let want = [p[0], p[1], p[2], v[0], v[1], v[2], csv.densities[i], csv.pressures[i]].map(|x| x as f32);
            assert_eq!(r.as_slice(), want.as_slice(), "step {step}, particle {i}");
        }
    }
    let series: FileSeries = serde_json::from_str(&std::fs::read_to_string(out.join("snapshots").join(VTK_SERIES_NAME)).unwrap()).unwrap();
    assert_eq!(series.version, "1.0");
    let want: Vec<(String, f64)> = steps.iter().map(|&s| (format!("step_{s:06}.vtk"), s as f64 * dt)).collect();
    let got: Vec<(String, f64)> = series.files.iter().map(|e| (e.name.clone(), e.time)).collect();
    assert_eq!(got, want);
}

#[test]
fn dam_break_exports_vtk_series_and_ply_equal_to_the_csv() {
    let dir = tempfile::tempdir().unwrap();
    let out = wgsph(
        &["run", "dam_break", "--steps", "20", "--snapshot-every", "10", "--backend", "cpu", "--out", "o", "--format", "csv,vtk", "--format", "ply"],
        dir.path(),
    );
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
    let o = dir.path().join("o");
    let dt = wgsph::Scene::builtin("dam_break").unwrap().time.dt;
    check_exports_against_csv(&o, &[0, 10, 20], dt);
    // The summary names the first format's file.
    let s: wgsph::io::summary::Summary = serde_json::from_str(&std::fs::read_to_string(o.join("summary.json")).unwrap()).unwrap();
    assert!(s.last_snapshot.unwrap().ends_with("step_000020.csv"));
}

#[test]
fn gpu_snapshots_export_the_same_values_in_every_format() {
    if common::contexts().is_empty() {
        return;
    }
    let dir = tempfile::tempdir().unwrap();
    let out = wgsph(&["run", "dam_break", "--steps", "8", "--snapshot-every", "8", "--backend", "gpu", "--out", "g", "--format", "ply,vtk,csv"], dir.path());
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
    let dt = wgsph::Scene::builtin("dam_break").unwrap().time.dt;
    check_exports_against_csv(&dir.path().join("g"), &[0, 8], dt);
}

#[test]
fn only_the_chosen_formats_are_written_and_bad_ones_are_refused() {
    let dir = tempfile::tempdir().unwrap();
    let out = wgsph(&["run", "hydrostatic", "--steps", "2", "--snapshot-every", "0", "--backend", "cpu", "--out", "v", "--format", "vtk"], dir.path());
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
    let mut names: Vec<String> =
        std::fs::read_dir(dir.path().join("v/snapshots")).unwrap().map(|e| e.unwrap().file_name().to_string_lossy().into_owned()).collect();
    names.sort();
    assert_eq!(names, ["index.csv", "particles.vtk.series", "step_000000.vtk", "step_000002.vtk"]);
    let out = wgsph(&["run", "hydrostatic", "--steps", "2", "--out", "x", "--format", "obj"], dir.path());
    assert_eq!(out.status.code(), Some(2));
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(err.contains("obj") && err.contains("csv") && err.contains("vtk") && err.contains("ply"), "{err}");
}

#[test]
fn a_snapshot_with_nan_is_never_written_in_any_format() {
    let dir = tempfile::tempdir().unwrap();
    let mut s = Snapshot::with_len(3, 7, 0.5);
    s.densities[1] = f64::NAN;
    for (path, result) in [
        (dir.path().join("a.vtk"), write_vtk(&dir.path().join("a.vtk"), &s)),
        (dir.path().join("a.ply"), write_ply(&dir.path().join("a.ply"), &s)),
    ] {
        let e = result.expect_err("refused");
        assert!(e.to_string().contains("NaN"), "{e}");
        assert!(!path.exists());
    }
    assert_eq!(std::fs::read_dir(dir.path()).unwrap().count(), 0, "no temporary file is left");
}

/// `snapshots/index.csv` gives each snapshot's step and simulated time to a CSV reader (the
/// snapshots keep their header as their first line); `--snapshot-every 0.005s` writes one at
/// the first step reaching each multiple of the time, with adaptive dt too.
#[test]
fn snapshots_at_simulated_times_and_their_index() {
    let dir = tempfile::tempdir().unwrap();
    let interval = 0.005;
    for (out, extra) in [("fixed", &[][..]), ("adaptive", &["--set", "time.adaptive=true"][..])] {
        let o = wgsph(
            &[&["run", "hydrostatic", "--particles", "300", "--time", "0.0305", "--snapshot-every", "0.005s", "--backend", "cpu", "--out", out], extra].concat(),
            dir.path(),
        );
        assert!(o.status.success(), "{out}: {}", String::from_utf8_lossy(&o.stderr));
        let summary: serde_json::Value = serde_json::from_slice(&std::fs::read(dir.path().join(out).join("summary.json")).unwrap()).unwrap();
        let dt_max = summary["dt_max"].as_f64().unwrap();
        let index = std::fs::read_to_string(dir.path().join(out).join("snapshots/index.csv")).unwrap();
        let mut lines = index.lines();
        assert_eq!(lines.next(), Some("step,time,csv"), "{out}");
        let rows: Vec<(u64, f64, String)> = lines
            .map(|l| {
                let f: Vec<&str> = l.split(',').collect();
                (f[0].parse().unwrap(), f[1].parse().unwrap(), f[2].to_string())
            })
            .collect();
        // t = 0, each of 0.005 ... 0.030, and the end.
        assert_eq!(rows.len(), 8, "{out}: {index}");
        for (k, (step, time, file)) in rows.iter().enumerate().take(7) {
            let due = k as f64 * interval;
            assert!(*time >= due - 1e-12 && *time < due + dt_max + 1e-12, "{out}: snapshot {k} at t = {time}, due at {due}");
            assert_eq!(file, &format!("step_{step:06}.csv"));
            let csv = std::fs::read_to_string(dir.path().join(out).join("snapshots").join(file)).unwrap();
            assert_eq!(csv.lines().next(), Some(SNAPSHOT_HEADER), "{out}: {file}");
        }
        assert!((rows[7].1 - summary["sim_time"].as_f64().unwrap()).abs() < 1e-12, "{out}: the last row is the end");
    }
    for bad in ["0.02x", "-1s", "0s", "nans"] {
        let o = wgsph(&["run", "hydrostatic", "--steps", "1", &format!("--snapshot-every={bad}")], dir.path());
        assert_eq!(o.status.code(), Some(2), "{bad}");
        assert!(String::from_utf8_lossy(&o.stderr).contains("0.02s"), "{bad}: {}", String::from_utf8_lossy(&o.stderr));
    }
}
