//! Host memory of writing one snapshot (CSV, VTK, PLY) or checkpoint of a GPU run: the
//! whole-array path (read every array back, build the `Snapshot` or `BackendState`, write it)
//! against the streamed one, with the default piece size (`STREAM_CHUNK`) and a smaller one;
//! and of resuming from a checkpoint (read whole).
//!
//! Every case runs in a process of its own (this program started again), which resets the
//! kernel's peak-RSS mark (`/proc/self/clear_refs`, Linux) once the solver is set up, writes the
//! file, and reports the rise of the peak over the resident size before it, per fluid particle.
//! On a software adapter the staging buffers of the readback are host memory, as the mappable
//! buffers of a discrete GPU are, so they are counted.
//!
//! `cargo bench --bench snapshot_memory` (`WGSPH_BENCH_PARTICLES`, default 1 000 000).

#[path = "../tests/common/mod.rs"]
mod common;

use std::process::Command;
use wgsph::io::snapshot::format::SnapshotFormat;
use wgsph::solver::gpu::buffers::STREAM_CHUNK;
use wgsph::solver::gpu::GpuContext;
use wgsph::app::run::RunOptions;
use wgsph::solver::Backend;
use wgsph::model::scene::Scene;

const CASES: [&str; 5] = ["csv", "vtk", "ply", "checkpoint", "resume"];

fn status_kib(field: &str) -> u64 {
    let status = std::fs::read_to_string("/proc/self/status").expect("Linux /proc");
    let line = status.lines().find(|l| l.starts_with(field)).unwrap_or_else(|| panic!("{field} in /proc/self/status"));
    line.split_whitespace().nth(1).and_then(|v| v.parse().ok()).expect("a number of kB")
}

/// Runs one case in this process and prints `bytes-per-particle particles`.
fn run_case(case: &str, path: &str, chunk: u64, particles: u64) {
    let scene = Scene::builtin("dam_break").unwrap().with_fluid_particles(particles);
    let mut solver = common::gpu(GpuContext::new().unwrap(), &scene);
    let n = solver.fluid_count() as f64;
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join(format!("out.{case}"));
    let opts = RunOptions { out: dir.path().to_path_buf(), ..Default::default() };
    // One step and a readback first: a software adapter makes a buffer resident when a shader
    // first writes it, which is not the writer's memory.
    solver.step(1).unwrap();
    solver.health().unwrap();
    let record = wgsph::app::run::run_record(&solver, &opts, 2, None, 0.0);
    if case == "resume" {
        wgsph::io::checkpoint::save(&mut solver, &scene.to_toml(), &record, &out).unwrap();
    }
    std::fs::write("/proc/self/clear_refs", "5").expect("resetting the peak RSS mark");
    let before = status_kib("VmRSS:");
    match (case, path) {
        ("resume", _) => {
            let c = wgsph::io::checkpoint::read(&out).unwrap();
            solver.restore_state(&c.state).unwrap();
            solver.wait().unwrap();
        }
        ("checkpoint", "whole") => {
            let c = wgsph::io::checkpoint::capture(&mut solver, &scene.to_toml(), record).unwrap();
            wgsph::io::checkpoint::write(&out, &c).unwrap();
        }
        ("checkpoint", _) => {
            wgsph::io::checkpoint::write_with_state(&out, &scene.to_toml(), &record, |w| wgsph::io::checkpoint::write_state_in_pieces(&mut solver, w, chunk)).unwrap();
        }
        (format, path) => {
            let format = match format {
                "csv" => SnapshotFormat::Csv,
                "vtk" => SnapshotFormat::Vtk,
                _ => SnapshotFormat::Ply,
            };
            if path == "whole" {
                let s = solver.snapshot().unwrap();
                wgsph::io::snapshot::write_snapshot(&out, format, &s).unwrap();
            } else {
                let (n, step, time) = (solver.fluid_count() as u64, solver.steps_done(), solver.time());
                wgsph::io::snapshot::write_rows(&[(format, out.clone())], n, step, time, |v| solver.visit_rows_in_pieces(chunk, v)).unwrap();
            }
        }
    }
    let peak = status_kib("VmHWM:");
    println!("{:.1} {}", (peak.saturating_sub(before) * 1024) as f64 / n, n);
}

fn main() {
    let particles: u64 = std::env::var("WGSPH_BENCH_PARTICLES").ok().and_then(|v| v.parse().ok()).unwrap_or(1_000_000);
    if let Ok(case) = std::env::var("WGSPH_MEMORY_CASE") {
        let mut parts = case.split(' ');
        let (what, path, chunk) = (parts.next().unwrap(), parts.next().unwrap(), parts.next().unwrap().parse().unwrap());
        run_case(what, path, chunk, particles);
        return;
    }
    let small = STREAM_CHUNK / 16;
    println!("| file | path | piece (particles) | fluid particles | host bytes per particle (peak RSS rise) |");
    println!("|---|---|---|---|---|");
    for case in CASES {
        let paths: &[(&str, u64)] = if case == "resume" { &[("whole", 0)] } else { &[("whole", 0), ("streamed", STREAM_CHUNK), ("streamed", small)] };
        for &(path, chunk) in paths {
            let exe = std::env::current_exe().unwrap();
            // glibc: blocks of 64 KiB and more are mapped and unmapped on their own, so memory
            // freed before the measurement is not silently reused without a rise of the peak.
            let out = Command::new(exe)
                .env("WGSPH_MEMORY_CASE", format!("{case} {path} {chunk}"))
                .env("MALLOC_MMAP_THRESHOLD_", "65536")
                .env("MALLOC_TRIM_THRESHOLD_", "0")
                .output()
                .unwrap();
            let text = String::from_utf8_lossy(&out.stdout);
            let Some((bytes, n)) = text.lines().last().and_then(|l| l.split_once(' ')) else {
                eprintln!("{case} {path}: {}", String::from_utf8_lossy(&out.stderr));
                continue;
            };
            let piece = if path == "whole" { "-".to_string() } else { chunk.to_string() };
            println!("| {case} | {path} | {piece} | {n} | {bytes} |");
        }
    }
}
