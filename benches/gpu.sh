#!/usr/bin/env bash
# The measurements of a hardware GPU in one command, for a machine without a Rust toolchain:
# the dam break profiled by size, the tuning knobs (the neighbour skin among them), the
# continuity/delta-SPH and DFSPH variants, the block workload, the GPU against the CPU
# reference, what probes cost and the Buchner wall-pressure case, and each parity test alone
# (with its own time limit, so that one slow or stuck test cannot hide the others).
#
# Usage, from the project root, with the release binary at $WGSPH (default .gpu/wgsph) and,
# optionally, the parity test program at $PARITY (default .gpu/tests/parity; the one that
# `cargo test --release --no-run` builds):
#
#   benches/gpu.sh [OUTDIR] [LARGEST]
#
# With ONLY=probes in the environment it runs only the probes' measurement.
#
# OUTDIR (default gpu-results) receives log.txt, one JSON file per profile and bench, and
# parity_failures.txt; LARGEST (default 64000000) is the largest dam break profiled (256000000
# needs about 37 GB of host memory and 14 GB of GPU memory). The figures go to BENCHMARKS.md
# with the adapter, driver, particle count, date and commit.
set -u
out=${1:-gpu-results}
largest=${2:-64000000}
W=${WGSPH:-.gpu/wgsph}
P=${PARITY:-.gpu/tests/parity}
mkdir -p "$out"
exec > >(tee "$out/log.txt") 2>&1
export XDG_RUNTIME_DIR=${XDG_RUNTIME_DIR:-/tmp}

# One command with a time limit, its output without the lattice notes of --particles.
t() {
  local limit=$1; shift
  echo; echo "=== $* ($(date -u +%T))"
  timeout "$limit" "$@" 2>&1 | grep -v '^warning: fluid\['
  echo "=== exit ${PIPESTATUS[0]} ($(date -u +%T))"
}

# Probes: what four point probes sampled every step cost on the GPU. The dam break at 30 k
# particles without and with them, each at two step counts (the difference between the two is
# the steps' own time, without the setup and the snapshots), alternating, twice; and at 1 M the
# profile without and with them (the probes' dispatches are timed with the density; at 1 M a
# run's setup varies by more than the steps take).
probe_runs() {
  awk '/^\[\[fluid\]\]/ && !done { for (y = 1; y <= 4; y++) printf "[[probe]]\nname = \"p%d\"\ntype = \"point\"\nposition = [1.0, %.2f, 0.05]\nevery_steps = 1\n\n", y, 0.1 * y; done = 1 } { print }' \
    scenes/dam_break.toml > "$variants/dam_break_probes.toml"
  for round in 1 2; do
    for steps in 2000 8000; do
      for scene in dam_break "$variants/dam_break_probes.toml"; do
        rm -rf "$variants/run"
        t 120 "$W" run "$scene" --backend gpu --particles 30000 --steps $steps --snapshot-every 0 --out "$variants/run"
      done
    done
  done
  for scene in dam_break "$variants/dam_break_probes.toml"; do
    t 60 "$W" profile "$scene" --particles 1000000 --steps 40
  done
}

variants=$(mktemp -d)
if [ "${ONLY:-}" = probes ]; then probe_runs; rm -rf "$variants"; exit 0; fi

command -v nvidia-smi >/dev/null && nvidia-smi --query-gpu=name,driver_version,memory.total --format=csv
echo "host cores: $(nproc)"; date -u
t 20 "$W" adapters

# The dam break by size (the largest last), then the knobs at 4 M and 16 M.
for n in 1000000 4000000 16000000; do
  t 120 "$W" profile dam_break --particles $n --steps 40 --out "$out/profile_$n.json"
done
t 60 "$W" profile dam_break --particles 4000000 --steps 40 --fused
t 60 "$W" profile dam_break --particles 16000000 --steps 40 --fused
t 60 "$W" profile dam_break --particles 4000000 --steps 40 --workgroup-size 64
t 60 "$W" profile dam_break --particles 4000000 --steps 40 --workgroup-size 256
t 60 "$W" profile dam_break --particles 4000000 --steps 40 --single-cells
# The neighbour skin (no lists on a hardware GPU: the sort left out between rebuilds, the walks
# over cells 1.1 h wide), at 1 M and 4 M.
t 60 "$W" profile dam_break --particles 1000000 --steps 40 --neighbour-skin 0.1
t 60 "$W" profile dam_break --particles 4000000 --steps 40 --neighbour-skin 0.1

# The pressure model and DFSPH: the dam break with the lines changed.
sed -e 's/^name = "dam_break"$/name = "dam_break_delta"/' \
    -e 's/^viscosity = 0.01$/viscosity = 0.01\ndensity = "continuity"\ndensity_diffusion = 0.1\nboundary_pressure = "adami"/' \
    scenes/dam_break.toml > "$variants/dam_break_delta.toml"
sed -e 's/^name = "dam_break"$/name = "dam_break_dfsph"/' -e 's/^equation_of_state = "tait"$/solver = "dfsph"/' \
    -e '/^speed_of_sound = /d' -e 's/^dt = 0.00025$/dt = 0.001/' scenes/dam_break.toml > "$variants/dam_break_dfsph.toml"
t 60 "$W" profile "$variants/dam_break_delta.toml" --particles 4000000 --steps 40
t 60 "$W" profile "$variants/dam_break_dfsph.toml" --particles 1000000 --steps 40

# The block workload on every path, and the GPU against the f64 CPU path.
t 120 "$W" bench --n 30 --steps 200 --out "$out/bench_n30.json"
t 120 "$W" bench --n 40 --steps 200 --paths gpu,dfsph-gpu,cpu-f32 --out "$out/bench_n40.json"
t 120 "$W" bench --n 30 --steps 200 --paths dfsph-gpu --solver-loop indirect
t 60 "$W" compare dam_break --steps 100

probe_runs
for resolution in default fine; do
  t 120 "$W" validate buchner_p1 --backend gpu --resolution $resolution --out "$out/buchner_$resolution"
done

# The largest dam break asked for.
t 300 "$W" profile dam_break --particles "$largest" --steps 10 --out "$out/profile_$largest.json"

# Each parity test alone (the tests read the checkout's files and may run the wgsph binary).
if [ -x "$P" ]; then
  echo; echo "=== parity tests, each alone"
  : > "$out/parity_failures.txt"
  for test in $("$P" --list 2>/dev/null | sed -n 's/: test$//p'); do
    start=$(date +%s%N)
    timeout 60 "$P" --exact "$test" --test-threads 1 > "$variants/one.log" 2>&1
    rc=$?
    echo "parity exit $rc, $(( ($(date +%s%N) - start) / 1000000 )) ms: $test"
    [ $rc -ne 0 ] && { echo "--- $test"; tail -25 "$variants/one.log"; } >> "$out/parity_failures.txt"
  done
fi
rm -rf "$variants"
