#!/usr/bin/env bash
# Choose the depth DOE by the depth network's validation MAE (same network, same training budget, honest
# captures). Candidates: the committed design, and radial designs of both ring laws from the refocusing lens.
# Every network trains the same number of steps (a budget a loaded machine cannot shrink).
#   bash scripts/depth_candidates.sh [STEPS_PER_NETWORK]
set -euo pipefail
cd "$(dirname "$0")/.."
S=${1:-300}
D=out/depthcand
PY=.venv/bin/python
mkdir -p $D
[ -f $D/committed/design.json ] || { mkdir -p $D/committed; cp masks/half-ring/design/* $D/committed/; }
for law in seed defocus; do
  [ -f $D/radial-$law/design.json ] || $PY -m doefab design --task half-ring --parameterization radial --sampling 2 \
      --iterations 600 --ring-law $law --out $D/radial-$law
done
for c in ${CANDIDATES:-committed radial-seed radial-defocus}; do
  [ -f $D/$c/weights/depth_proposed.json ] || $PY -m doefab train --task depth --variant proposed --minutes 600 --steps $S \
      --design $D/$c --weights-dir $D/$c/weights --out $D/$c/train --force
  $PY -m doefab evaluate --task depth --split val --design $D/$c --weights-dir $D/$c/weights --variants proposed \
      --images 12 --size 256 --out $D/$c/eval --force
done
