#!/usr/bin/env bash
# granular against its peers, side by side on this machine: one thread, CPU seconds (user + sys
# of the whole process, to the millisecond: bash's `times`), REPEATS runs of each interleaved (A B A B ...),
# medians. See ../shared/peers/README.md for the peers and earlier measurements.
#
#   (a) MD: LAMMPS (Debian's `lmp`, GRANULAR package) on ../shared/peers/lammps-rfm2d.in
#       (N = 2000 discs, 20 000 steps of dt = 1e-6 s, gran/hooke, eps = 0.6; forcing
#       LAMMPS_FORCING, default langevin) against granular's 2D RFM on the same system
#       (N = 2000, L = 0.2 m, eps_n = 0.6, eps_t = 1, D = 1e-8, dt = 1e-6, 20 000 steps:
#       warm-up 0, duration 0.02 s). Prints particle-steps per CPU second and the ratio.
#   (b) DSMC, only where AUTHORS_DSMC points at a local build of the authors' code
#       (github.com/RodniO/Low-rank-Monte-Carlo; this script never fetches or builds it): a
#       binary that runs the paper's Table I low-rank set-up (N_k = round(N_1 k^-3), n_1 = 0.1,
#       T(0) = 1, eps = 0.5, t = 100: MonteDSMC) and prints its "Collisions" line, called as
#       `$AUTHORS_DSMC $N1`. Against granular's Table I low-rank run (one run, the
#       temperature observable, `granular run --threads 1`: start-up, theory and tables
#       included). Prints collisions per CPU second and the ratio.
#
# Usage: scripts/bench-peers.sh [REPEATS (3)]
#   BIN=path/to/granular (default: this checkout's release build, built if missing)
#   LMP=lmp  LAMMPS_IN=../shared/peers/lammps-rfm2d.in  LAMMPS_FORCING=langevin
#   AUTHORS_DSMC=/path/to/binary  N1=1000000  PYTHON=python with pyarrow (for the collision
#   count of granular's run; default .venv/bin/python, else python3)
#   SKIP_MD=1 / SKIP_DSMC=1 to leave a part out.
# The machine should be quiet: the load (uptime) is printed before and after.
set -euo pipefail
cd "$(dirname "$0")/.."
root=$PWD
reps=${1:-3}
case $reps in '' | *[!0-9]* | 0) echo "REPEATS must be a positive integer, got '$reps'" >&2; exit 2 ;; esac
if [ -z "${BIN:-}" ] && [ ! -x target/release/granular ]; then cargo build --release -q; fi
bin=${BIN:-$root/target/release/granular}
lmp=${LMP:-lmp}
lammps_in=${LAMMPS_IN:-$root/../shared/peers/lammps-rfm2d.in}
forcing=${LAMMPS_FORCING:-langevin}
n1=${N1:-1000000}
case $n1 in '' | *[!0-9]* | 0) echo "N1 must be a positive integer, got '$n1'" >&2; exit 2 ;; esac
python=${PYTHON:-}
if [ -z "$python" ]; then
  if [ -x "$root/.venv/bin/python" ]; then python=$root/.venv/bin/python; else python=python3; fi
fi
work=$(mktemp -d /tmp/granular-bench-peers.XXXXXX)
trap 'rm -rf "$work"' EXIT

# cpu LABEL CMD...: runs CMD (stdout to $work/LABEL.out), appends user+sys seconds to
# $work/LABEL.cpu. The times are those of the subshell's children (bash's `times`, to the
# millisecond; /usr/bin/time gives user and sys to 10 ms each, ~4 % of granular's MD run).
cpu() {
  local label=$1 t
  shift
  t=$(
    "$@" >"$work/$label.out" 2>"$work/$label.err" || exit 1
    times
  ) || {
    echo "$label failed:" >&2
    tail -5 "$work/$label.err" >&2
    exit 1
  }
  # The second line of `times`: the children's user and sys, as 0m0.233s 0m0.021s.
  printf '%s\n' "${t##*$'\n'}" |
    awk '{s = 0; for (i = 1; i <= 2; i++) {split($i, a, /[ms]/); s += a[1] * 60 + a[2]}; printf "%.3f\n", s}' \
      >>"$work/$label.cpu"
}
median() { sort -g "$1" | awk '{a[NR] = $1} END {if (NR % 2) print a[(NR + 1) / 2]; else print (a[NR / 2] + a[NR / 2 + 1]) / 2}'; }
list() { paste -sd' ' "$1"; }

echo "machine: $(grep -m1 'model name' /proc/cpuinfo | cut -d: -f2 | sed 's/^ *//'), $(nproc) cores; granular: $bin"
echo "load before: $(uptime | sed 's/.*load average/load average/')"

if [ -z "${SKIP_MD:-}" ]; then
  if ! command -v "$lmp" >/dev/null; then
    echo "(a) skipped: no LAMMPS ('$lmp'; Debian: apt-get install lammps)"
  elif [ ! -f "$lammps_in" ]; then
    echo "(a) skipped: no LAMMPS input at $lammps_in (LAMMPS_IN=...)"
  else
    cat >"$work/md.json" <<'JSON'
{
  "name": "bench-peers-md",
  "description": "the LAMMPS peer's 2D RFM system: N = 2000, L = 0.2 m, eps_n = 0.6, 20 000 steps",
  "model": "rfm",
  "seed": 12345,
  "replicas": 1,
  "params": {
    "dim": 2, "n_particles": 2000, "box_length": 0.2, "restitution_normal": 0.6,
    "restitution_tangential": 1.0, "noise_strength": 1e-8, "dt": 1e-6,
    "warmup": 0.0, "duration": 0.02, "sample_every": 1000
  }
}
JSON
    steps=20000 n=2000
    for r in $(seq "$reps"); do
      cpu lammps "$lmp" -in "$lammps_in" -log none -screen none -var FORCING "$forcing" -var N $n -var NSTEPS $steps
      rm -rf "$work/md-c"
      cpu granular-md "$bin" run "$work/md.json" --out "$work/md-c" --threads 1 --quiet --no-final-states
    done
    ml=$(median "$work/lammps.cpu") mg=$(median "$work/granular-md.cpu")
    echo "(a) MD, 2D RFM, N = $n, $steps steps, one thread, CPU s (median of $reps):"
    echo "    LAMMPS fix $forcing  $ml s  [$(list "$work/lammps.cpu")]  $(awk -v c="$ml" -v w=$((n * steps)) 'BEGIN {printf "%.3e", w / c}') particle-steps/s"
    echo "    granular           $mg s  [$(list "$work/granular-md.cpu")]  $(awk -v c="$mg" -v w=$((n * steps)) 'BEGIN {printf "%.3e", w / c}') particle-steps/s (start-up and tables included)"
    echo "    ratio LAMMPS / granular: $(awk -v a="$ml" -v b="$mg" 'BEGIN {printf "%.2f", a / b}')x"
  fi
fi

if [ -z "${SKIP_DSMC:-}" ]; then
  if [ -z "${AUTHORS_DSMC:-}" ]; then
    echo "(b) skipped: AUTHORS_DSMC is not set (a local build of the authors' code; never fetched or built here)"
  elif [ ! -x "$AUTHORS_DSMC" ]; then
    echo "(b) skipped: AUTHORS_DSMC=$AUTHORS_DSMC is not an executable"
  else
    cat >"$work/dsmc.json" <<JSON
{
  "name": "bench-peers-dsmc",
  "description": "the paper's Table I, low-rank, one run",
  "model": "dsmc",
  "seed": 2024,
  "replicas": 1,
  "params": {
    "method": "low_rank",
    "species": {"power_law": {"n1": 0.1, "N1": $n1, "theta": 3}},
    "restitution": {"constant": 0.5},
    "initial_temperature": 1.0,
    "t_end": 100.0,
    "output_times": {"log": {"from": 0.1, "to": 100.0, "per_decade": 4}},
    "observables": ["temperature"]
  }
}
JSON
    # The authors' code keeps large arrays on the stack (its README).
    ulimit -s unlimited 2>/dev/null || true
    for r in $(seq "$reps"); do
      cpu authors "$AUTHORS_DSMC" "$n1"
      rm -rf "$work/dsmc-c"
      cpu granular-dsmc "$bin" run "$work/dsmc.json" --out "$work/dsmc-c" --threads 1 --quiet --no-final-states
    done
    ca=$(awk '/Collisions/ {print $2}' "$work/authors.out" | tail -1)
    cg=$("$python" - "$work/dsmc-c/tables/runs" <<'PY' 2>/dev/null || echo ""
import sys, pyarrow.dataset as ds
t = ds.dataset(sys.argv[1], format="parquet").to_table(columns=["collisions"])
print(sum(t.column("collisions").to_pylist()))
PY
)
    ma=$(median "$work/authors.cpu") mg=$(median "$work/granular-dsmc.cpu")
    rate() { if [ -n "$1" ]; then awk -v n="$1" -v c="$2" 'BEGIN {printf "%.3e collisions/s", n / c}'; else echo "collisions/s n/a"; fi; }
    echo "(b) DSMC, Table I low-rank (N_1 = $n1, eps = 0.5, t = 100), one thread, CPU s (median of $reps):"
    echo "    authors' code  $ma s  [$(list "$work/authors.cpu")]  ${ca:-?} collisions, $(rate "$ca" "$ma")"
    echo "    granular       $mg s  [$(list "$work/granular-dsmc.cpu")]  ${cg:-?} collisions, $(rate "$cg" "$mg") (start-up, theory and tables included)"
    echo "    ratio authors / granular: $(awk -v a="$ma" -v b="$mg" 'BEGIN {printf "%.2f", a / b}')x"
  fi
fi
echo "load after: $(uptime | sed 's/.*load average/load average/')"
