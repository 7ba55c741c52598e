#!/usr/bin/env bash
# GPU runs of session 3 (issues #4, #7, #8), on the lent GPU after the packed wheels are in /tmp/site:
#   bash bench/gpu_session3.sh lego DATA_ROOT RUNS      lego 8-view baseline settings (hull init, densification stop)
#   bash bench/gpu_session3.sh seeds RUNS               synthetic: baseline vs full (9 / 13 frames), seeds 0-2
# Runs go in parallel on the one GPU; each writes RUNS/<name>/metrics.json (gather: bench/gather_runs.py).
set -u
export PYTHONPATH=/tmp/site:$PWD PYTHONUNBUFFERED=1
sp() { local name=$1; shift; python3 -m warpgs.pipelines.sparse --no-progress --device cuda --out "$R/$name" "$@" \
       > "$R/$name.log" 2>&1; echo "$name rc=$?"; }
case $1 in
lego)
  D=$2; R=$3; mkdir -p "$R"
  L="--method baseline --data blender --data-root $D --set train.eval_every=1000 --set model.init=hull"
  sp l9 $L --set strategy.refine_stop_iter=6500 &
  sp l10 $L --set strategy.refine_stop_iter=6500 --set model.sh_degree=1 &
  sp l11 $L --set strategy.refine_stop_iter=4500 &
  sp l12 $L --set strategy.refine_stop_iter=6500 --seed 1 &
  ;;
seeds)
  R=$2; mkdir -p "$R"
  for s in 0 1 2; do
    sp "b$s" --method baseline --seed $s &
    sp "f9_$s" --method full --seed $s &
    sp "f13_$s" --method full --seed $s --set full.n_frames=13 &
  done
  ;;
esac
wait
