#!/bin/bash
# Issue 17 on a lent GPU: Warp (sent in two parts) and the missing wheels, then the race bench and pytest -m gpu.
# usage: bash .devB/go.sh COMMIT   (run in the repo root; writes into $OUT)
cd "$(dirname "$0")/.."
export PYTHONUNBUFFERED=1 DDFBENCH_GIT_SHA=$1 DDFBENCH_SAMPLE_MESHES=/tmp/meshes WARP_CACHE_PATH=/tmp/warpcache
T0=$(date +%s)
mkdir -p /tmp/site /tmp/meshes
python3 -m pip install -q --no-index --no-deps --no-compile --no-cache-dir --upgrade --target /tmp/site .devB/*.whl || exit 3
python3 - <<'PY' || exit 4
import lzma, shutil, tarfile
with open("/tmp/warp.so.xz", "wb") as out:
    for part in ("/root/stage/wA", ".devB/wB"):
        with open(part, "rb") as f:
            shutil.copyfileobj(f, out)
with tarfile.open(".devB/rest.tar.xz") as tar:
    tar.extractall("/tmp/site", filter="data")
for src, dst in (("/tmp/warp.so.xz", "/tmp/site/warp/bin/warp.so"), (".devB/clang.xz", "/tmp/site/warp/bin/warp-clang.so"),
                 (".devB/bunny.obj.xz", "/tmp/meshes/bunny.obj")):
    with lzma.open(src) as f, open(dst, "wb") as o:
        shutil.copyfileobj(f, o, 1 << 24)
PY
export PYTHONPATH=/tmp/site:$PWD
nvidia-smi --query-gpu=name,driver_version,clocks.max.sm,power.limit,memory.total --format=csv | tee $OUT/gpu.csv
python3 -c "import sys, torch, numpy, warp; warp.init(); print(sys.version.split()[0], torch.__version__, numpy.__version__, warp.__version__)"
echo "setup $(( $(date +%s) - T0 )) s"
timeout -s TERM ${BENCH_S:-330} python3 -m ddfbench.bench --device cuda --only race --oracle-backend warp --repeats ${REPEATS:-7} ${BENCH_ARGS:-} --out $OUT > $OUT/bench.log 2>&1
echo "bench rc $? at $(( $(date +%s) - T0 )) s"; grep -v "^|" $OUT/bench.log | tail -5; grep "goal\|bare\|warp_bvh" $OUT/bench.log | head -12
[ "${RUN_GPU_TESTS:-1}" = 1 ] && timeout ${TEST_S:-150} python3 -m pytest -m gpu tests/test_gpu.py tests/test_ddf_fused.py -q -p no:cacheprovider -n 4 -rs > $OUT/pytest_gpu.log 2>&1
echo "pytest rc $? at $(( $(date +%s) - T0 )) s"; tail -8 $OUT/pytest_gpu.log
