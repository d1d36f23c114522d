#!/usr/bin/env bash
# Train the shipped networks of the given tasks (all three variants each, the same wall-time budget, one after
# another), into a staging folder, then evaluate them on the held-out test set. Run with nothing else on the
# machine: every variant must get the same share of the CPU.
#   bash scripts/train_shipped.sh MINUTES STAGING_DIR TASK [TASK ...]
# Copy STAGING_DIR/weights/* to doefab/weights/ to ship them.
set -euo pipefail
cd "$(dirname "$0")/.."
M=$1; S=$2; shift 2
PY=.venv/bin/python
for task in "$@"; do
  for v in proposed coded_only uncoded_only; do
    [ -f $S/weights/${task}_$v.json ] || $PY -m doefab train --task $task --variant $v --minutes $M \
        --weights-dir $S/weights --out $S/train/${task}_$v --force
  done
  $PY -m doefab evaluate --task $task --weights-dir $S/weights --images 12 --size 256 --out $S/eval/$task --force
done
