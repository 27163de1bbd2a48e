#!/bin/bash
# Issues 17 and 51: make the two ignored staging folders that the device calls carry (the device machine has no
# network and one call carries 64 MiB, the working tree included: move reports/ aside during the calls). .devA for
# the first call (stage_and_parts.sh as pre.sh and Warp's first part, as much as fits), .devB for the second
# (Warp's second part and the rest of its wheel, the wheels the bench needs, the bunny, setup_b.sh, run_race.sh
# as go.sh, run_train_curves.sh, run_repeats.sh, run_capacities_and_tier.sh, and with PREPARED=DIR that folder of
# trained networks and LODs (ddfbench.bench.prepared) as .devB/prepared).
# Sizes (issue 51's run 6): .devA ~56 MB (Warp's first 54 MB, WA_BYTES), .devB ~49 MB with the embreex wheel (15 MB),
# ~34 MB without (EMBREEX=0: for races with race.embree=false, leaving room for PREPARED's networks, ~7 MB;
# tools/device/make_prepared.py makes that folder).
# usage: [PREPARED=DIR] [EMBREEX=0] [WA_BYTES=N] bash tools/device/make_dev_folders.sh   (in the repo root, with the
#   project's venv active)
set -euo pipefail
cd "$(dirname "$0")/../.."
here=tools/device
rm -rf .whl .devA .devB /tmp/wx && mkdir -p .whl .devA .devB /tmp/wx
pip download -q --no-deps --only-binary=:all: --python-version 3.12 --implementation cp \
  --platform manylinux_2_28_x86_64 -d .whl warp-lang==1.19.0 embreex==4.4.0.post1 trimesh==5.2.0 \
  rtree==1.4.1 hydra-core==1.3.8 omegaconf==2.3.1
pip wheel -q --no-deps -w .whl antlr4-python3-runtime==4.9.3
unzip -q .whl/warp_lang-*.whl -d /tmp/wx -x 'warp/examples/*' 'warp/tests/*' && rm .whl/warp_lang-*.whl
xz -9 -T2 -k /tmp/wx/warp/bin/warp.so
xz -9 -T2 -c /tmp/wx/warp/bin/warp-clang.so > .devB/clang.xz
tar -C /tmp/wx -cf - --exclude='warp/bin/*.so' --exclude='warp/bin/*.xz' warp warp_lang-1.19.0.dist-info \
  | xz -9 > .devB/rest.tar.xz
wa=${WA_BYTES:-54000000}  # a call counts disk use (du): 63 MB of .devA beside the tree (4.1 MiB) was refused
head -c $wa /tmp/wx/warp/bin/warp.so.xz > .devA/wA
tail -c +$((wa + 1)) /tmp/wx/warp/bin/warp.so.xz > .devB/wB
cp .whl/*.whl .devB/ && cp .devB/*.whl .devA/ && rm .devA/embreex-*.whl
[ "${EMBREEX:-1}" = 1 ] || rm .devB/embreex-*.whl
if [ -n "${PREPARED:-}" ]; then cp -r "$PREPARED" .devB/prepared; fi
meshes="$(python -c 'import os, pymeshlab; print(os.path.dirname(pymeshlab.__file__))')/tests/sample_meshes"
xz -9 -c "$meshes/bunny.obj" > .devB/bunny.obj.xz
cp $here/stage_and_parts.sh .devA/pre.sh && cp $here/run_race.sh .devB/go.sh
cp $here/setup_b.sh $here/run_train_curves.sh $here/run_repeats.sh $here/run_capacities_and_tier.sh .devB/
rm -rf .whl /tmp/wx
du -sh .devA .devB
