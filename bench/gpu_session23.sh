#!/usr/bin/env bash
# GPU runs of session 23 (issue 14: lego 8 views below 24.5), after the packed wheels are installed in /tmp/site and
# the scenes copied to $D.
#   T=seconds bash bench/gpu_session23.sh PHASE D RUNS
# l: lego 8 views, 400x400, 10,000 it, seeds 0-2: session 17's best baseline (DropGaussian 0.2, opacity noise 0.8, SH
#    degree 1) against the same with an L1 on the inputs' alpha (loss.alpha_weight), and the full method (never run on
#    lego before) with the blender config's settings and with the best baseline's; a summary line per run in
#    $OUT/lego.txt. (The full runs in bench/results/s23/lego.txt used the config before session 23: with its depth
#    terms and no dropout; the config now has neither.)
# v: the full method on lego with one change each (VARIANTS, SEEDS), to find what made it fall at its first cycle.
# d: the full method without its Pearson depth terms, and with the captures' stricter densification stereo, on DTU
#    scan65 and fern (3 views, 3000 it) and lego; e: without the depth terms and with DropGaussian 0.2 on DTU and fern,
#    and without the depth terms on the captures' three weak cases (384x256, 3000 it). Seeds 0-2.
#    `python bench/session23_table.py` prints the table of all of these from bench/results/s23.
set -u
source "$(dirname "${BASH_SOURCE[0]}")/gpu_one.sh"
session_env "$@"; P=$1; D=$2; R=$3; shift 3
export R D T
BEST="--set train.drop_rate=0.2 --set train.opacity_noise=0.8 --set model.sh_degree=1"
# lego NAME METHOD SEED [--set k=v ...]: sparse_run of lego, 8 views, 10,000 it, 10 evaluations
lego() {
  local name=$1 method=$2 seed=$3; shift 3
  sparse_run "$name" --method "$method" --data blender --scene lego --views 8 --iterations 10000 --seed "$seed" \
    --set train.eval_every=1000 "$@"
}
export -f lego
# other NAME DATA SCENE SEED [--set k=v ...]: the full method on a 3-view scene of DATA (llff, dtu), 3000 it
other() {
  local name=$1 data=$2 scene=$3 seed=$4; shift 4
  sparse_run "$name" --method full --data "$data" --scene "$scene" --views 3 --iterations 3000 --seed "$seed" \
    --set train.eval_every=300 "$@"
}
export -f other
NODEPTH="--set full.input_depth_weight=0 --set full.depth_weight=0"  # the full method's Pearson depth terms off
STRICT="--set densify.stereo.min_score=0.8 --set densify.stereo.min_consistent=2"  # the captures' densification stereo
case $P in
l)
  for s in 0 1 2; do
    echo "l_best_s$s baseline $s $BEST"
    echo "l_alpha_s$s baseline $s $BEST --set loss.alpha_weight=${ALPHA:-0.5}"
    echo "l_full_s$s full $s"
    echo "l_fullbest_s$s full $s $BEST --set full.drop_rate=0.2"
  done | xargs -P ${JOBS:-12} -L 1 bash -c 'lego "$@"' _ | grep -v "rc=0"
  summary l_ lego.txt
  ;;
v)
  # the full method on lego, one change each to find what makes it fall after its first cycle
  declare -A SET=(
    [nodens]="--set full.densify=false"
    [pw02]="--set full.pseudo_weight=0.2"
    [rel]="--set full.pseudo_mask=reliable"
    [budget]="--set full.growth_budget=1.0"
    [nodepth]="--set full.input_depth_weight=0 --set full.depth_weight=0"
  )
  for v in ${VARIANTS:-nodens pw02 rel budget}; do for s in ${SEEDS:-0 1 2}; do
    echo "v_${v}_s$s full $s ${SET[$v]}"
  done; done | xargs -P ${JOBS:-12} -L 1 bash -c 'lego "$@"' _ | grep -v "rc=0"
  summary v_ lego_full_variants.txt
  ;;
d)
  # the full method without its Pearson depth terms (full.input_depth_weight / depth_weight 0) and with the captures'
  # stricter densification stereo, on DTU scan65 3 views and fern 3 views (3000 it) and lego (the best baseline's
  # settings, 10,000 it); seeds 0-2
  for s in 0 1 2; do
    echo "other d_dtu_nodepth_s$s dtu scan65 $s $NODEPTH"
    echo "other d_dtu_strict_s$s dtu scan65 $s $STRICT"
    echo "other d_fern_nodepth_s$s llff fern $s $NODEPTH"
    echo "lego d_lego_fullbest_nodepth_s$s full $s $BEST --set full.drop_rate=0.2 $NODEPTH"
    echo "lego d_lego_strict_s$s full $s $STRICT"
  done | xargs -P ${JOBS:-15} -L 1 bash -c '"$@"' _ | grep -v "rc=0"
  summary d_ depth_terms.txt
  ;;
e)
  # the full method without the depth terms and with DropGaussian 0.2 (the baseline's default there) on DTU and fern,
  # and without the depth terms on the captures' three weak cases (384x256, 3000 it); d's unfinished runs resume
  for s in 0 1 2; do
    echo "lego d_lego_strict_s$s full $s $STRICT"
    echo "other e_dtu_nodepth_drop_s$s dtu scan65 $s $NODEPTH --set full.drop_rate=0.2"
    echo "other e_fern_nodepth_drop_s$s llff fern $s $NODEPTH --set full.drop_rate=0.2"
    for c in castle_p30:3 castle_p30:6 herz_jesus_p25:3; do
      echo "one e_cap_nodepth_${c%%:*}_${c##*:}v_full_s$s full ${c%%:*} ${c##*:} $s $NODEPTH"
    done
  done | xargs -P ${JOBS:-18} -L 1 bash -c '"$@"' _ | grep -v "rc=0"
  summary d_ depth_terms.txt; summary e_ depth_terms_e.txt
  ;;
esac
