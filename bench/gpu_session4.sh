#!/usr/bin/env bash
# GPU runs of session 4 (issues #4, #7), on the lent GPU after the packed wheels are in /tmp/site:
#   bash bench/gpu_session4.sh a DATA_ROOT RUNS   lego 8-view variants (growth threshold, init count, importance
#                                                 pruning as a default), DTU curve, synthetic seeds 0-2
#                                                 (baseline / full / full without densification, 21 test views)
# Runs go in parallel on the one GPU; each writes RUNS/<name>/metrics.json (gather: bench/gather_runs.py).
set -u
export PYTHONPATH=/tmp/site:$PWD PYTHONUNBUFFERED=1
sp() { local name=$1; shift; python3 -m warpgs.pipelines.sparse --no-progress --device cuda --out "$R/$name" "$@" \
       > "$R/$name.log" 2>&1; echo "$name rc=$?"; }
case $1 in
a)
  D=$2; R=$3; mkdir -p "$R"
  sp warm --method full --iterations 40 --set train.checkpoint_every=0   # compiles the kernels once
  L="--method baseline --data blender --data-root $D --set train.eval_every=1000"
  P="--set compact.enabled=true --set compact.ratios=[] --set compact.sh_search=false"
  sp la $L --set strategy.grow_grad2d=0.0005 &
  sp lb $L --set model.init_num=30000 &
  sp lc $L $P --set compact.prune_at=[0.5] --set compact.prune_ratio=0.5 &
  sp ld $L $P --set compact.prune_at=[0.3,0.6] --set compact.prune_ratio=0.3 &
  sp d1 --method baseline --data dtu --data-root $D --iterations 3000 --set train.eval_every=250 &
  sp d2 --method baseline --data dtu --data-root $D --iterations 1200 &
  for s in 0 1 2; do
    sp "b$s" --method baseline --seed $s &
    sp "f$s" --method full --seed $s &
    sp "n$s" --method full --seed $s --ablation no_densify &
  done
  ;;
b)
  D=$2; R=$3; mkdir -p "$R"
  L="--method baseline --data blender --data-root $D --set train.eval_every=1000"
  sp lb1 $L --set model.init_num=30000 --seed 1 &
  sp lb2 $L --set model.init_num=30000 --seed 2 &
  sp le $L --set model.init_num=15000 &
  sp lf $L --set model.init_num=50000 &
  sp d3 --method baseline --data dtu --data-root $D --iterations 300 &
  sp d4 --method baseline --data dtu --data-root $D --iterations 300 --set model.sh_degree=0 &
  for s in 0 1 2; do
    sp "m$s" --method full --seed $s --set full.max_new=1000 &
    sp "o$s" --method full --seed $s --set full.init_opacity=0.01 &
  done
  sp n3 --method full --seed 3 --ablation no_densify &
  sp b3 --method baseline --seed 3 &
  ;;
c)
  D=$2; R=$3; mkdir -p "$R"
  L="--method baseline --data blender --data-root $D --set train.eval_every=1000"
  sp warm --method full --iterations 40 --set train.checkpoint_every=0
  sp le1 $L --set model.init_num=15000 --seed 1 &
  sp le2 $L --set model.init_num=15000 --seed 2 &
  sp lg $L --set model.init_num=20000 &
  sp fern --method compare --data llff --data-root $D --iterations 3000 &
  for s in 0 1 2 3; do sp "i$s" --method full --seed $s & done
  [ -d old6dc ] && (cd old6dc && PYTHONPATH=/tmp/site:$PWD sp dtu_old --method baseline --data dtu --data-root $D --iterations 1200) &
  ;;
d)
  D=$2; R=$3; mkdir -p "$R"
  sp warm --method full --iterations 40 --set train.checkpoint_every=0
  sp lego --method baseline --data blender --data-root $D --set train.eval_every=1000 &
  sp lego_compact --method baseline --data blender --data-root $D --compact &
  sp dtu --method compare --data dtu --data-root $D --iterations 3000 &
  sp synth --method compare &
  ;;
esac
wait
