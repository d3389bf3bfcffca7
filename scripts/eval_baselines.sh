#!/usr/bin/env bash
# Evaluate the baselines (and optionally trained policies) on the 500-scene sets, obstacle-free and
# with obstacles, noise off and on, then write tables and plots (footsim.planners.report).
#
#   scripts/eval_baselines.sh [OUT=outputs/baselines] [BACKEND=pymunk] [N=500]
#   POLICY_FREE=RUN_DIR POLICY_OBSTACLES=RUN_DIR scripts/eval_baselines.sh   # add the policies' rows
#
# Scene files: seed 20220101 (obstacle-free) and 20220102 (obstacles); the same files serve every
# backend and controller.  Extra footsim-eval overrides go in EXTRA (e.g. EXTRA="controller.time_budget_s=0.1").
# VELOCITY picks the velocity baseline's preset (e.g. VELOCITY=velocity_mujoco, tuned for the 3D walk);
# FOOTSTEP likewise picks the footstep planner's preset (e.g. FOOTSTEP=footstep_mujoco).
# NOISES limits the noise settings (e.g. NOISES=none).
# SHARDS=K runs every evaluation as K scene shards in parallel on this machine (footsim-eval shard=,
# joblib launcher), merged into the same summary.json / episodes.csv (docs/SWEEPS.md).
set -euo pipefail
OUT=${OUT:-outputs/baselines}
BACKEND=${BACKEND:-pymunk}
N=${N:-500}
EXTRA=${EXTRA:-}
VELOCITY=${VELOCITY:-velocity}
FOOTSTEP=${FOOTSTEP:-footstep}
NOISES=${NOISES:-none localization}
SHARDS=${SHARDS:-1}
mkdir -p "$OUT"
evaluate() {  # evaluate DIR FOOTSIM-EVAL-ARGS...: results in DIR
  local dir=$1
  shift
  if [ "$SHARDS" -gt 1 ]; then
    footsim-eval -m "$@" shard="$(seq -s, -f "%g/$SHARDS" 0 $((SHARDS - 1)))" \
      hydra/launcher=joblib hydra.launcher.n_jobs="$SHARDS" hydra.sweep.dir="$dir"
  else
    footsim-eval "$@" hydra.run.dir="$dir"
  fi
}
[ -f "$OUT/scenes_free.json" ] || footsim-scenes out="$OUT/scenes_free.json" n="$N" seed=20220101 obstacles=false
[ -f "$OUT/scenes_obstacles.json" ] || footsim-scenes out="$OUT/scenes_obstacles.json" n="$N" seed=20220102 obstacles=true
for controller in velocity footstep; do
  preset=$controller
  [ "$controller" = velocity ] && preset=$VELOCITY
  [ "$controller" = footstep ] && preset=$FOOTSTEP
  for set in free obstacles; do
    for noise in $NOISES; do
      dir="$OUT/$BACKEND/$controller/$set/$noise"
      [ -f "$dir/summary.json" ] && continue
      evaluate "$dir" controller=$preset backend=$BACKEND noise=$noise scenes="$OUT/scenes_$set.json" $EXTRA
    done
  done
done
for set in free obstacles; do
  var=POLICY_$(echo $set | tr a-z A-Z)
  run=${!var:-}
  [ -n "$run" ] || continue
  for noise in $NOISES; do
    dir="$OUT/$BACKEND/policy/$set/$noise"
    [ -f "$dir/summary.json" ] && continue
    evaluate "$dir" run="$run" backend=$BACKEND noise=$noise scenes="$OUT/scenes_$set.json"
  done
done
python -m footsim.planners.report "$OUT" backend=$BACKEND paths=${PATHS:-4} ${POLICY_OBSTACLES:+policy_run=$POLICY_OBSTACLES}
