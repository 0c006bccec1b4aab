#!/usr/bin/env bash
# Keep a training run's checkpoints at every EVERY-th step as run folders of their own, while it
# trains (a run keeps only its latest checkpoints):
#   bash scripts/snapshot_checkpoints.sh RUN EVERY OUT
# OUT/step-N is then a run like RUN (its config.json and the checkpoint's weights, EMA included),
# which `orbitmodel eval policy` and `eval closed-loop` read; scripts/policy_curve.py plots them.
# Stops when RUN has its final weights.
set -euo pipefail
RUN=${1:?usage: bash scripts/snapshot_checkpoints.sh RUN EVERY OUT}
EVERY=${2:?give the step interval}
OUT=${3:?give the folder for the snapshots}
mkdir -p "$OUT"
while :; do
  done_=0
  [ -f "$RUN/model.safetensors" ] && done_=1  # read before the last scan, so the final checkpoint is caught
  for ckpt in "$RUN"/checkpoints/step-*; do
    [ -f "$ckpt/model.safetensors" ] || continue
    step=$((10#${ckpt##*step-}))
    [ $((step % EVERY)) = 0 ] && [ ! -d "$OUT/step-$step" ] || continue
    tmp="$OUT/.step-$step.tmp"
    rm -rf "$tmp" && mkdir -p "$tmp"
    cp "$RUN/config.json" "$ckpt/model.safetensors" "$tmp/" && mv "$tmp" "$OUT/step-$step"
  done
  [ "$done_" = 1 ] && break
  sleep 20
done
