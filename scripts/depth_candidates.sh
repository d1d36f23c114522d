#!/usr/bin/env bash
# Issue 12: compare depth DOE candidates by the depth network's test MAE (same network, same training budget).
# Run with nothing else on the machine: every training has the same wall-time budget.
#   bash scripts/depth_candidates.sh [MINUTES_PER_NETWORK] [E2E_MINUTES]
set -euo pipefail
cd "$(dirname "$0")/.."
M=${1:-6}
E=${2:-20}
D=out/depthcand
PY=.venv/bin/python
mkdir -p $D
# the pixel-wise design that was the default before this comparison (from git history)
if [ ! -f $D/pixelwise/design.json ]; then
  mkdir -p $D/pixelwise
  for f in design.json levels.npy; do git show 8c3351e:masks/half-ring/design/$f > $D/pixelwise/$f; done
fi
# the two radial candidates (skipped when they exist)
for law in seed defocus; do
  [ -f $D/radial-$law/design.json ] || $PY -m doefab design --task half-ring --parameterization radial --sampling 2 \
      --iterations 600 --ring-law $law --out $D/radial-$law
done
train() {  # name design-folder
  $PY -m doefab train --task depth --variant proposed --minutes $M --design $2 --weights-dir $D/$1/weights \
      --out $D/$1/train --force
}
evaluate() {
  $PY -m doefab evaluate --task depth --design $2 --weights-dir $D/$1/weights --variants proposed --images 12 \
      --size 256 --out $D/$1/eval --force
}
[ -f $D/pixelwise/weights/depth_proposed.json ] || train pixelwise $D/pixelwise
[ -f $D/radial-seed/weights/depth_proposed.json ] || train radial-seed $D/radial-seed
[ -f $D/radial-defocus/weights/depth_proposed.json ] || train radial-defocus $D/radial-defocus
# end-to-end: start from the defocus-law radial design and its network
[ -f $D/e2e/design/design.json ] || $PY -m doefab finetune --design $D/radial-defocus \
    --weights-dir $D/radial-defocus/weights --minutes $E --out $D/e2e --force
# the fine-tuned design gets a fresh network with the same budget as the others
[ -f $D/e2e-fresh/weights/depth_proposed.json ] || train e2e-fresh $D/e2e/design
for c in pixelwise radial-seed radial-defocus; do
  evaluate $c $D/$c
done
evaluate e2e-fresh $D/e2e/design
evaluate e2e $D/e2e/design   # the jointly trained network itself
