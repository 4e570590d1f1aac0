#!/usr/bin/env bash
# The report and the live dashboard in a real browser: installs Debian's `chromium` when no
# Chromium is on PATH (needs root and apt, as the SLURM test), then runs scripts/browser_test.py
# (headless: --dump-dom of the report, screenshots, and the served page followed over the
# DevTools protocol while another process runs a campaign). Screenshots go to
# ${BROWSER_SHOTS:-a temporary directory}. Needs target/release/granular and .venv
# (scripts/setup.sh). ~30 s once Chromium is installed.
set -euo pipefail
cd "$(dirname "$0")/.."
bin=$PWD/target/release/granular
[ -x "$bin" ] || { echo "browser-test: build first (cargo build --release)" >&2; exit 2; }

chrome=
for c in chromium chromium-browser google-chrome; do
    if command -v "$c" >/dev/null 2>&1; then chrome=$(command -v "$c"); break; fi
done
if [ -z "$chrome" ]; then
    if [ "$(id -u)" -ne 0 ] || ! command -v apt-get >/dev/null 2>&1; then
        echo "browser-test: no chromium on PATH, and installing it needs root and apt-get" >&2
        exit 2
    fi
    echo "browser-test: installing Debian's chromium"
    apt-get update -qq
    DEBIAN_FRONTEND=noninteractive apt-get install -y -qq --no-install-recommends chromium >/dev/null
    chrome=$(command -v chromium)
fi
echo "browser-test: $("$chrome" --version 2>/dev/null | head -1)"

shots=${BROWSER_SHOTS:-}
if [ -z "$shots" ]; then
    shots=$(mktemp -d)
    trap 'rm -rf "$shots"' EXIT
fi
.venv/bin/python scripts/browser_test.py "$bin" "$chrome" "$shots" "$@"
