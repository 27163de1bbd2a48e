#!/bin/bash
# Issues 17 and 51, first call: stage Warp's first part, then (PARTS_RAYS, default "2097152 16777216"; empty: none)
# where the fused DDF's time goes (no Warp needed; it also fills Triton's cache with the autotuned kernels of
# ddf_tuned, so leave it out when the second call measures cold costs), then (GPU_TESTS, a pytest path list;
# default none) pytest -m gpu on them, e.g. GPU_TESTS=tests/test_trace_device.py (no Warp needed either).
cd "$(dirname "$0")/.."
STAGE=${DDFBENCH_STAGE:-$HOME/stage}  # outside the working tree: the second call finds Warp's first part here
mkdir -p "$STAGE" /tmp/site && cp .devA/wA "$STAGE/wA"
python3 -m pip install -q --no-index --no-deps --no-compile --no-cache-dir --upgrade --target /tmp/site .devA/*.whl || exit 3
export PYTHONPATH=/tmp/site:$PWD PYTHONUNBUFFERED=1
nvidia-smi --query-gpu=name,driver_version,clocks.max.sm,power.limit,memory.total --format=csv | tee $OUT/gpu.csv
for n in ${PARTS_RAYS-2097152 16777216}; do
  timeout ${PARTS_S:-150} python3 -m ddfbench.bench.fused_parts --device cuda --rays $n --out $OUT/fused_parts_$n.json 2>&1 | tail -10
done
if [ -n "${GPU_TESTS:-}" ]; then
  timeout ${TEST_S:-60} python3 -m pytest -m gpu $GPU_TESTS -q -p no:cacheprovider -rs 2>&1 | tee $OUT/pytest_gpu.log | tail -5
fi
