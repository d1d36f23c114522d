#!/usr/bin/env bash
# Install everything into .venv and run the main job: the three shipped scenes end to end (writes out/run/<scene>/,
# each with report.html). Extra arguments go to doefab run (e.g. --quick).
set -euo pipefail
cd "$(dirname "$0")/.."
bash scripts/setup.sh
exec .venv/bin/doefab run scenes/hdr.toml scenes/hyperspectral.toml scenes/depth.toml "$@"
