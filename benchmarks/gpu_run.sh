#!/usr/bin/env bash
# On a machine with a CUDA GPU and PyTorch installed (no network needed: the other packages as wheels in .whl/):
# the CUDA tests, then the CPU-against-GPU table (benchmarks/gpu_table.py). Writes into ${OUT:-out/gpu}.
#   bash benchmarks/gpu_run.sh [gpu_table.py options]
set -uo pipefail
OUT=${OUT:-out/gpu}
mkdir -p "$OUT"
if [ -d .whl ]; then
  python3 -m pip install -q --no-index --no-deps --no-compile --no-cache-dir --upgrade --target /tmp/site .whl/*.whl \
    || exit 1
  export PYTHONPATH=/tmp/site
fi
export PYTHONPATH="$PWD${PYTHONPATH:+:$PYTHONPATH}" PYTHONUNBUFFERED=1 DOEFAB_CACHE=/tmp/doefab-cache
nvidia-smi --query-gpu=name,driver_version,memory.total --format=csv | tee "$OUT/gpu.txt"
python3 -c "import torch, numpy; print('torch', torch.__version__, 'cuda', torch.version.cuda, 'numpy', numpy.__version__)" \
  | tee -a "$OUT/gpu.txt"
timeout "${TEST_TIMEOUT:-150}" python3 -m pytest -q -rfEsx -m cuda -p no:cacheprovider $(grep -rlE "pytest\.mark\.cuda" tests) > "$OUT/cuda_tests.txt" 2>&1
tail -40 "$OUT/cuda_tests.txt"
for wt in ${WORKLOADS:-psf:60 design:90 train:150 judge:120}; do  # WORKLOAD:SECONDS, each on its own clock
  w=${wt%%:*}
  timeout "${wt##*:}" python3 benchmarks/gpu_table.py --only "$w" --out "$OUT/$w" "$@" 2>&1 \
    | tee -a "$OUT/gpu_table.log"
done
cat "$OUT"/*/gpu_table.md > "$OUT/gpu_table.md" 2>/dev/null
python3 - "$OUT" <<'PY'  # one JSON: each workload's rows under its name
import json, pathlib, sys
out = pathlib.Path(sys.argv[1])
got = {p.parent.name: json.loads(p.read_text()) for p in sorted(out.glob("*/gpu_table.json"))}
(out / "gpu_table.json").write_text(json.dumps(got, indent=1))
PY
for w in psf design train judge; do rm -rf "${OUT:?}/$w"; done
