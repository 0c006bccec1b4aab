#!/usr/bin/env bash
# Reproduce the model results (docs/results.md) from an empty folder, on a 2-core CPU:
#   bash scripts/reproduce_model.sh OUT [EPISODES_PER_SETTING]
# The headline chain: generate a 64 px dataset -> train the world model (preset cpu-step5, the run
# the planner flies) -> eval rollout -> train the probe (Stage II) -> eval probe -> refit the depth
# head -> train and evaluate the Diffusion Policy (and its variant without the camera, flown on the
# test seeds only) -> fly the planner (planner preset cpu), its MPPI
# oracles (and the depth oracle on the Stage I head), the Diffusion Policy, the expert and the risky
# pilot on the grid (same seeds, none used by the dataset) -> Figure 6 -> the planner, oracles and
# references again on a second validation seed (OUT/grid/seed2) -> every pilot on the test seeds
# 3, 4 and 5 (OUT/grid/seedN/, pooled in OUT/grid/test/, Figure 6 of them).
# The validation rule: grid seeds 0, 1, 2, 11 and 12 choose (docs/results/validation/), the test
# seeds only report; dataset-side choices are made on held-out training episodes (--val-fraction).
# ALL=1 adds the per-frame-predictor comparisons: the cpu preset and upstream's per-frame SIGReg
# recipe (Stage I, probes and their state-only reference, eval), and the planner, learned-dynamics
# and depth oracles flown on the cpu run (OUT/grid/cpu-run/).
# POLICY=0 leaves out the Diffusion Policy (its training, evaluation and flights); a later run
# without it adds them and flies nothing else again.
# QUICK=1 runs every command at toy sizes (40 episodes, 3 training steps, 20-frame flights): a check
# that the chain runs, not the reported numbers.
# Every step resumes if run again: training, probes and refits whose output exists are skipped
# (training resumes from its checkpoints); the evaluations re-run (seconds each). A grid is flown
# again unless its JSON records ("command") exactly the command that would fly it now, so a
# changed flag, preset or run re-flies it; an eval closed-loop grid cut mid-way continues from
# the chunks its flight kept (docs/planner.md), and its step time then counts what it flew.
# Each step's wall time goes to OUT/timings.tsv (step, seconds, finished at), and the last line
# is the whole invocation's ("total"). The grid flights run two at a time, one torch thread each:
# both cores busy. With the policies, the static chain's trainings run as two streams side by side,
# on half the cores' threads each (below), so their steps' times overlap in timings.tsv.
# BATCH=N flies each eval closed-loop grid N episodes at a time in lockstep (--batch N), and
# EXECUTOR=ray spreads its chunks over the Ray cluster that RAY_ADDRESS names (docs/planner.md);
# without them the grids fly as reported (one episode at a time, here). The planner's and oracles'
# episodes fly bit for bit as unbatched, the policy's up to float rounding. A grid flown with either
# is another command, so it is flown again.
# TIER=dynamic builds the dynamic tier's results instead (its dataset, run and grids; below), and
# WAY=imagined|tracker names the way of predicting the debris that its planner.json flies.
set -euo pipefail
OUT=$(realpath -m "${1:?usage: bash scripts/reproduce_model.sh OUT [EPISODES_PER_SETTING]}")
N=${2:-20}
cd "$(dirname "$0")/.."
BIN=${BIN:-.venv/bin}
POLICY=${POLICY:-1}
refuse() { echo "reproduce_model.sh: $*" >&2; exit 2; }  # a usage error, before anything runs
[[ "$N" =~ ^[1-9][0-9]*$ ]] || refuse "EPISODES_PER_SETTING=$N: give a whole number of episodes per setting, 1 or more"
case "${TIER:-static}" in static | dynamic) ;; *) refuse "TIER=$TIER: give static or dynamic" ;; esac
case "${WAY:-tracker}" in tracker | imagined) ;; *) refuse "WAY=$WAY: give tracker or imagined" ;; esac
case "$POLICY" in 0 | 1) ;; *) refuse "POLICY=$POLICY: give 1 (train and fly the Diffusion Policy) or 0" ;; esac
case "${QUICK:-0}" in 0 | 1) ;; *) refuse "QUICK=$QUICK: give 1 (toy sizes) or 0" ;; esac
[[ "${BATCH:-1}" =~ ^[1-9][0-9]*$ ]] || refuse "BATCH=$BATCH: give a whole number of episodes, 1 or more"
case "${EXECUTOR:-local}" in local | ray) ;; *) refuse "EXECUTOR=$EXECUTOR: give local or ray" ;; esac
# A folder holds one chain's sizes: toy-size outputs (QUICK=1) are never taken up by the full chain, nor
# the other way round, since every step skips what its output already holds.
SIZES="$([ "${QUICK:-0}" = 1 ] && echo quick || echo full)"
if [ -f "$OUT/chain-sizes" ] && [ "$(cat "$OUT/chain-sizes")" != "$SIZES" ]; then
  refuse "$OUT holds a chain of $(cat "$OUT/chain-sizes") sizes; give another OUT for a $SIZES one"
fi
mkdir -p "$OUT" && echo "$SIZES" >"$OUT/chain-sizes"
DATA="$OUT/orbit64"
WMS="$OUT/wm-cpu-step5"
WM="$OUT/wm-cpu"
WMF="$OUT/wm-cpu-perframe"
DP="$OUT/dp-cpu"
DPS="$OUT/dp-state"  # the policy without the camera (preset cpu-state), a second baseline row
# The policy trains the cpu preset's 16,000 steps, the run the test seeds report. DP_STEPS=N trains
# a copy of it on to N steps (--resume --extend) in OUT/dp-cpu-N, which the policy's grids then fly:
# trained on under N = 32,000 (and stopped at 28,000), its held-out MSE kept falling slowly and its
# one-obstacle flights on validation seed 1 (20 episodes per point, the only flights of the extension)
# stayed at 17-18 of 20 (docs/results.md#the-diffusion-policy).
DP_STEPS=${DP_STEPS:-}
AT_SCALE=()  # eval closed-loop's --batch and --executor, only when asked for (the recorded commands stay as they were)
[ "${BATCH:-1}" = 1 ] || AT_SCALE+=(--batch "$BATCH")
[ "${EXECUTOR:-local}" = local ] || AT_SCALE+=(--executor "$EXECUTOR")
use_grid() {  # use_grid SEED DIR: the grid the flights below fly, and the folder of their JSON
  GRID=(--obstacles 1,3,5 --speeds 1,2 --episodes "$N" --seed "$1") GDIR=$2
  mkdir -p "$GDIR"
}
use_grid 0 "$OUT/grid"
EPISODES=3000 STEPS=() PROBE=() PROBE_EVAL=() DEPTH=() FLIGHT=() ROLLOUT=() VAL_WINDOWS=(--windows 90) FLOOR=()
if [ "${QUICK:-0}" = 1 ]; then
  EPISODES=40 STEPS=(--max-steps 3) PROBE=(--max-steps 3 --cache-windows 0) PROBE_EVAL=(--windows 2)
  VAL_WINDOWS=(--windows 1 --horizon 5)
  DEPTH=(--frames 500 --test-frames 100) FLIGHT=(--max-steps 20) ROLLOUT=(--windows 2) DP_STEPS=6
  FLOOR=(--plans 4 --position-m 0.5 --speed-mps 0.5 --angle-deg 60)
fi
DP0=$DP  # the preset-length policy run
[ -z "$DP_STEPS" ] || DP="$OUT/dp-cpu-$DP_STEPS"  # a longer one has a folder of its own, named in its grids' commands

TIMES="$OUT/timings.tsv"
step() {  # step NAME COMMAND...: run it and log its wall time
  local name=$1 t0=$SECONDS
  shift
  "$@"
  printf '%s\t%d\t%s\n' "$name" $((SECONDS - t0)) "$(date -u +%FT%TZ)" >>"$TIMES"
}
JOBS=()
spawn() { "$@" & JOBS+=($!); }  # start a flight in the background
join() {  # wait for every spawned flight; fail if any failed
  local rc=0 pid
  for pid in "${JOBS[@]}"; do wait "$pid" || rc=$?; done
  JOBS=()
  return $rc
}
flown_by() {  # flown_by JSON COMMAND...: true when JSON exists and records exactly COMMAND
  [ -f "$1" ] && "$BIN/python" - "$@" <<'PY'
import json, sys
sys.exit(0 if json.load(open(sys.argv[1])).get("command") == sys.argv[2:] else 1)
PY
}
fly() {  # fly JSON COMMAND...: COMMAND --json JSON, then record COMMAND in JSON; skipped if JSON was flown by it
  local json=$1
  shift
  mkdir -p "$(dirname "$json")"
  flown_by "$json" "$@" && return 0
  "$@" --json "$json"
  "$BIN/python" - "$json" "$@" <<'PY'
import json, sys
report = json.load(open(sys.argv[1]))
report["command"] = sys.argv[2:]
open(sys.argv[1], "w").write(json.dumps(report, indent=2) + "\n")
PY
}
fly_run() {  # fly_run RUN NAME PILOT [OPTIONS...]: a planning pilot on RUN -> grid/NAME.json
  local run=$1 name=$2 pilot=$3
  shift 3
  fly "$GDIR/$name.json" "$BIN/orbitmodel" eval closed-loop "$run" --pilot "$pilot" --preset cpu "${GRID[@]}" \
    "${FLIGHT[@]}" "${AT_SCALE[@]}" "$@"
}
fly_model() { fly_run "$WMS" "$@"; }  # fly_model NAME PILOT [OPTIONS...]: on the planner's run
fly_data() {  # fly_data PILOT [OPTIONS...]: an orbitdata pilot -> grid/PILOT.json
  local pilot=$1
  shift
  fly "$GDIR/$pilot.json" "$BIN/orbitdata" fly --pilot "$pilot" --image-size 64 "${GRID[@]}" "$@"
}
# The policy flies the flight preset cpu (`orbitmodel presets`): 8 actions per chunk, one draw, DDIM with
# trailing spacing, the camera through the dataset's JPEG codec, chosen on validation seeds
# (docs/results/validation/diffusion/). Its camera-less variant was reported with the reference's sampler.
fly_policy() {  # the Diffusion Policy run, flown by eval closed-loop like the planner -> grid/diffusion.json
  fly "$GDIR/diffusion.json" "$BIN/orbitmodel" eval closed-loop "$DP" --preset cpu "${GRID[@]}" "${FLIGHT[@]}" \
    "${AT_SCALE[@]}"
}
fly_policy_state() {  # the policy without the camera -> grid/diffusion-state.json
  fly "$GDIR/diffusion-state.json" "$BIN/orbitmodel" eval closed-loop "$DPS" --preset reference "${GRID[@]}" \
    "${FLIGHT[@]}" "${AT_SCALE[@]}"
}
train_wm() {  # train_wm RUN PRESET [OPTIONS...]: Stage I, resuming a cut run
  local run=$1 preset=$2 resume=()
  shift 2
  [ -f "$run/model.safetensors" ] && return 0
  [ -d "$run/checkpoints" ] && resume=(--resume)
  "$BIN/orbitmodel" train "$DATA" --preset "$preset" --out "$run" "${resume[@]}" "$@" "${STEPS[@]}"
}
probe_and_eval() {  # probe_and_eval RUN ROLLOUT_HORIZON: eval rollout, the probe, eval probe
  local run=$1 horizon=$2 name
  name=$(basename "$run")
  step "rollout-$name" "$BIN/orbitmodel" eval rollout "$run" "$DATA" --horizon "$horizon" "${ROLLOUT[@]}"
  [ -f "$run/probe/model.safetensors" ] || step "probe-$name" "$BIN/orbitmodel" probe "$run" "$DATA" "${PROBE[@]}"
  step "eval-probe-$name" "$BIN/orbitmodel" eval probe "$run" "$DATA" "${PROBE_EVAL[@]}"
}
refit() {  # refit RUN [OPTIONS...]: the depth head refitted for the planner (RUN/depth), unless there
  local run=$1
  shift
  [ -f "$run/depth/model.safetensors" ] || step "depth-refit-$(basename "$run")" "$BIN/orbitmodel" depth "$run" "$DATA" "$@" "${DEPTH[@]}"
}

if [ "${TIER:-static}" = dynamic ]; then
  # The dynamic tier (docs/results.md "The dynamic tier"): its 3000-episode 64 px dataset, the
  # tier's recipe (cpu-step5-dynamic: cpu-step5 with the probe chosen for the tier) trained on it,
  # the probe, the depth refit and the imagined-depth head (way a), then the tier's grid (3, 7 and
  # 10 pieces of debris at 1 and 3 m/s) on validation seeds 0, 1 and 2 and test seeds 3, 4 and 5
  # (OUT/dynamic/grid/seedN/PILOT.json, pooled in OUT/dynamic/grid/test/):
  # the planner both ways (planner-imagined, planner-tracker; planner.json is WAY's, the way chosen
  # on the validation seeds), both ways again with the body fitted to the pilot's history in place
  # of the probe's states (planner-fitted-*) and under the prior learned from the tier's episodes
  # (planner-inferred-tracker), and with the world model's own dynamics corrected by their misses over
  # the pilot's history (planner-corrected-tracker), the oracles (oracle-fitted and oracle-inferred: the
  # true debris and the fitted or inferred body; oracle-learned-dyn-corrected: the true debris and the
  # corrected dynamics), the expert, and the Diffusion Policy trained on the tier's expert episodes with the
  # flown recipe (preset cpu), flown as the static grid flies it.
  DATA="$OUT/orbit_dynamic64" WMS="$OUT/wm-dyn" GDIR_ROOT="$OUT/dynamic/grid"
  WAY=${WAY:-tracker}
  IMAGINED=() BODY=()
  [ "${QUICK:-0}" = 1 ] && IMAGINED=(--frames 8 --test-frames 4 --epochs 1)
  # the tier's probe trains on a cache of its calm windows (--max-body-rate needs one)
  [ "${QUICK:-0}" = 1 ] && PROBE=(--max-steps 3 --cache-windows 64 --batch-size 16)
  [ "${QUICK:-0}" = 1 ] && BODY=(--steps 3)
  [ -f "$DATA/meta/info.json" ] || step generate-dynamic "$BIN/orbitdata" generate "$DATA" --tier dynamic \
    --episodes "$EPISODES" --image-size 64 --workers 2 --seed 0
  # the flown recipe for the tier's shorter, faster-spinning episodes (docs/model.md)
  step train-dynamic train_wm "$WMS" cpu-step5-dynamic
  [ -f "$WMS/probe/model.safetensors" ] || step probe-dynamic "$BIN/orbitmodel" probe "$WMS" "$DATA" "${PROBE[@]}"
  # The tier's held-out episodes hold 53 windows of 8 context steps and the probe's horizon (the
  # static dataset's, 90 and more): the windows docs/results.md scores every tier probe on.
  [ "${QUICK:-0}" = 1 ] || VAL_WINDOWS=(--windows 53)
  for history in 2 8; do
    "$BIN/orbitmodel" eval probe "$WMS" "$DATA" --split val --history "$history" --context 8 \
      --out "$WMS/eval-val-history$history" --no-figures "${VAL_WINDOWS[@]}"
  done
  refit "$WMS"
  # the prior over the tier's bodies that --set body=inferred fits under (RUN/body, docs/planner.md)
  [ -f "$WMS/body/model.safetensors" ] || step body-dynamic "$BIN/orbitmodel" body "$WMS" "$DATA" "${BODY[@]}"
  DPD="$OUT/dp-dyn" RESUME=()
  [ -d "$DPD/checkpoints" ] && RESUME=(--resume)
  if [ "$POLICY" = 1 ] && [ ! -f "$DPD/model.safetensors" ]; then
    step train-diffusion-dynamic "$BIN/orbitmodel" train-policy "$DATA" --preset cpu \
      --val-fraction 0.05 --out "$DPD" "${RESUME[@]}" "${STEPS[@]}"
  fi
  [ -f "$WMS/depth-imagined/model.safetensors" ] || step imagined-dynamic "$BIN/orbitmodel" depth "$WMS" "$DATA" \
    --imagined --eval-split val "${IMAGINED[@]}"
  use_tier_grid() {  # use_tier_grid SEED DIR [SPEEDS]: the tier's grid (both speeds unless SPEEDS), and its folder
    GRID=(--config configs/dynamic.toml --obstacles 3,7,10 --speeds "${3:-1,3}" --episodes "$N" --seed "$1") GDIR=$2
    mkdir -p "$GDIR"
  }
  for seed in 0 1 2 3 4 5; do
    use_tier_grid "$seed" "$GDIR_ROOT/seed$seed"
    spawn fly_model planner-imagined planner --set obstacle_motion=imagined
    spawn fly_model planner-tracker planner --set obstacle_motion=tracker
    step "dynamic-seed$seed-planner" join
    spawn fly_model oracle-true oracle-true --set obstacle_motion=true
    spawn fly_model oracle-frozen oracle-true --set obstacle_motion=frozen
    step "dynamic-seed$seed-oracles" join
    spawn fly_model oracle-nominal oracle-true --set obstacle_motion=true --set body=nominal
    spawn fly_model oracle-learned-dyn oracle-learned-dyn --set obstacle_motion=true
    step "dynamic-seed$seed-oracles-2" join
    # the body fitted to each pilot's own history (--set body=fitted, docs/planner.md)
    spawn fly_model planner-fitted-tracker planner --set obstacle_motion=tracker --set body=fitted
    spawn fly_model planner-fitted-imagined planner --set obstacle_motion=imagined --set body=fitted
    step "dynamic-seed$seed-fitted" join
    spawn fly_model oracle-fitted oracle-true --set obstacle_motion=true --set body=fitted
    spawn fly_model planner-inferred-tracker planner --set obstacle_motion=tracker --set body=inferred
    step "dynamic-seed$seed-fitted-2" join
    spawn fly_model oracle-inferred oracle-true --set obstacle_motion=true --set body=inferred
    # the world model's own dynamics corrected by their misses over the pilot's history (--set body=corrected)
    spawn fly_model planner-corrected-tracker planner --set obstacle_motion=tracker --set body=corrected
    step "dynamic-seed$seed-inferred" join
    spawn fly_model oracle-learned-dyn-corrected oracle-learned-dyn --set obstacle_motion=true --set body=corrected
    step "dynamic-seed$seed-corrected" join
    step "dynamic-seed$seed-expert" fly_data expert
    if [ "$POLICY" = 1 ]; then
      step "dynamic-seed$seed-diffusion" fly "$GDIR/diffusion.json" "$BIN/orbitmodel" eval closed-loop "$DPD" --preset cpu \
        "${GRID[@]}" "${FLIGHT[@]}" "${AT_SCALE[@]}"
    fi
    cp "$GDIR/planner-$WAY.json" "$GDIR/planner.json"
  done
  mkdir -p "$GDIR_ROOT/test"
  POOLED=()
  for pilot in planner planner-imagined planner-tracker planner-fitted-tracker planner-fitted-imagined \
    planner-inferred-tracker planner-corrected-tracker oracle-true oracle-frozen oracle-nominal oracle-learned-dyn \
    oracle-learned-dyn-corrected oracle-fitted oracle-inferred expert $([ "$POLICY" = 1 ] && echo diffusion); do
    "$BIN/orbitmodel" eval pool "$GDIR_ROOT"/seed{3,4,5}/"$pilot.json" --json "$GDIR_ROOT/test/$pilot.json"
    POOLED+=("$GDIR_ROOT/test/$pilot.json")
  done
  # success by factor (the fault, eclipse, ...), closest approach, delta-v and time to goal
  "$BIN/orbitmodel" eval factors "${POOLED[@]}" --json "$GDIR_ROOT/test/factors.json" >"$GDIR_ROOT/test/factors.md"
  # The static tier's run (OUT/wm-cpu-step5, the static chain's: run it into this OUT first) on this
  # tier (docs/results.md "The dynamic tier: the static tier's world model"), OUT/dynamic/static-run/:
  # alone with its own depth head, and corrected by its misses with a depth head refitted on this
  # tier's frames (RUN/depth-dynamic), at the preset's K = 32, at K = 128 and at K = 256 (its -k128 and
  # -k256 grids, each chosen on validation seeds 0-2); on validation seeds 0-2 also corrected with its own head.
  # Beside them, on every seed, the oracles that say where the corrected planner loses: its corrected
  # dynamics with the true debris, and the true body with the tier's head or the rendered depth,
  # each through the tracker (docs/results.md "The dynamic tier: where the static run's planner loses").
  SRUN="$OUT/wm-cpu-step5" SDIR="$OUT/dynamic/static-run"
  if [ -f "$SRUN/model.safetensors" ] && [ -f "$SRUN/probe/model.safetensors" ]; then
    [ -f "$SRUN/depth-dynamic/model.safetensors" ] || step depth-refit-static-run-dynamic "$BIN/orbitmodel" depth \
      "$SRUN" "$DATA" --name dynamic --eval-split val "${DEPTH[@]}"
    for seed in 0 1 2 3 4 5; do
      use_tier_grid "$seed" "$SDIR/seed$seed"
      spawn fly_run "$SRUN" planner-tracker planner --set obstacle_motion=tracker
      spawn fly_run "$SRUN" planner-corrected-tracker-depth-dynamic planner --set obstacle_motion=tracker \
        --set body=corrected --set depth_head=dynamic
      step "dynamic-static-run-seed$seed" join
      spawn fly_run "$SRUN" oracle-learned-dyn-corrected oracle-learned-dyn --set obstacle_motion=true \
        --set body=corrected
      spawn fly_run "$SRUN" oracle-true-dyn-depth-dynamic-tracker oracle-true-dyn-depth \
        --set obstacle_motion=tracker --set depth_head=dynamic
      step "dynamic-static-run-seed$seed-oracles" join
      spawn fly "$GDIR/oracle-true-dyn-sensor-tracker.json" "$BIN/orbitmodel" eval closed-loop \
        --pilot oracle-true-dyn-sensor --preset cpu "${GRID[@]}" "${FLIGHT[@]}" "${AT_SCALE[@]}" --set obstacle_motion=tracker
      [ "$seed" -gt 2 ] || spawn fly_run "$SRUN" planner-corrected-tracker planner --set obstacle_motion=tracker \
        --set body=corrected
      step "dynamic-static-run-seed$seed-2" join
      # K = 128 candidates for this planner, chosen on validation seeds 0-2 against K = 32
      # (docs/results.md "The dynamic tier: the flown planner's cost and K, on validation"), then
      # K = 256, chosen there against K = 128 ("The dynamic tier: K = 256 on validation seeds 0-2"):
      # each several times the CPU of its K = 32 grid, so two halves of each grid (one speed each)
      # fly side by side and `eval merge` joins them.
      for k in 128 256; do
        KN=planner-corrected-tracker-depth-dynamic-k$k
        for speed in 1 3; do
          use_tier_grid "$seed" "$GDIR" "$speed"
          spawn fly_run "$SRUN" "$KN-speed$speed" planner --set obstacle_motion=tracker --set body=corrected \
            --set depth_head=dynamic --set samples=$k
        done
        step "dynamic-static-run-seed$seed-k$k" join
        "$BIN/orbitmodel" eval merge "$GDIR/$KN-speed1.json" "$GDIR/$KN-speed3.json" --json "$GDIR/$KN.json"
      done
    done
    mkdir -p "$SDIR/test"
    LOSSES=(planner-tracker planner-corrected-tracker-depth-dynamic planner-corrected-tracker-depth-dynamic-k128
      planner-corrected-tracker-depth-dynamic-k256 oracle-learned-dyn-corrected oracle-true-dyn-depth-dynamic-tracker
      oracle-true-dyn-sensor-tracker)
    POOLED=()
    for pilot in "${LOSSES[@]}"; do
      "$BIN/orbitmodel" eval pool "$SDIR"/seed{3,4,5}/"$pilot.json" --json "$SDIR/test/$pilot.json"
      POOLED+=("$SDIR/test/$pilot.json")
    done
    "$BIN/orbitmodel" eval factors "${POOLED[@]}" --json "$SDIR/test/factors.json" >"$SDIR/test/factors.md"
  else
    echo "reproduce_model.sh: $SRUN is not there; run the static chain into $OUT to fly it on this tier" >&2
  fi
  printf 'total\t%d\t%s\n' "$SECONDS" "$(date -u +%FT%TZ)" >>"$TIMES"
  exit 0
fi
[ -f "$DATA/meta/info.json" ] || step generate "$BIN/orbitdata" generate "$DATA" --episodes "$EPISODES" --image-size 64 --workers 2 --seed 0
# The flown run: preset cpu-step5 steps 5 frames per prediction, so 10 predictor calls imagine a
# 50-frame plan (rollout horizon in model steps); it holds 5 % of the training episodes out, the
# validation split its recipe was chosen on. Scored there, and on the test split at the planner's
# history of 2 latents.
world_model_steps() {
  step train-step5 train_wm "$WMS" cpu-step5
  probe_and_eval "$WMS" 10
  step "eval-val-$(basename "$WMS")" "$BIN/orbitmodel" eval rollout "$WMS" "$DATA" --horizon 10 --split val \
    --out "$WMS/eval-val" "${ROLLOUT[@]}"
  "$BIN/orbitmodel" eval probe "$WMS" "$DATA" --split val --history 2 --out "$WMS/eval-val" --no-figures "${VAL_WINDOWS[@]}"
  "$BIN/orbitmodel" eval probe "$WMS" "$DATA" --history 2 --out "$WMS/eval-history2" --no-figures "${PROBE_EVAL[@]}"
  refit "$WMS"
}
max_steps_of() {  # a run's --max-steps: under train.loop, or beside the other settings in a run from before that
  "$BIN/python" -c "import json, sys; t = json.load(open(sys.argv[1]))['preset']['train']
print(t.get('loop', t)['max_steps'])" "$1/config.json"; }
train_policy() {  # train_policy RUN PRESET [TO]: the preset's steps, then (with TO) on to TO steps; resumes a cut run.
  # With TO, RUN starts as a copy of the finished preset-length run $DP0 when there is one.
  local run=$1 preset=$2 to=${3:-} resume=()
  if [ -n "$to" ] && [ ! -e "$run" ] && [ -f "$DP0/model.safetensors" ]; then
    rm -rf "$run.copy" && cp -r "$DP0" "$run.copy" && mv "$run.copy" "$run"
  fi
  [ -d "$run/checkpoints" ] && resume=(--resume)
  if [ ! -f "$run/config.json" ] || [ "$(max_steps_of "$run")" != "$to" ]; then
    [ -f "$run/model.safetensors" ] || "$BIN/orbitmodel" train-policy "$DATA" --preset "$preset" --val-fraction 0.05 \
      --out "$run" "${resume[@]}" "${STEPS[@]}"
  fi
  [ -n "$to" ] || return 0
  [ -f "$run/model.safetensors" ] && [ "$(max_steps_of "$run")" = "$to" ] && return 0
  "$BIN/orbitmodel" train-policy "$DATA" --preset "$preset" --val-fraction 0.05 --out "$run" --resume --extend --max-steps "$to"
}
policy_steps() {  # the Diffusion Policy with the camera, its evaluation and the expert's floor
  step train-diffusion train_policy "$DP" cpu "$DP_STEPS"
  step eval-diffusion "$BIN/orbitmodel" eval policy "$DP" "$DATA" --max-windows 2000 --preset cpu
  step expert-floor "$BIN/orbitmodel" eval expert-floor "$DP" "$DATA" --max-windows 2000 --preset cpu "${FLOOR[@]}"
}
state_policy_steps() {  # the policy without the camera
  step train-diffusion-state train_policy "$DPS" cpu-state
  step eval-diffusion-state "$BIN/orbitmodel" eval policy "$DPS" "$DATA" --max-windows 2000 --preset reference
}
# With the policies, the training runs as two streams side by side, each with half the cores' torch
# threads: the world model's steps then the camera-less policy, beside the camera policy (the two
# take about as long). Trainings this size gain 1.4-1.6x from a second thread, and two of one
# thread each run side by side about as fast as alone (docs/results.md#the-chain), so the two streams
# finish sooner than the same steps one after the other on every core. Without the policies the
# world model's steps take every core.
HALF=$(($(nproc) / 2))
[ "$HALF" -ge 1 ] || HALF=1
halved() { (
  export OMP_NUM_THREADS=$HALF
  "$@"
); }  # torch's threads, in commands not given --threads
if [ "$POLICY" = 1 ]; then
  world_model_stream() {
    world_model_steps
    state_policy_steps
  }
  spawn halved world_model_stream
  spawn halved policy_steps
  join
else
  world_model_steps
fi
# The grid, two flights at a time: the learned-dynamics pair is the long one.
# learned_pair FLY / depth_pair FLY: FLY is fly_model (the planner's run) or fly_cpu (ALL=1's cpu run)
learned_pair() { spawn "$1" planner planner; spawn "$1" oracle-learned-dyn oracle-learned-dyn; join; }
depth_pair() {  # the refitted depth head, and the Stage I head it replaces
  spawn "$1" oracle-true-dyn-depth oracle-true-dyn-depth
  spawn "$1" oracle-true-dyn-depth-stage1-head oracle-true-dyn-depth --set depth_head=stage1
  join
}
rigid_pair() { spawn fly_model oracle-true oracle-true; spawn fly_model oracle-true-dyn-sensor oracle-true-dyn-sensor; join; }
data_pilots() {  # the policy (unless POLICY=0), the expert and the risky pilot
  if [ "$POLICY" = 1 ]; then spawn fly_policy; fi
  spawn fly_data expert; join; fly_data risky
}
with_policy() { if [ "$POLICY" = 1 ]; then echo "$@" diffusion; else echo "$@"; fi; }  # pilot names
with_policies() { if [ "$POLICY" = 1 ]; then echo "$@" diffusion diffusion-state; else echo "$@"; fi; }
step grid-learned learned_pair fly_model
step grid-depth depth_pair fly_model
step grid-rigid rigid_pair
step grid-data data_pilots
FIG6=()
for pilot in $(with_policy expert risky oracle-true oracle-true-dyn-sensor oracle-true-dyn-depth oracle-learned-dyn planner); do
  FIG6+=("$OUT/grid/$pilot.json")
done
step figure6 "$BIN/orbitmodel" eval figure6 "${FIG6[@]}" --out "$OUT/grid/figure6.png"
# A second grid seed: the planner, the oracles that tell its losses apart, and the references.
use_grid 2 "$OUT/grid/seed2"
seed2_rest() {
  spawn fly_model oracle-true-dyn-depth oracle-true-dyn-depth; spawn fly_model oracle-true-dyn-sensor oracle-true-dyn-sensor; join
  spawn fly_data expert; spawn fly_data risky; join
}
step grid-seed2-learned learned_pair fly_model
step grid-seed2-rest seed2_rest
# The test seeds 3, 4 and 5: flown only to report, with every choice above fixed. Each seed flies
# the planner, every oracle, the references and the policy (grid/seedN/PILOT.json); `eval pool`
# puts each pilot's three seeds in one table (grid/test/PILOT.json), which Figure 6 plots.
for seed in 3 4 5; do
  use_grid "$seed" "$OUT/grid/seed$seed"
  step "grid-seed$seed-learned" learned_pair fly_model
  step "grid-seed$seed-depth" depth_pair fly_model
  step "grid-seed$seed-rigid" rigid_pair
  step "grid-seed$seed-data" data_pilots
  if [ "$POLICY" = 1 ]; then step "grid-seed$seed-state" fly_policy_state; fi
done
mkdir -p "$OUT/grid/test"
FIG6=()
for pilot in $(with_policies expert risky oracle-true oracle-true-dyn-sensor oracle-true-dyn-depth \
                             oracle-true-dyn-depth-stage1-head oracle-learned-dyn planner); do
  "$BIN/orbitmodel" eval pool "$OUT"/grid/seed{3,4,5}/"$pilot.json" --json "$OUT/grid/test/$pilot.json"
  case "$pilot" in oracle-true-dyn-depth-stage1-head|diffusion-state) ;; *) FIG6+=("$OUT/grid/test/$pilot.json") ;; esac
done
step figure6-test "$BIN/orbitmodel" eval figure6 "${FIG6[@]}" --out "$OUT/grid/test/figure6.png"
use_grid 0 "$OUT/grid"

if [ "${ALL:-0}" = 1 ]; then
  # The per-frame predictor: the cpu preset (pooled SIGReg) and upstream's per-frame SIGReg recipe.
  step train-cpu train_wm "$WM" cpu
  step train-perframe train_wm "$WMF" cpu --no-sigreg-pool --lambda-sigreg 0.1
  for run in "$WM" "$WMF"; do  # the state-only reference first: eval probe puts it beside the probe
    [ -f "$run/probe-state/model.safetensors" ] || step "probe-state-$(basename "$run")" "$BIN/orbitmodel" probe "$run" "$DATA" \
      --state-only --batch-size 512 --lr 0.002 "${PROBE[@]}"
    probe_and_eval "$run" 50
  done
  # The cpu-run rows (docs/results.md) were flown with the 30,000-frame x 8-epoch refit and
  # without the planner's neighbour filter (--set support=0); these pin what they were.
  refit "$WM" --frames 30000 --epochs 8
  fly_cpu() { fly_run "$WM" "cpu-run/$1" "${@:2}" --set support=0; }
  step grid-cpu-learned learned_pair fly_cpu
  step grid-cpu-depth depth_pair fly_cpu
fi
printf 'total\t%d\t%s\n' "$SECONDS" "$(date -u +%FT%TZ)" >>"$TIMES"
