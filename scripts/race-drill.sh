#!/usr/bin/env bash
# The race drill (scripts/race_drill.py): for MINUTES minutes (default 10), 4 commands at a time
# (run with random grown manifests, resume, compact, status, verify, report, plan, upgrade) on
# one small DSMC campaign, a fifth of them killed with SIGKILL at a random moment; then a final
# resume, and the campaign must equal the direct campaign of its final manifest
# (scripts/compare_tables.py --current), `verify` must be clean, and nothing outside the
# campaign directory may have changed (a symbolic link out of it is planted in tables/).
#
# Usage: scripts/race-drill.sh [MINUTES] [WORKDIR]   (default 10, a temporary directory)
# Needs the release binary (cargo build --release) and .venv (scripts/setup.sh).
# Expected: "PASS ..." with at least 500 commands and 50 kills in 10 minutes (numbers in the
# README, "Two commands at once").
set -euo pipefail
cd "$(dirname "$0")/.."
minutes=${1:-10}
work=${2:-}
if [ -z "$work" ]; then
    work=$(mktemp -d)
    trap 'rm -rf "$work"' EXIT
fi
.venv/bin/python scripts/race_drill.py target/release/granular "$work" --minutes "$minutes"
