#!/usr/bin/env bash
# Sourced by the GPU session scripts (bench/gpu_session14.sh, gpu_session15.sh): one capture run.
#   one NAME METHOD SCENE VIEWS SEED [--set k=v ...]
# Runs python -m warpgs.pipelines.sparse on the DL3DV-layout scene SCENE under $D into $R/NAME (log: $R/NAME.log),
# at --downscale ${DS:-8} for ${IT:-3000} iterations, 10 evaluations; skipped when NAME has its metrics, resumed
# when it has started (a run stopped before its first checkpoint resumes from the start); stopped at the
# deadline $END (epoch seconds), or after ${T:-540} s without one.
one() {
  local name=$1 method=$2 scene=$3 views=$4 seed=$5; shift 5
  [ -f "$R/$name/metrics.json" ] && return 0
  local resume=(); [ -f "$R/$name/config.yaml" ] && resume=(--resume)
  local t=${T:-540}; [ -n "${END:-}" ] && t=$((END - $(date +%s)))
  [ "$t" -lt 20 ] && { echo "$name: no time left in this call"; return 0; }
  timeout -s INT "$t" python3 -m warpgs.pipelines.sparse --method "$method" --data dl3dv --scene "$scene" \
    --views "$views" --downscale "${DS:-8}" --iterations "${IT:-3000}" --device cuda --no-progress --seed "$seed" \
    --data-root "$D" --set train.eval_every=$(( ${IT:-3000} / 10 )) --out "$R/$name" "${resume[@]}" "$@" >> "$R/$name.log" 2>&1
  echo "$name rc=$? $(grep -h 'test: PSNR' "$R/$name.log" | tail -1)"
}
export -f one
