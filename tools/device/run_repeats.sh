#!/bin/bash
# Issue 51 on a lent GPU, second call (after stage_and_parts.sh with PARTS_RAYS=""): setup_b.sh, then the race in
# five fresh processes with ray seeds 1-5 on the networks of .devB/prepared (trained at FIT_STEPS steps,
# ddfbench.bench.prepared; one missing there is trained by seed 1's process and saved for the others), seed 1
# first with empty caches (its cold costs are a first launch: Triton compile + autotune, torch.compile, Warp's
# module), seeds 2-5 without the DDF's torch.compile variants; no sweep (runs 1-3 have it); each process under its
# own time limit (a stopped race keeps what it measured); the pooled ratios (ddfbench.bench.repeats); the crossover
# on the GPU (Warp's BVH against the one-kernel DDF, 1M rays a set). The runs come back as $OUT/res.tgz (packed
# again after each step, so a stop keeps what ran): `tar -xzf res.tgz` here. SEEDS (default "1 2 3 4 5"),
# LATER_SETS (more --set options for seeds 2-5, e.g. "--set race.embree=false --set race.sdf_loops=false"),
# ALL_SETS (for every seed, e.g. "--set race.capacity_levels=[c3,c4]"),
# CROSSOVER=0 (no crossover) and the limits RACE1_S, RACE_S, CROSS_S, LAST_RACE_AT shape a shorter call.
# usage: FIT_STEPS=N bash .devB/run_repeats.sh COMMIT   (in the repo root; writes into $OUT). A check on the CPU:
#   NO_SETUP=1 DEVICE=cpu SIZES=small FIT_STEPS=50 PREPARED_DIR=/tmp/p OUT=/tmp/o bash .devB/run_repeats.sh x
cd "$(dirname "$0")/.."
[ -n "${NO_SETUP:-}" ] && T0=${T0:-$(date +%s)} || source .devB/setup_b.sh "$1" || exit $?
export TRITON_CACHE_DIR=/tmp/triton TORCHINDUCTOR_CACHE_DIR=/tmp/inductor WARP_CACHE_PATH=/tmp/warpcache
rm -rf /tmp/triton /tmp/inductor /tmp/warpcache /tmp/res && mkdir -p /tmp/res
dev=${DEVICE:-cuda}
common="--device $dev --sizes ${SIZES:-default} --oracle-backend warp --repeats ${REPEATS:-5}"
prep=${PREPARED_DIR:-.devB/prepared}  # relative: no machine path in the reports
pack() { tar -C /tmp -czf $OUT/res.tgz res; echo "$1 rc $2 at $(( $(date +%s) - T0 )) s"; }
for k in ${SEEDS:-1 2 3 4 5}; do
  [ $(( $(date +%s) - T0 )) -lt ${LAST_RACE_AT:-440} ] || break  # leave the crossover its time in the call
  extra="" limit=${RACE1_S:-150}
  [ $k = 1 ] || extra="--set race.compile=false ${LATER_SETS:-}" limit=${RACE_S:-70}
  timeout -k 10 -s TERM $limit python3 -m ddfbench.bench $common --only race --set race.ray_seed=$k --set race.sweep=[] $extra ${ALL_SETS:-} \
    --set race.prepared=$prep --set race.fit_steps=${FIT_STEPS:?} --out /tmp/res/seed$k > /tmp/res/seed$k.log 2>&1
  pack "race seed $k" $?; grep "^\[bench\] race:" /tmp/res/seed$k.log
done
python3 -m ddfbench.bench.repeats /tmp/res/seed*/bench-*.json --out /tmp/res > /tmp/res/repeats.log 2>&1
pack repeats $?; cp /tmp/res/repeats.md $OUT/ 2>/dev/null; sed -n 7,9p /tmp/res/repeats.md
[ "${CROSSOVER:-1}" = 1 ] || exit 0
big=""; [ $dev = cpu ] || big="--set crossover.px=1024 --set crossover.incoherent_rays=1048576"
timeout -k 10 -s TERM ${CROSS_S:-70} python3 -m ddfbench.bench $common --only crossover --set crossover.prepared=$prep $big \
  --out /tmp/res/crossover > /tmp/res/crossover.log 2>&1
pack crossover $?; grep "^\[bench\] crossover:" /tmp/res/crossover.log
