//! Snapshots and checkpoints written in pieces: the same bytes as the whole-array writers, in
//! every format and on every adapter, with pieces small enough that every array is split
//! unevenly and several passes are made; NaN is refused and leaves no file; a checkpoint
//! written in pieces resumes bitwise exactly.

use crate::common;

use std::path::{Path, PathBuf};
use wgsph::io::checkpoint::capture;
use wgsph::io::checkpoint::read;
use wgsph::io::checkpoint::write;
use wgsph::io::checkpoint::{write_state_in_pieces, write_with_state};
use wgsph::io::snapshot::write_rows;
use wgsph::app::run::run_record;
use wgsph::io::snapshot::stream::SnapshotStream;
use wgsph::io::snapshot::write_snapshot;
use wgsph::io::snapshot::format::SnapshotFormat;
use wgsph::solver::gpu::buffers::STREAM_CHUNK;
use wgsph::app::run::RunOptions;
use wgsph::solver::Backend;
use wgsph::model::scene::Scene;
use wgsph::model::state::Snapshot;
use wgsph::io::snapshot::pieces::write_pieces;
use wgsph::solver::communicator::Communicator;
use wgsph::solver::{id_block, LocalGroup, SnapshotPiece};
use std::sync::Arc;

const FORMATS: [SnapshotFormat; 3] = [SnapshotFormat::Csv, SnapshotFormat::Vtk, SnapshotFormat::Ply];

/// The files of one snapshot in every format, named `{stem}.{ext}` in `dir`.
fn files(dir: &Path, stem: &str) -> Vec<(SnapshotFormat, PathBuf)> {
    FORMATS.iter().map(|&f| (f, dir.join(format!("{stem}.{}", f.extension())))).collect()
}

/// The whole-array writers' bytes of `s` in every format.
fn whole_bytes(dir: &Path, s: &Snapshot) -> Vec<Vec<u8>> {
    files(dir, "whole")
        .iter()
        .map(|(f, path)| {
            write_snapshot(path, *f, s).unwrap();
            std::fs::read(path).unwrap()
        })
        .collect()
}

fn rows_of(s: &Snapshot) -> Vec<[f32; 8]> {
    (0..s.len())
        .map(|i| {
            let (p, v) = (s.positions[i], s.velocities[i]);
            [p[0], p[1], p[2], v[0], v[1], v[2], s.densities[i], s.pressures[i]].map(|x| x as f32)
        })
        .collect()
}

fn names_in(dir: &Path) -> Vec<String> {
    let mut v: Vec<String> = std::fs::read_dir(dir).unwrap().map(|e| e.unwrap().file_name().to_string_lossy().into_owned()).collect();
    v.sort();
    v
}

#[test]
fn snapshots_written_in_uneven_pieces_equal_the_whole_array_files() {
    // f32 values (widened in the snapshot), as the GPU hands them over.
    let scene = Scene::builtin("dam_break").unwrap().with_fluid_particles(300);
    let mut cpu = common::cpu::<f32>(&scene);
    cpu.step(3);
    let s = Backend::snapshot(&mut cpu).unwrap();
    let dir = tempfile::tempdir().unwrap();
    let expected = whole_bytes(dir.path(), &s);
    let rows = rows_of(&s);
    for piece in [1, 7, 64, rows.len()] {
        let stem = format!("pieces_{piece}");
        let mut out = SnapshotStream::create(&files(dir.path(), &stem), rows.len() as u64, s.step, s.time).unwrap();
        for (k, part) in rows.chunks(piece).enumerate() {
            out.write_rows((k * piece) as u64, part).unwrap();
        }
        let written = out.finish().unwrap();
        assert_eq!((written.step, written.particles, written.extremes), (s.step, s.len() as u64, s.extremes()));
        for ((_, path), want) in files(dir.path(), &stem).iter().zip(&expected) {
            assert!(&std::fs::read(path).unwrap() == want, "{} differs from the whole-array file", path.display());
        }
    }
}

#[test]
fn streamed_snapshots_with_nan_missing_or_misordered_rows_leave_no_file() {
    let scene = Scene::builtin("hydrostatic").unwrap().with_fluid_particles(100);
    let s = Backend::snapshot(&mut common::cpu::<f32>(&scene)).unwrap();
    let rows = rows_of(&s);
    let n = rows.len() as u64;
    let dir = tempfile::tempdir().unwrap();
    let fs = files(dir.path(), "step_000004");
    let mut with_nan = rows.clone();
    with_nan[17][6] = f32::NAN;
    with_nan[40][1] = f32::INFINITY;
    let mut out = SnapshotStream::create(&fs, n, 4, 0.1).unwrap();
    out.write_rows(0, &with_nan).unwrap();
    let e = out.finish().unwrap_err().to_string();
    assert!(e.contains("refusing to write") && e.contains("step_000004.csv") && e.contains("2 particles hold NaN or infinity at step 4"), "{e}");
    // Too few rows, and rows out of order.
    let mut out = SnapshotStream::create(&fs, n, 4, 0.1).unwrap();
    out.write_rows(0, &rows[..10]).unwrap();
    assert!(out.write_rows(20, &rows[20..30]).unwrap_err().to_string().contains("out of order"));
    let e = out.finish().unwrap_err().to_string();
    assert!(e.contains(&format!("only 10 of {n} particles")), "{e}");
    assert!(names_in(dir.path()).is_empty(), "no file and no temporary file is left: {:?}", names_in(dir.path()));
}

/// `ranks` threads, each writing its block of `rows` (ids cut as the solver cuts them) with
/// [`write_pieces`]; every rank's result.
fn written_in_pieces(fs: &[(SnapshotFormat, PathBuf)], rows: &[[f64; 8]], ranks: usize, step: u64, time: f64) -> Vec<anyhow::Result<wgsph::io::snapshot::stream::StreamedSnapshot>> {
    std::thread::scope(|scope| {
        let handles: Vec<_> = LocalGroup::new(ranks)
            .into_iter()
            .map(|comm| {
                scope.spawn(move || {
                    let block = id_block(rows.len() as u64, ranks, comm.rank());
                    let piece = SnapshotPiece { step, time, total: rows.len() as u64, first: block.start, rows: rows[block.start as usize..block.end as usize].to_vec(), comm: Arc::new(comm) };
                    write_pieces(fs, &piece)
                })
            })
            .collect();
        handles.into_iter().map(|h| h.join().expect("rank thread")).collect()
    })
}

#[test]
fn snapshots_written_in_pieces_by_several_ranks_equal_the_whole_array_files() {
    // f64 values, as the CPU path's ranks hand them over; 4 ranks over 7 particles leave blocks
    // of one and two, 3 over 301 uneven ones, 5 over 3 empty blocks.
    let scene = Scene::builtin("dam_break").unwrap().with_fluid_particles(300);
    let mut cpu = common::cpu::<f64>(&scene);
    cpu.step(3);
    let whole = Backend::snapshot(&mut cpu).unwrap();
    for (particles, ranks) in [(whole.len(), 3), (7, 4), (3, 5), (whole.len(), 1)] {
        let mut s = whole.clone();
        s.positions.truncate(particles);
        s.velocities.truncate(particles);
        s.densities.truncate(particles);
        s.pressures.truncate(particles);
        let dir = tempfile::tempdir().unwrap();
        let expected = whole_bytes(dir.path(), &s);
        let rows: Vec<[f64; 8]> = (0..s.len())
            .map(|i| {
                let (p, v) = (s.positions[i], s.velocities[i]);
                [p[0], p[1], p[2], v[0], v[1], v[2], s.densities[i], s.pressures[i]]
            })
            .collect();
        let fs = files(dir.path(), "step_000003");
        for written in written_in_pieces(&fs, &rows, ranks, s.step, s.time) {
            let written = written.unwrap();
            assert_eq!((written.step, written.particles, written.extremes), (s.step, s.len() as u64, s.extremes()), "every rank reports the whole snapshot");
        }
        for ((f, path), want) in fs.iter().zip(&expected) {
            assert!(&std::fs::read(path).unwrap() == want, "{f:?}: {particles} particles by {ranks} ranks differ from the whole-array file");
        }
        let mut names = names_in(dir.path());
        names.retain(|n| !n.starts_with("whole"));
        assert_eq!(names, ["step_000003.csv", "step_000003.ply", "step_000003.vtk"], "no temporary file is left");
    }
    // A NaN on one rank: every rank refuses, and no file (nor temporary file) is written.
    let mut rows: Vec<[f64; 8]> = (0..40).map(|i| [i as f64, 0.0, 0.0, 1.0, 0.0, 0.0, 1000.0, 0.0]).collect();
    rows[33][4] = f64::NAN;
    let dir = tempfile::tempdir().unwrap();
    for e in written_in_pieces(&files(dir.path(), "step_000009"), &rows, 3, 9, 0.5) {
        let e = e.unwrap_err().to_string();
        assert!(e.contains("refusing to write") && e.contains("step_000009.csv") && e.contains("1 particles hold NaN or infinity at step 9"), "{e}");
    }
    assert!(names_in(dir.path()).is_empty(), "{:?}", names_in(dir.path()));
}

#[test]
fn a_rank_that_cannot_write_its_piece_stops_every_rank_and_leaves_no_file() {
    // Rank 1 looks for the files in another directory than rank 0 writes to: what a rank on
    // a machine that does not share the output directory meets.
    let (shared, elsewhere) = (tempfile::tempdir().unwrap(), tempfile::tempdir().unwrap());
    let rows: Vec<[f64; 8]> = (0..20).map(|i| [i as f64, 0.0, 0.0, 1.0, 0.0, 0.0, 1000.0, 0.0]).collect();
    let results: Vec<anyhow::Result<_>> = std::thread::scope(|scope| {
        let handles: Vec<_> = LocalGroup::new(2)
            .into_iter()
            .map(|comm| {
                let (rows, dir) = (&rows, if comm.rank() == 0 { shared.path() } else { elsewhere.path() });
                scope.spawn(move || {
                    let block = id_block(20, 2, comm.rank());
                    let piece = SnapshotPiece { step: 7, time: 0.1, total: 20, first: block.start, rows: rows[block.start as usize..block.end as usize].to_vec(), comm: Arc::new(comm) };
                    write_pieces(&files(dir, "step_000007"), &piece)
                })
            })
            .collect();
        handles.into_iter().map(|h| h.join().expect("rank thread")).collect()
    });
    let e0 = format!("{:#}", results[0].as_ref().unwrap_err());
    let e1 = format!("{:#}", results[1].as_ref().unwrap_err());
    assert!(e0.contains("rank 1 of 2 could not write its piece of") && e0.contains("step_000007.csv"), "{e0}");
    assert!(e1.contains("rank 1 of 2 cannot open the file rank 0 created") && e1.contains("every rank must see the output directory"), "{e1}");
    assert!(names_in(shared.path()).is_empty() && names_in(elsewhere.path()).is_empty(), "no file and no temporary file: {:?} {:?}", names_in(shared.path()), names_in(elsewhere.path()));
}

#[test]
fn gpu_snapshots_streamed_in_pieces_and_passes_equal_the_whole_array_files_on_every_adapter() {
    for ctx in common::contexts() {
        let scene = Scene::builtin("dam_break").unwrap().with_fluid_particles(700);
        let mut solver = common::gpu(ctx.clone(), &scene);
        solver.step(5).unwrap();
        let dir = tempfile::tempdir().unwrap();
        let snapshot = solver.snapshot().unwrap();
        let expected = whole_bytes(dir.path(), &snapshot);
        // 7: pieces that split every array unevenly and more than MAX_PASSES passes' worth of
        // pieces (8 passes); 64: 11 pieces per pass; 1 << 20: one piece, one pass.
        for chunk in [7, 64, STREAM_CHUNK] {
            let stem = format!("streamed_{chunk}");
            let n = solver.fluid_count() as u64;
            let s = write_rows(&files(dir.path(), &stem), n, solver.steps_done(), solver.time(), |v| solver.visit_rows_in_pieces(chunk, v)).unwrap();
            for ((f, path), want) in files(dir.path(), &stem).iter().zip(&expected) {
                assert!(&std::fs::read(path).unwrap() == want, "{f:?}, chunk {chunk} on {}", ctx.describe());
            }
            assert_eq!((s.step, s.particles, s.time), (5, snapshot.len() as u64, snapshot.time));
            assert_eq!(s.extremes, snapshot.extremes());
        }
        // A velocity that is not finite: refused in every format, and no file is written.
        let mut state = solver.save_state().unwrap();
        state.velocities[123][2] = f64::NAN;
        solver.restore_state(&state).unwrap();
        let bad = tempfile::tempdir().unwrap();
        let n = solver.fluid_count() as u64;
        let e = write_rows(&files(bad.path(), "nan"), n, solver.steps_done(), solver.time(), |v| solver.visit_rows_in_pieces(64, v)).unwrap_err().to_string();
        assert!(e.contains("1 particles hold NaN or infinity at step 5"), "{e}");
        assert!(names_in(bad.path()).is_empty(), "{}", ctx.describe());
    }
}

#[test]
fn a_checkpoint_read_in_part_keeps_exactly_the_particles_asked_for() {
    use wgsph::io::checkpoint::{read_where, visit_positions};
    // Continuity density (an array per particle) and DFSPH (warm starts by id, read whole).
    let continuity = common::TestScene::from(Scene::builtin("dam_break").unwrap().with_fluid_particles(400)).continuity().build();
    let dfsph = common::TestScene::from(Scene::builtin("dam_break").unwrap().with_fluid_particles(400)).dfsph().dt(0.001).build();
    for scene in [continuity, dfsph] {
        let mut cpu = common::cpu::<f64>(&scene);
        cpu.step(5);
        let dir = tempfile::tempdir().unwrap();
        let opts = RunOptions { steps: 10, out: dir.path().to_path_buf(), checkpoint_every: 5, ..Default::default() };
        let path = dir.path().join("c.wgsph");
        let record = run_record(&cpu, &opts, 10, None, 0.5, Vec::new());
        wgsph::io::checkpoint::save(&mut cpu, &scene.to_toml(), &record, &path).unwrap();
        let whole = read(&path).unwrap();
        // DFSPH's warm starts, by id in the file, come in the kept particles' order.
        let warm_of = |kept: &[u64]| if whole.state.warm_start.is_empty() { Vec::new() } else { kept.iter().map(|&i| whole.state.warm_start[whole.state.ids[i as usize] as usize]).collect::<Vec<_>>() };
        // Keeping every particle reads what the whole read reads.
        let (mut all, kept) = read_where(&path, &mut |_, _| true).unwrap();
        assert!(all.state.warm_start == warm_of(&kept));
        all.state.warm_start = whole.state.warm_start.clone();
        assert!(all == whole && kept.len() == whole.state.positions.len());
        // Every third particle and those below y = 0.1, by index and position.
        let (part, kept) = read_where(&path, &mut |i, p| i % 3 == 0 || p[1] < 0.1).unwrap();
        let expected: Vec<u64> = (0..whole.state.positions.len()).filter(|&i| i % 3 == 0 || whole.state.positions[i][1] < 0.1).map(|i| i as u64).collect();
        assert_eq!(kept, expected);
        assert!(kept.len() < whole.state.positions.len());
        let at = |i: &u64| *i as usize;
        assert!(part.state.positions == kept.iter().map(|i| whole.state.positions[at(i)]).collect::<Vec<_>>());
        assert!(part.state.velocities == kept.iter().map(|i| whole.state.velocities[at(i)]).collect::<Vec<_>>());
        assert!(part.state.ids == kept.iter().map(|i| whole.state.ids[at(i)]).collect::<Vec<_>>());
        assert!(part.state.densities == if whole.state.densities.is_empty() { Vec::new() } else { kept.iter().map(|i| whole.state.densities[at(i)]).collect::<Vec<_>>() });
        assert!(part.state.warm_start == warm_of(&kept) && part.state.step == whole.state.step && part.scene_toml == whole.scene_toml && part.run == whole.run);
        // Keeping none: the header alone; the positions visited in order.
        let (header, none) = read_where(&path, &mut |_, _| false).unwrap();
        assert!(none.is_empty() && header.state.positions.is_empty() && header.state.time == whole.state.time);
        let mut seen = Vec::new();
        visit_positions(&path, &mut |p| seen.push(p)).unwrap();
        assert!(seen == whole.state.positions);
    }
}

#[test]
fn gpu_checkpoints_streamed_in_pieces_equal_the_whole_state_ones_and_resume_bitwise_on_every_adapter() {
    // Adaptive dt: the status words (time, dt and its compensation) are in the state too;
    // continuity density: the densities the particles carry.
    let mut adaptive = Scene::builtin("dam_break").unwrap().with_fluid_particles(500);
    adaptive.time.adaptive = true;
    let continuity = common::TestScene::from(Scene::builtin("dam_break").unwrap().with_fluid_particles(500)).continuity().density_diffusion(0.1).build();
    // DFSPH: the warm-start stiffnesses, an array of their own.
    let dfsph = common::TestScene::from(adaptive.clone()).dfsph().build();
    for (i, ctx) in common::contexts().into_iter().enumerate() {
        for scene in [&adaptive, &continuity, &dfsph] {
            let mut solver = common::gpu(ctx.clone(), &scene);
            solver.step(6).unwrap();
            let dir = tempfile::tempdir().unwrap();
            let opts = RunOptions { steps: 10, out: dir.path().to_path_buf(), checkpoint_every: 6, ..Default::default() };
            let record = run_record(&solver, &opts, 10, None, 0.5, Vec::new());
            let whole = capture(&mut solver, &scene.to_toml(), record.clone()).unwrap();
            let whole_path = dir.path().join("whole.wgsph");
            write(&whole_path, &whole).unwrap();
            let expected = std::fs::read(&whole_path).unwrap();
            for chunk in [1, 7, 64, STREAM_CHUNK] {
                let path = dir.path().join(format!("streamed_{chunk}.wgsph"));
                write_with_state(&path, &whole.scene_toml, &whole.run, |w| write_state_in_pieces(&mut solver, w, chunk)).unwrap();
                assert!(std::fs::read(&path).unwrap() == expected, "chunk {chunk} on {}", ctx.describe());
            }
            // What the run loop writes (the streamed path) is the same file too.
            let saved = dir.path().join("saved.wgsph");
            wgsph::io::checkpoint::save(&mut solver, &scene.to_toml(), &record, &saved).unwrap();
            assert!(std::fs::read(&saved).unwrap() == expected, "{}", ctx.describe());
            // Resumed from the checkpoint written in the smallest pieces, a fresh solver continues
            // bitwise as the original does.
            let c = read(&dir.path().join("streamed_7.wgsph")).unwrap();
            assert!(c == whole);
            let mut resumed = common::gpu(common::contexts().into_iter().nth(i).unwrap(), &scene);
            resumed.restore_state(&c.state).unwrap();
            solver.step(4).unwrap();
            resumed.step(4).unwrap();
            let (a, b) = (solver.snapshot().unwrap(), resumed.snapshot().unwrap());
            assert!(a == b, "{}: the resumed run differs", ctx.describe());
            assert_eq!(a.step, 10);
        }
    }
}
