#!/bin/bash
# Issue 17 on a lent GPU, second call: setup_b.sh, then the race bench and pytest -m gpu.
# usage: bash .devB/go.sh COMMIT   (run in the repo root; writes into $OUT)
cd "$(dirname "$0")/.."
source .devB/setup_b.sh "$1" || exit $?
timeout -s TERM ${BENCH_S:-330} python3 -m ddfbench.bench --device cuda --only race --oracle-backend warp --repeats ${REPEATS:-7} ${BENCH_ARGS:-} --out $OUT > $OUT/bench.log 2>&1
echo "bench rc $? at $(( $(date +%s) - T0 )) s"; grep -v "^|" $OUT/bench.log | tail -5; grep "goal\|bare\|warp_bvh" $OUT/bench.log | head -12
[ "${RUN_GPU_TESTS:-1}" = 1 ] && timeout ${TEST_S:-150} python3 -m pytest -m gpu tests/test_gpu.py tests/test_ddf_fused.py -q -p no:cacheprovider -n 4 -rs > $OUT/pytest_gpu.log 2>&1
echo "pytest rc $? at $(( $(date +%s) - T0 )) s"; tail -8 $OUT/pytest_gpu.log
