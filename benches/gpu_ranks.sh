#!/usr/bin/env bash
# GPU ranks on one hardware GPU, in one command: the dam break on one process against two
# ranks of wgsph-mpi sharing the GPU, with resident steps (the default) and
# with the full path every step (--full-exchange), weakly compressible and DFSPH, and with
# probes sampled every step; and whether two ranks end on one GPU's last snapshot, byte for byte.
#
# Usage, from the project root, with the release binaries at $WGSPH and $WGSPH_MPI (default
# .gpu/wgsph and .gpu/wgsph-mpi) and Open MPI's launcher at $MPIRUN (default mpirun):
#
#   benches/gpu_ranks.sh [OUTDIR] [SIZES]
#
# SIZES (default "1000000 4000000") are the weakly compressible dam breaks' particle counts;
# DFSPH runs at the first. One process is profiled; each run across ranks goes twice, at two
# step counts: the difference of their wall times (or of their exchange and device seconds)
# over the difference of the steps is the time per step without the setup. OUTDIR
# (default gpu-ranks) receives log.txt and each run's summary.json as NAME.json; the figures
# go to BENCHMARKS.md with the adapter, driver, particle count, date and commit. Debian 12's Open
# MPI taken to a newer system may crash in mpirun's PMIx; PMIX_MCA_preg=native avoided it there.
set -u
out=${1:-gpu-ranks}
sizes=${2:-"1000000 4000000"}
W=${WGSPH:-.gpu/wgsph}
M=${WGSPH_MPI:-.gpu/wgsph-mpi}
R=${MPIRUN:-mpirun}
mkdir -p "$out"
exec > >(tee "$out/log.txt") 2>&1
export XDG_RUNTIME_DIR=${XDG_RUNTIME_DIR:-/tmp}
work=$(mktemp -d)
same=${SAME:-100000}
dfsph=(--set physics.solver=dfsph --unset physics.speed_of_sound)

# NAME LIMIT HOW ARGS...: one run of the dam break; HOW is one (one process), resident (two
# ranks, resident steps) or full (two ranks, the full path every step: --full-exchange).
run() {
  local name=$1 limit=$2 how=$3; shift 3
  local launch=("$W")
  case $how in
    resident) launch=("$R" --allow-run-as-root --oversubscribe --bind-to none -np 2 "$M") ;;
    full) launch=("$R" --allow-run-as-root --oversubscribe --bind-to none -np 2 "$M"); set -- "$@" --full-exchange ;;
  esac
  rm -rf "$work/run"
  echo "=== $name ($(date -u +%T))"
  timeout "$limit" "${launch[@]}" run "${SCENE:-dam_break}" --backend gpu --quiet --out "$work/run" "$@" 2>&1 \
    | grep -v '^warning: fluid\[' | tail -3
  echo "=== exit ${PIPESTATUS[0]}"
  [ -f "$work/run/summary.json" ] && cp "$work/run/summary.json" "$out/$name.json"
  grep -h -E '"(wall_seconds|fluid_particles|resident_steps|bus_bytes|exchange_share)"' "$work/run/summary.json" 2>/dev/null | tr -d ' \n'; echo
}

command -v nvidia-smi >/dev/null && nvidia-smi --query-gpu=name,driver_version,memory.total --format=csv
date -u

# Byte for byte: two ranks with resident steps against one GPU, both methods, $SAME particles
# (default 100 k).
for method in wcsph dfsph; do
  extra=(); [ $method = dfsph ] && extra=("${dfsph[@]}")
  for how in one resident; do
    run "same_${method}_$how" 120 $how --particles "$same" --steps 200 --snapshot-every 200 "${extra[@]}"
    cp "$work/run/snapshots/step_000200.csv" "$work/${method}_$how.csv" 2>/dev/null
  done
  if cmp -s "$work/${method}_one.csv" "$work/${method}_resident.csv"; then
    echo "SAME: $method, 2 ranks with resident steps end on one GPU's snapshot byte for byte"
  else
    echo "DIFFERENT: $method, 2 ranks with resident steps against one GPU"
  fi
done

# Time per step: the weakly compressible dam break by size, then DFSPH at the first size. One
# process is profiled (its setup varies by more than its steps take); the ranks run twice, and
# their summaries' exchange_seconds and device_seconds split a rank's time. The full path runs
# at the first size only (at 4 M it takes minutes).
first=${sizes%% *}
profile() {
  echo "=== $1 ($(date -u +%T))"
  timeout 150 "$W" profile dam_break --steps 40 "${@:2}" 2>&1 | grep -E 'host wall-clock|^total|iterations per step'
}
for n in $sizes; do
  profile "wcsph_${n}_one" --particles "$n"
  hows="resident"; [ "$n" = "$first" ] && hows="resident full"
  for how in $hows; do
    for steps in 100 300; do
      run "wcsph_${n}_${how}_$steps" 150 $how --particles "$n" --steps $steps --snapshot-every 0
    done
  done
done
# Probes every step (a point on the far wall, a gauge, the tank's force, the front), sampled by
# each rank's device: the steps stay resident.
probes="$work/dam_probes.toml"
cp scenes/dam_break.toml "$probes"
for p in 'name = "wall_sensor"\ntype = "point"\nposition = [1.59, 0.05, 0.05]' 'name = "gauge_1"\ntype = "gauge"\nposition = [0.3, 0.0, 0.05]' 'name = "tank"\ntype = "force"\nboundary = 0' 'name = "front"\ntype = "front"'; do
  printf '\n[[probe]]\n%b\nevery_steps = 1\n' "$p" >> "$probes"
done
echo "=== probes_${first}_one ($(date -u +%T))"
timeout 150 "$W" profile "$probes" --steps 40 --particles "$first" 2>&1 | grep -E 'host wall-clock|^total|probes'
for steps in 100 300; do
  SCENE=$probes run "probes_${first}_resident_$steps" 150 resident --particles "$first" --steps $steps --snapshot-every 0
done
profile "dfsph_${first}_one" --particles "$first" "${dfsph[@]}"
for how in resident full; do
  for steps in 50 150; do
    run "dfsph_${first}_${how}_$steps" 150 $how --particles "$first" --steps $steps --snapshot-every 0 "${dfsph[@]}"
  done
done
rm -rf "$work"
