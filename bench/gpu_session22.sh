#!/usr/bin/env bash
# GPU runs of session 22 (issue 13: the full method on the captures, where it adds little at castle_p30 3 / 6 views and
# herz_jesus_p25 3 views), after the packed wheels are installed in /tmp/site and the scenes copied to $D.
#   T=seconds bash bench/gpu_session22.sh PHASE D RUNS
# x: the variants named by VARIANTS (default: all of SET's full-method ones) on the three weak cases (castle_p30 3 and
#    6 views, herz_jesus_p25 3 views; 384x256, 3000 it, seeds 0-2), full method; the variants in BOTH also run the
#    baseline. A summary line per run in $OUT/weak.txt; the default's runs are in bench/results/s21.
# s: at 768x512 (images_4, 10,000 it, seed 0) at 3 views, the start from plane-sweep stereo alone (model.init=stereo, so
#    train.hold_geometry stereo holds it) against session 21's start from SfM's 120 / 373 points, baseline and full
#    (in $OUT/a768_stereo.txt), beside bench/gpu_session21.sh f (model.init_fill 8 and 4 at 384x256; $OUT/fill.txt).
# m: at 768x512 (10,000 it) at 3 views, the captures' new geometry.sfm_min_views 4 (stereo, held, its sweep bounded by
#    SfM's points), baseline and full, seeds 0-2, and the start from SfM's points (geometry.sfm_min_views=0, session
#    21's default) for seeds 1 and 2 (seed 0: bench/results/s21/a768_10k_3v.txt); $OUT/a768_views.txt.
# w: the variants named by VARIANTS on all six cases, baseline and full (METHODS narrows), seeds 0-2 (is it a default?),
#    in $OUT/wide.txt. combo: the three full-method changes of x that helped castle_p30 together.
set -u
source "$(dirname "${BASH_SOURCE[0]}")/gpu_one.sh"
session_env "$@"; P=$1; D=$2; R=$3; shift 3
export R D T
declare -A SET=(
  [pw02]="--set full.pseudo_weight=0.2"
  [pw05]="--set full.pseudo_weight=0.5"
  [rel]="--set full.pseudo_mask=reliable"
  [nodens]="--set full.densify=false"
  [bf06]="--set full.baseline_fraction=0.6"
  [cyc1]="--set full.cycles=1"
  [ffauto]="--set train.far_field_blur=auto"
  [combo]="--set full.pseudo_weight=0.2 --set full.pseudo_mask=reliable --set full.baseline_fraction=0.6"
  [default]=""
)
BOTH=" ffauto default "
case $P in
x)
  for v in ${VARIANTS:-pw02 pw05 rel nodens bf06 cyc1 ffauto}; do
    ms=full; [[ $BOTH == *" $v "* ]] && ms="baseline full"
    for c in castle_p30:3 castle_p30:6 herz_jesus_p25:3; do for m in $ms; do for s in 0 1 2; do
      echo "x_${v}_${c%%:*}_${c##*:}v_${m}_s$s $m ${c%%:*} ${c##*:} $s${SET[$v]:+ ${SET[$v]}}"
    done; done; done
  done | xargs -P ${JOBS:-12} -L 1 bash -c 'one "$@"' _ | grep -v "rc=0"
  summary x_ weak.txt
  ;;
s)
  for c in castle_p30 herz_jesus_p25; do for m in baseline full; do
    echo "s_${c}_3v_${m}_s0 $m $c 3 0 --set model.init=stereo"
  done; done | DS=4 IT=10000 xargs -P 4 -L 1 bash -c 'one "$@"' _ > "$OUT/a768_stereo.log" &
  JOBS=8 bash "$(dirname "${BASH_SOURCE[0]}")/gpu_session21.sh" f "$D" "$R"
  wait
  summary s_ a768_stereo.txt
  ;;
m)
  for c in castle_p30 herz_jesus_p25; do for m in baseline full; do
    for s in 0 1 2; do echo "m_${c}_3v_${m}_s$s $m $c 3 $s"; done
    for s in 1 2; do echo "n_${c}_3v_${m}_s$s $m $c 3 $s --set geometry.sfm_min_views=0"; done
  done; done | DS=4 IT=10000 xargs -P ${JOBS:-8} -L 1 bash -c 'one "$@"' _ | grep -v "rc=0"
  summary m_ a768_views.txt; summary n_ a768_sfm.txt
  ;;
w)
  for v in ${VARIANTS}; do
    for c in castle_p30:3 castle_p30:6 castle_p30:9 herz_jesus_p25:3 herz_jesus_p25:6 herz_jesus_p25:9; do
      for m in ${METHODS:-baseline full}; do for s in 0 1 2; do
        echo "w_${v}_${c%%:*}_${c##*:}v_${m}_s$s $m ${c%%:*} ${c##*:} $s${SET[$v]:+ ${SET[$v]}}"
      done; done
    done
  done | xargs -P ${JOBS:-12} -L 1 bash -c 'one "$@"' _ | grep -v "rc=0"
  summary w_ wide.txt
  ;;
esac
