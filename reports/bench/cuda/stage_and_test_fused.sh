#!/bin/bash
# Issue 17, first call: stage Warp's first part, then the fused-MLP tests on the GPU (no Warp needed).
cd "$(dirname "$0")/.."
mkdir -p /root/stage /tmp/site && cp .devA/wA /root/stage/wA
python3 -m pip install -q --no-index --no-deps --no-compile --no-cache-dir --upgrade --target /tmp/site .devA/*.whl || exit 3
export PYTHONPATH=/tmp/site:$PWD PYTHONUNBUFFERED=1
timeout ${TEST_S:-120} python3 -m pytest -q -p no:cacheprovider tests/test_ddf_fused.py -rs 2>&1 | tail -12
# where the fused DDF's time goes (added after the H100 runs; not yet run on a GPU)
timeout ${PARTS_S:-90} python3 -m ddfbench.bench.fused_parts --device cuda --out $OUT/fused_parts.json 2>&1 | tail -8
