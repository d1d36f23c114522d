#!/usr/bin/env bash
# Train the shipped networks of the given tasks (all three variants each, the same number of steps, one after
# another, from scratch, under the honest training conditions), into a staging folder, then evaluate them once on
# the held-out test split: under honest conditions and under --clean (the nominal model's own captures).
# A step budget is one a loaded machine cannot shrink, so every variant gets the same training.
#   bash scripts/train_shipped.sh STEPS STAGING_DIR TASK [TASK ...]
# Copy STAGING_DIR/weights/* to doefab/weights/ to ship them.
set -euo pipefail
cd "$(dirname "$0")/.."
N=$1; S=$2; shift 2
PY=.venv/bin/python
for task in "$@"; do
  for v in proposed coded_only uncoded_only; do
    [ -f $S/weights/${task}_$v.json ] || $PY -m doefab train --task $task --variant $v --minutes 600 --steps $N \
        --weights-dir $S/weights --out $S/train/${task}_$v --force
  done
done
for task in "$@"; do
  $PY -m doefab evaluate --task $task --weights-dir $S/weights --images 12 --size 256 --out $S/eval/$task --force
  $PY -m doefab evaluate --task $task --weights-dir $S/weights --images 12 --size 256 --clean \
      --out $S/eval/${task}_clean --force
done
