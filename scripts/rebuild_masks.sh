#!/usr/bin/env bash
# Rebuild every committed mask set in masks/ from the design it came from (masks/<task>/design/),
# or, with --from DIR, from fresh design folders DIR/<task> (as written by `doefab design`), and re-pack each
# design into the package (doefab/designs/<task>.npz, what an installed doefab uses).
set -euo pipefail
cd "$(dirname "$0")/.."
bash scripts/setup.sh
src=""
if [ "${1:-}" = "--from" ]; then src="$2"; fi
for task in streak grating half-ring; do
    design="masks/$task/design"
    if [ -n "$src" ]; then design="$src/$task"; fi
    .venv/bin/doefab masks --design "$design" --out "masks/$task" --name "${task//-/}" --oasis --force
    .venv/bin/python -c "from doefab.design.packing import pack_design; print(pack_design('masks/$task/design', '$task'))"
done
