#!/usr/bin/env bash
# Build the documentation site into docs/_build/html (open docs/_build/html/index.html): install everything
# into .venv (scripts/setup.sh), then Sphinx with warnings as errors. The tutorials run as part of the build.
# Extra arguments go to sphinx-build (e.g. -j 2).
set -euo pipefail
cd "$(dirname "$0")/.."
bash scripts/setup.sh
exec .venv/bin/python -m sphinx -W --keep-going -b html docs docs/_build/html "$@"
