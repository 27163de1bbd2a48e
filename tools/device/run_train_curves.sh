#!/bin/bash
# Issue 17 on a lent GPU, second call (after stage_and_parts.sh): setup_b.sh, then the convergence
# experiment's DDF curves on the GPU (ddf_tuned, bunny, 3 seeds, TRAIN_S s of wall clock each, probes
# log-spaced as on the CPU; the run folders come back as one file, $OUT/res.tgz: the device's transfer left
# the nested $OUT/res/... folders out; `tar -xzf res.tgz` here, then `python -m ddfbench.report res/...`),
# then the whole of pytest -m gpu.
# usage: bash .devB/go.sh COMMIT   (run in the repo root; writes into $OUT)
cd "$(dirname "$0")/.."
source .devB/setup_b.sh "$1" || exit $?
timeout -s TERM ${TRAIN_WALL_S:-330} python3 -m ddfbench +experiment=convergence hydra.sweeper.params.model=ddf_tuned \
  hydra.sweeper.params.shape=bunny train.device=cuda train.max_seconds=${TRAIN_S:-60} oracle.backend=warp \
  threads=16 quiet=true experiment_name=convergence_cuda out_dir=$OUT/res > $OUT/train.log 2>&1
echo "train rc $? at $(( $(date +%s) - T0 )) s"; tail -5 $OUT/train.log
tar -C $OUT -czf $OUT/res.tgz --exclude=.cache res && rm -rf $OUT/res
timeout ${TEST_S:-200} python3 -m pytest -m gpu tests/test_gpu.py tests/test_ddf_fused.py -q -p no:cacheprovider -n 4 -rs > $OUT/pytest_gpu.log 2>&1
echo "pytest rc $? at $(( $(date +%s) - T0 )) s"; tail -8 $OUT/pytest_gpu.log
