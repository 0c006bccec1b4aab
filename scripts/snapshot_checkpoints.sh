#!/usr/bin/env bash
# Keep a training run's checkpoints at every EVERY-th step as run folders of their own, while it
# trains (a run keeps only its latest checkpoints):
#   bash scripts/snapshot_checkpoints.sh RUN EVERY OUT
# OUT/step-N is then a run like RUN (its config.json and the checkpoint's weights, EMA included),
# which `orbitmodel eval policy` and `eval closed-loop` read; scripts/policy_curve.py plots them.
# Stops when RUN has its final weights at its max_steps (a run trained on with --resume --extend
# keeps its old final weights for a moment after it starts: those do not stop it). A run that ends
# at its --epochs before its --max-steps is never seen to end: stop the script by hand.
set -euo pipefail
RUN=${1:?usage: bash scripts/snapshot_checkpoints.sh RUN EVERY OUT}
EVERY=${2:?give the step interval}
OUT=${3:?give the folder for the snapshots}
mkdir -p "$OUT"
while :; do
  done_=0
  if [ -f "$RUN/model.safetensors" ]; then  # read before the last scan, so the final checkpoint is caught
    end=$(grep -o '"max_steps": [0-9]*' "$RUN/config.json" | head -1 | grep -o '[0-9]*$' || true)
    latest=$(cat "$RUN/checkpoints/latest" 2>/dev/null || true)
    if [ -z "$end" ] || [ "$end" = 0 ] || [ "$latest" = "$(printf 'step-%07d' "$end")" ]; then done_=1; fi
  fi
  for ckpt in "$RUN"/checkpoints/step-*; do
    [ -f "$ckpt/model.safetensors" ] || continue
    step=$((10#${ckpt##*step-}))
    [ $((step % EVERY)) = 0 ] && [ ! -d "$OUT/step-$step" ] || continue
    tmp="$OUT/.step-$step.tmp"
    rm -rf "$tmp" && mkdir -p "$tmp"
    cp "$RUN/config.json" "$ckpt/model.safetensors" "$tmp/" && mv "$tmp" "$OUT/step-$step"
  done
  [ "$done_" = 1 ] && break
  sleep "${SNAPSHOT_POLL_S:-20}"
done
