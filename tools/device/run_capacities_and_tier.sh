#!/bin/bash
# Issues 51 and 54 on a lent GPU, second call (after stage_and_parts.sh with PARTS_RAYS=""): setup_b.sh; then the four
# DDF capacities alone (race.main=false: no SDF, no ray-set race, no sweep), each beside Warp's BVH and the bunny's
# LODs on the primary rays of ray seeds SEEDS (default 1-5; Warp's answers the reference), one fresh process a seed,
# on the networks of .devB/prepared, pooled (run_repeats.sh: $OUT/res.tgz, $OUT/repeats.md); then the suite's gpu
# tier for ddf_tuned on the bunny (TRAIN_S s of wall clock a run, default 40), whose report with its compact records
# comes back as $OUT/tier.tgz (`tar -xzf tier.tgz` here: reports/convergence_cuda), its log as $OUT/tier.log.
# usage: bash .devB/run_capacities_and_tier.sh COMMIT   (in the repo root). A check on the CPU:
#   NO_SETUP=1 DEVICE=cpu SIZES=small TIER_DEVICE=cpu TRAIN_S=2 PREPARED_DIR=/tmp/p OUT=/tmp/o bash .devB/... x
here=$(cd "$(dirname "$0")" && pwd)  # this script's folder (.devB), wherever it was started from
cd "$(dirname "$0")/.."
if [ -z "${NO_SETUP:-}" ]; then source .devB/setup_b.sh "$1" || exit $?; else T0=$(date +%s); fi
export T0  # run_repeats.sh counts LAST_RACE_AT from this call's start, setup included
SEEDS=${SEEDS:-1 2 3 4 5} CROSSOVER=0 LAST_RACE_AT=${LAST_RACE_AT:-330} RACE1_S=${RACE1_S:-150} RACE_S=${RACE_S:-60} \
  ALL_SETS="--set race.main=false --set race.embree=false" NO_SETUP=1 FIT_STEPS=${FIT_STEPS:-6600} \
  bash "$here/run_repeats.sh" "$1"
echo "capacities done at $(( $(date +%s) - T0 )) s"
rm -rf results/convergence_cuda
timeout -k 10 -s TERM ${TIER_S:-260} python3 -m ddfbench.suite run v1 --tier gpu -- \
  hydra.sweeper.params.model=ddf_tuned hydra.sweeper.params.shape=bunny train.max_seconds=${TRAIN_S:-40} \
  train.device=${TIER_DEVICE:-cuda} threads=16 > $OUT/tier.log 2>&1
echo "tier rc $? at $(( $(date +%s) - T0 )) s"; tail -4 $OUT/tier.log
tar -czf $OUT/tier.tgz reports/convergence_cuda results/convergence_cuda/*/record.json 2>/dev/null; ls -la $OUT
