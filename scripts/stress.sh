#!/usr/bin/env bash
# The numerical-stability stress suite (examples/stress.rs): eps in {0, 1e-3, 0.5, 0.999, 1},
# mass ratios up to 1e6, 2 to ~500 species, t_end = 1e9 (theta = 3, 4), densities 1e-6 and
# 1e3, both methods. `scripts/stress.sh quick` is a smaller version (~1 min).
set -euo pipefail
cd "$(dirname "$0")/.."
cargo run --release --quiet --example stress -- "$@"
