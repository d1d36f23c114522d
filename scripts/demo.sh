#!/usr/bin/env bash
# Install everything into .venv and run the main job: the three shipped scenes end to end (writes out/run/<scene>/,
# each with report.html; side by side, one per core as memory allows: each logs to out/run/<scene>.log). Extra
# arguments go to doefab run (e.g. --quick, --jobs 1).
set -euo pipefail
cd "$(dirname "$0")/.."
bash scripts/setup.sh
exec .venv/bin/doefab run scenes/depth.toml scenes/hdr.toml scenes/hyperspectral.toml "$@"  # the longest first
