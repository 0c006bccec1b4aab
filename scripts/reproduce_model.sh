#!/usr/bin/env bash
# Reproduce the README's model tables and figures from an empty folder, on a 2-core CPU:
#   bash scripts/reproduce_model.sh OUT [EPISODES_PER_SETTING]
# generate a 64 px dataset -> train the world model (Stage I: the cpu preset, and the per-frame
# SIGReg variant) -> eval rollout -> train the probe (Stage II) and its state-only reference ->
# eval probe -> train the Diffusion Policy -> refit the depth head for the planner -> fly the
# planner, its three MPPI oracles, Diffusion Policy, the expert and the risky pilot on the grid
# (same seeds, none used by the dataset) -> Figure 6. Every step resumes if run again.
# QUICK=1 runs every command at toy sizes (40 episodes, 3 training steps, 20-frame flights): a
# ~10 min check that the chain runs, not the README's numbers.
set -euo pipefail
OUT=${1:?usage: bash scripts/reproduce_model.sh OUT [EPISODES_PER_SETTING]}
N=${2:-20}
cd "$(dirname "$0")/.."
BIN=${BIN:-.venv/bin}
mkdir -p "$OUT/grid"
DATA="$OUT/orbit64"
WM="$OUT/wm-cpu"
WMF="$OUT/wm-cpu-perframe"
DP="$OUT/dp-cpu"
GRID=(--obstacles 1,3,5 --speeds 1,2 --episodes "$N" --seed 0)
# MPPI at what this 2-core CPU flies in reasonable time (README, "Plan and fly"); the defaults
# (K 256, H 50, 8 latents of history) are for a faster machine.
PLAN=(--samples 32 --horizon 50 --history 2)
EPISODES=3000 STEPS=() PROBE=() PROBE_EVAL=() DEPTH=() FLIGHT=()
if [ "${QUICK:-0}" = 1 ]; then
  EPISODES=40 STEPS=(--max-steps 3) PROBE=(--max-steps 3 --cache-windows 0) PROBE_EVAL=(--windows 2)
  DEPTH=(--frames 500 --test-frames 100) FLIGHT=(--max-steps 20)
fi

[ -f "$DATA/meta/info.json" ] || "$BIN/orbitdata" generate "$DATA" --episodes "$EPISODES" --image-size 64 --workers 2 --seed 0
if [ ! -f "$WM/model.safetensors" ]; then
  if [ -d "$WM/checkpoints" ]; then RESUME=--resume; else RESUME=; fi
  "$BIN/orbitmodel" train "$DATA" --preset cpu --out "$WM" $RESUME "${STEPS[@]}"
fi
# The per-frame SIGReg run (upstream's recipe on the cpu sizes): the README's Stage I comparison
# and its Table I row. The grid below is flown on the cpu run.
if [ ! -f "$WMF/model.safetensors" ]; then
  if [ -d "$WMF/checkpoints" ]; then RESUME=--resume; else RESUME=; fi
  "$BIN/orbitmodel" train "$DATA" --preset cpu --no-sigreg-pool --lambda-sigreg 0.1 --out "$WMF" $RESUME "${STEPS[@]}"
fi
for run in "$WM" "$WMF"; do
  "$BIN/orbitmodel" eval rollout "$run" "$DATA"
  [ -f "$run/probe/model.safetensors" ] || "$BIN/orbitmodel" probe "$run" "$DATA" "${PROBE[@]}"
  [ -f "$run/probe-state/model.safetensors" ] || "$BIN/orbitmodel" probe "$run" "$DATA" --state-only --batch-size 512 --lr 0.002 "${PROBE[@]}"
  "$BIN/orbitmodel" eval probe "$run" "$DATA" "${PROBE_EVAL[@]}"
done
if [ ! -f "$DP/model.safetensors" ]; then
  if [ -d "$DP/checkpoints" ]; then RESUME=--resume; else RESUME=; fi
  "$BIN/orbitmodel" train-policy "$DATA" --policy diffusion --preset cpu --out "$DP" $RESUME "${STEPS[@]}"
fi
"$BIN/orbitmodel" eval policy "$DP" "$DATA" --max-windows 2000
# The depth head refitted for near cells (RUN/depth): the planner and the depth oracle use it.
[ -f "$WM/depth/model.safetensors" ] || "$BIN/orbitmodel" depth "$WM" "$DATA" "${DEPTH[@]}"
[ -f "$OUT/grid/oracle-true-dyn-depth-stage1.json" ] || "$BIN/orbitmodel" eval closed-loop "$WM" \
  --pilot oracle-true-dyn-depth --depth-head stage1 "${PLAN[@]}" "${GRID[@]}" "${FLIGHT[@]}" --json "$OUT/grid/oracle-true-dyn-depth-stage1.json"
for pilot in planner oracle-true oracle-learned-dyn oracle-true-dyn-depth oracle-true-dyn-sensor; do
  [ -f "$OUT/grid/$pilot.json" ] || "$BIN/orbitmodel" eval closed-loop "$WM" --pilot "$pilot" "${PLAN[@]}" "${GRID[@]}" "${FLIGHT[@]}" \
    --json "$OUT/grid/$pilot.json"
done
[ -f "$OUT/grid/diffusion.json" ] || "$BIN/orbitdata" fly --pilot diffusion --pilot-option "run=$DP" --image-size 64 "${GRID[@]}" --json "$OUT/grid/diffusion.json"
for pilot in expert risky; do
  [ -f "$OUT/grid/$pilot.json" ] || "$BIN/orbitdata" fly --pilot "$pilot" --image-size 64 "${GRID[@]}" --json "$OUT/grid/$pilot.json"
done
"$BIN/orbitmodel" eval figure6 "$OUT"/grid/*.json --out "$OUT/grid/figure6.png"
