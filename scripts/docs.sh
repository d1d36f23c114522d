#!/usr/bin/env bash
# Build the documentation site into docs/_build/html (open docs/_build/html/index.html): install everything
# into .venv (scripts/setup.sh), then Sphinx with warnings as errors. The tutorials run as part of the build.
# The files the tutorials write go to docs/_build/tutorial-files (emptied at each build). Extra arguments go to
# sphinx-build (e.g. -j 2).
set -euo pipefail
cd "$(dirname "$0")/.."
bash scripts/setup.sh
rm -rf docs/_build/tutorial-files && mkdir -p docs/_build/tutorial-files
export TMPDIR="$PWD/docs/_build/tutorial-files"
exec .venv/bin/python -m sphinx -W --keep-going -b html docs docs/_build/html "$@"
