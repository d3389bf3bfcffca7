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
set -euo pipefail
OUT=${OUT:-outputs/baselines}
BACKEND=${BACKEND:-pymunk}
N=${N:-500}
EXTRA=${EXTRA:-}
VELOCITY=${VELOCITY:-velocity}
FOOTSTEP=${FOOTSTEP:-footstep}
NOISES=${NOISES:-none localization}
mkdir -p "$OUT"
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
      footsim-eval controller=$preset backend=$BACKEND noise=$noise scenes="$OUT/scenes_$set.json" \
        hydra.run.dir="$dir" $EXTRA
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
    footsim-eval run="$run" backend=$BACKEND noise=$noise scenes="$OUT/scenes_$set.json" hydra.run.dir="$dir"
  done
done
python -m footsim.planners.report "$OUT" backend=$BACKEND paths=${PATHS:-4} ${POLICY_OBSTACLES:+policy_run=$POLICY_OBSTACLES}
