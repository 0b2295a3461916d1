#!/usr/bin/env bash
# The paper-scale run on a lent GPU machine, inside a fixed time budget (docs/results.md,
# docs/benchmarks.md). Run from the repository root on that machine with what
# scripts/gpu-build.sh prepared here and the device tool carried: gpu/hnet.gz (`hnet` with the
# wgpu backend) and, for a machine without a Vulkan loader, the packages in .gl/:
#
#   scripts/gpu-run.sh                      # paper's bench, XRay-2, wgpu, 8 minutes of training
#
# Environment (defaults in brackets):
#   HNET_BIN [./gpu/hnet]  OUT [./gpu-out]  SCENES [paper-bench]  MODALITY [xray2]
#   SAMPLES [19500]  SIZE [224]
#   CONFIG [paper]  BACKEND [wgpu]  TRAIN_BUDGET [8m]  SEED [42]  BENCH_BATCH [32]
# A dry run here with a tiny budget, on Mesa's software Vulkan (apt: mesa-vulkan-drivers), checks
# the script and the wgpu build, not the GPU (docs/results.md says what it gave):
#   HNET_BIN=gpu/hnet CONFIG=cpu SAMPLES=60 SIZE=64 BENCH_BATCH=2 \
#     TRAIN_BUDGET=30s OUT=/tmp/gpu-dry scripts/gpu-run.sh
#
# What it leaves in $OUT (at most 8 files, each far under 16 MiB): run.log (everything printed,
# with the adapter and timings), bench.json (training step and inference per pair on the
# device), eval-test.json, metrics.csv, config.json, model.bpk and report.tar.gz (the figures).
set -euo pipefail
cd "$(dirname "$0")/.."
HNET_BIN=${HNET_BIN:-./gpu/hnet}
OUT=${OUT:-./gpu-out}
SCENES=${SCENES:-paper-bench}
MODALITY=${MODALITY:-xray2}
SAMPLES=${SAMPLES:-19500}
SIZE=${SIZE:-224}
CONFIG=${CONFIG:-paper}
BACKEND=${BACKEND:-wgpu}
TRAIN_BUDGET=${TRAIN_BUDGET:-8m}
SEED=${SEED:-42}
BENCH_BATCH=${BENCH_BATCH:-32}
if [ ! -x "$HNET_BIN" ] && [ -f "$HNET_BIN.gz" ]; then
  gunzip -k "$HNET_BIN.gz" && chmod +x "$HNET_BIN"
fi
mkdir -p "$OUT"
exec > >(tee -a "$OUT/run.log") 2>&1
say() { printf '[gpu-run %(%H:%M:%S)T] %s\n' -1 "$*"; }

# Vulkan: the carried loader when the machine has none; NVIDIA's ICD where the image keeps it.
if [ "$BACKEND" = wgpu ]; then
  if ! ldconfig -p 2>/dev/null | grep -q libvulkan.so.1 && ls .gl/*.deb >/dev/null 2>&1; then
    say "no Vulkan loader: unpacking the carried .gl/*.deb"
    for f in .gl/*.deb; do dpkg -x "$f" /; done
    ldconfig
  fi
  nvidia_icd=/usr/local/nvidia/share/vulkan/icd.d/nvidia_icd.json
  if [ -f "$nvidia_icd" ] && [ -z "${VK_DRIVER_FILES:-}" ]; then
    export VK_DRIVER_FILES=$nvidia_icd
  fi
  nvidia-smi --query-gpu=name,memory.total,driver_version --format=csv,noheader || true
fi
say "hnet: $("$HNET_BIN" --version)  backend $BACKEND  $(nproc) cores"

# 1. The device works: a few training steps and inferences at the paper's size, timed.
say "bench: H-Net at ${SIZE}px, batch $BENCH_BATCH, on $BACKEND"
"$HNET_BIN" bench model --backend "$BACKEND" --size "$SIZE" --batch "$BENCH_BATCH" --steps 5 \
  --runs 20 --json | tee "$OUT/bench.json"

# 2. The dataset, on every core (the simulation is seeded and byte-identical for a seed).
data=$(mktemp -d)/"$MODALITY"
say "simulating $SAMPLES $SCENES $MODALITY pairs at ${SIZE}px into $data"
"$HNET_BIN" simulate --scenes "$SCENES" --modality "$MODALITY" --samples "$SAMPLES" \
  --size "$SIZE" --seed "$SEED" --out "$data"

# 3. Training, stopped cleanly at the budget with the best checkpoint exported.
run=$(mktemp -d)/run
say "training --config $CONFIG for at most $TRAIN_BUDGET"
"$HNET_BIN" train --data "$data" --out "$run" --config "$CONFIG" --backend "$BACKEND" \
  --seed "$SEED" --time-budget "$TRAIN_BUDGET"

# 4. Tables I and II on the test split, and the figures.
say "evaluating"
"$HNET_BIN" eval --run "$run" --backend "$BACKEND" --json > "$OUT/eval-test.json"
"$HNET_BIN" report --run "$run" --backend "$BACKEND"
cp "$run/metrics.csv" "$run/config.json" "$run/model.bpk" "$OUT/"
tar czf "$OUT/report.tar.gz" -C "$run" report
say "done: $(ls "$OUT" | tr '\n' ' ')"
