#!/bin/bash
# Sourced by the second call's scripts (run_race.sh, run_train_curves.sh, run_repeats.sh, run_capacities_and_tier.sh)
# in the repo root: Warp (sent in two parts: $DDFBENCH_STAGE/wA (default ~/stage) from stage_and_parts.sh,
# .devB/wB) and the missing wheels into /tmp/site, the bunny into /tmp/meshes; exports PYTHONPATH, DDFBENCH_GIT_SHA=$1,
# DDFBENCH_SAMPLE_MESHES and T0 (the start).
export STAGE=${DDFBENCH_STAGE:-$HOME/stage} PYTHONUNBUFFERED=1 DDFBENCH_GIT_SHA=$1 DDFBENCH_SAMPLE_MESHES=/tmp/meshes WARP_CACHE_PATH=/tmp/warpcache
T0=$(date +%s)
mkdir -p /tmp/site /tmp/meshes
python3 -m pip install -q --no-index --no-deps --no-compile --no-cache-dir --upgrade --target /tmp/site .devB/*.whl || exit 3
python3 - <<'PY' || exit 4
import lzma, os, shutil, tarfile
with open("/tmp/warp.so.xz", "wb") as out:
    for part in (os.path.join(os.environ["STAGE"], "wA"), ".devB/wB"):
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
