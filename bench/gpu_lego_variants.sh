#!/usr/bin/env bash
# GPU figures for issues #4/#7 (run on the lent GPU after the packed wheels are in /tmp/site):
# Blender lego 8-view baseline variants, the same-seed determinism pair on fern, in parallel on one GPU.
#   bash bench/gpu_lego_variants.sh DATA_ROOT RUNS_DIR
set -u
export PYTHONPATH=/tmp/site:$PWD PYTHONUNBUFFERED=1
D=$1; R=$2; mkdir -p "$R"
sp() { local name=$1; shift; python3 -m warpgs.pipelines.sparse --no-progress --device cuda --out "$R/$name" "$@" \
       > "$R/$name.log" 2>&1; echo "$name rc=$?"; }
lego() { local n=$1; shift; sp "$n" --method baseline --data blender --data-root "$D" --set train.eval_every=1000 "$@"; }
SCREEN="--set strategy.refine_scale2d_stop_iter=10000 --set strategy.prune_scale2d=0.05"
sp warm --method baseline --data blender --data-root "$D" --iterations 20   # compiles the kernels once
lego l0 &
lego l0b &
lego l1 $SCREEN &
lego l2 $SCREEN --set model.init=hull &
lego l3 $SCREEN --set loss.alpha_weight=0.2 &
lego l4 $SCREEN --set model.init=hull --set loss.alpha_weight=0.2 &
lego l5 $SCREEN --set model.init=hull --set loss.alpha_weight=0.2 --set model.sh_degree=1 &
lego l6 --set model.init=hull &
sp f1 --method baseline --data llff --data-root "$D" --iterations 3000 --seed 0 &
sp f2 --method baseline --data llff --data-root "$D" --iterations 3000 --seed 0 &
wait
