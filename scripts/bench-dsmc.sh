#!/usr/bin/env bash
# Single-threaded timing of the paper's Table I set-up (N1 = 1e6, eps = 0.5, t = 100), both
# methods, several seeds. Peer (authors' Fortran code on these machines): low-rank 15.5-20 s
# CPU, Bird 181-236 s CPU (../shared/peers/README.md). Target: low-rank <= ~1.5 s.
#   scripts/bench-dsmc.sh [N1] [seeds...]
set -euo pipefail
cd "$(dirname "$0")/.."
n1=${1:-1000000}
shift || true
seeds=${*:-1 2 3}
cargo build --release --example bench_dsmc >/dev/null 2>&1 || cargo build --release --example bench_dsmc
for method in low_rank bird; do
  for seed in $seeds; do
    ./target/release/examples/bench_dsmc "$method" "$n1" 100 0.5 "$seed"
    echo
  done
done
