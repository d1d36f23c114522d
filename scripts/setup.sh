#!/usr/bin/env bash
# Create .venv at the repository root and install doefab with everything its commands and tests use.
# PyTorch: the CPU build 2.13.0+cpu is pinned first (from local disk on the project machines, else from PyTorch's
# CPU index), so no multi-gigabyte CUDA build is ever pulled; pyproject.toml itself keeps a range (torch>=2.2).
set -euo pipefail
cd "$(dirname "$0")/.."
# Debian's chromium checks the HTML report in a real browser (tests/pipeline); installed when missing and
# when this machine allows it (root with apt-get); the browser test is skipped, and says so, otherwise.
if ! command -v chromium > /dev/null 2>&1 && [ "$(id -u)" = "0" ] && command -v apt-get > /dev/null 2>&1; then
    (apt-get update -qq && DEBIAN_FRONTEND=noninteractive apt-get install -y -qq chromium) > /dev/null 2>&1 \
        || echo "setup: could not install chromium; the browser test will be skipped" >&2
fi
PY=${PYTHON:-python3}
if [ ! -x .venv/bin/python ]; then
    "$PY" -m venv .venv
fi
stamp=.venv/.doefab-installed
want=$(cat pyproject.toml scripts/setup.sh | sha256sum | cut -d' ' -f1)
if [ -f "$stamp" ] && [ "$(cat "$stamp")" = "$want" ]; then
    exit 0
fi
.venv/bin/python -m pip install --quiet --upgrade pip
# the CPU build by its local version (PyPI's Linux wheel of 2.13.0 is a CUDA build of several GB): from a wheel
# on local disk where pip is pointed at one (the project machines), else from PyTorch's CPU index; a torch
# already in .venv (a GPU user's CUDA build) is left as it is
if ! .venv/bin/python -c "import torch" 2> /dev/null; then
    if ! .venv/bin/python -m pip install --quiet "torch==2.13.0+cpu" 2> /dev/null; then
        .venv/bin/python -m pip install --quiet "torch==2.13.0+cpu" --index-url https://download.pytorch.org/whl/cpu \
            --extra-index-url https://pypi.org/simple
    fi
    .venv/bin/python -c "import torch; assert not torch.version.cuda, f'torch {torch.__version__}: not a CPU build'"
fi
.venv/bin/python -m pip install --quiet -e ".[test,klayout,cad,cluster,docs]"
echo "$want" > "$stamp"
