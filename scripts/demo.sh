#!/usr/bin/env bash
# Install everything into .venv and run the main job (writes into ./out by default).
set -euo pipefail
cd "$(dirname "$0")/.."
bash scripts/setup.sh
exec .venv/bin/doefab demo --out "${1:-out/demo}"
