#!/usr/bin/env bash
# GPU runs of session 21 (issue 13: the captures at 3 views, where training lowers the test PSNR below its value
# at step 300), after the packed wheels are installed in /tmp/site and the scenes copied to $D.
#   T=seconds bash bench/gpu_session21.sh PHASE D RUNS
# v: the baseline at 3 views (castle_p30, herz_jesus_p25; 384x256, 3000 it, seeds 0-2) under one change each of
#    the captures' default: no densification (strategy.refine_stop_iter 0), SH degree 0, a 10x smaller means
#    learning rate, DropGaussian 0.5, a 5x smaller scales learning rate, and those three geometry changes together.
#    VARIANTS picks a subset (names), JOBS runs at a time; a summary line per run in $OUT/variants.txt.
#    VIEWS (default 3) and METHODS (default baseline) widen it.
# d: the captures' default (now with train.hold_geometry stereo) at 3 views, baseline and full, seeds 0-2 (prefix d).
# e: the captures' default at 6 and 9 views (prefix d; SfM's points start those runs, so the hold does not apply and
#    they should repeat bench/results/s20/captures_d.txt to the last digit), beside the four 3-view runs at 768x512,
#    10,000 it, seed 0 (prefix a; issue 13: every images_4 run completes).
# f: model.init_fill 8 and 4 at 3 views (castle_p30, herz_jesus_p25), baseline, seeds 0-2, on the captures' default.
#    (Not run in session 21: the device time was spent; bench/results/s21/cpu/init_fill_cpu.txt has the CPU runs.)
# o: DTU scan65 and LLFF fern at 3 views (3000 it, seeds 0-2, baseline and full), their default and
#    train.hold_geometry=on (their points come from sfm+stereo): SCENES picks dtu and/or llff.
# w: the variants named by VARIANTS on all six cases, baseline and full, seeds 0-2 (is it a default?).
set -u
source "$(dirname "${BASH_SOURCE[0]}")/gpu_one.sh"
session_env "$@"; P=$1; D=$2; R=$3; shift 3
export R D T
declare -A SET=(
  [nogrow]="--set strategy.refine_stop_iter=0"
  [sh0]="--set model.sh_degree=0"
  [mlr]="--set optim.means_lr=1.6e-5 --set optim.means_lr_final=1.6e-7"
  [drop5]="--set train.drop_rate=0.5"
  [slr]="--set optim.scales_lr=1e-3"
  [geo]="--set strategy.refine_stop_iter=0 --set optim.means_lr=1.6e-5 --set optim.means_lr_final=1.6e-7 --set optim.scales_lr=1e-3"
  [nogrow_sh0]="--set strategy.refine_stop_iter=0 --set model.sh_degree=0"
  [geo_sh0]="--set strategy.refine_stop_iter=0 --set optim.means_lr=1.6e-5 --set optim.means_lr_final=1.6e-7 --set optim.scales_lr=1e-3 --set model.sh_degree=0"
  [geo_is2]="--set strategy.refine_stop_iter=0 --set optim.means_lr=1.6e-5 --set optim.means_lr_final=1.6e-7 --set optim.scales_lr=1e-3 --set model.init_scale=2.0"
  [geo_m0]="--set strategy.refine_stop_iter=0 --set optim.means_lr=1.6e-7 --set optim.means_lr_final=1.6e-8 --set optim.scales_lr=1e-3"
  [geo_grow]="--set optim.means_lr=1.6e-5 --set optim.means_lr_final=1.6e-7 --set optim.scales_lr=1e-3"
  [geo_d0]="--set strategy.refine_stop_iter=0 --set optim.means_lr=1.6e-5 --set optim.means_lr_final=1.6e-7 --set optim.scales_lr=1e-3 --set train.drop_rate=0"
  [geo_q]="--set strategy.refine_stop_iter=0 --set optim.means_lr=1.6e-5 --set optim.means_lr_final=1.6e-7 --set optim.scales_lr=1e-3 --set optim.quats_lr=1e-4"
  [ss]="--set model.init=sfm+stereo"
  [ss_geo]="--set model.init=sfm+stereo --set strategy.refine_stop_iter=0 --set optim.means_lr=1.6e-5 --set optim.means_lr_final=1.6e-7 --set optim.scales_lr=1e-3"
  [geo_rand]="--set strategy.refine_stop_iter=0 --set optim.means_lr=1.6e-5 --set optim.means_lr_final=1.6e-7 --set optim.scales_lr=1e-3 --set model.init_random=20000"
)
case $P in
d)
  for c in castle_p30 herz_jesus_p25; do for m in baseline full; do for s in 0 1 2; do
    echo "d_${c}_3v_${m}_s$s $m $c 3 $s"
  done; done; done | xargs -P ${JOBS:-12} -L 1 bash -c 'one "$@"' _ | grep -v "rc=0"
  summary d_ default3.txt
  ;;
e)
  for c in castle_p30 herz_jesus_p25; do
    for m in baseline full; do echo "a_${c}_3v_${m}_s0 $m $c 3 0"; done | DS=4 IT=10000 xargs -P 4 -L 1 bash -c 'one "$@"' _ > "$OUT/a768.log" &
  done
  for c in castle_p30 herz_jesus_p25; do for n in 6 9; do for m in baseline full; do for s in 0 1 2; do
    echo "d_${c}_${n}v_${m}_s$s $m $c $n $s"
  done; done; done; done | xargs -P ${JOBS:-12} -L 1 bash -c 'one "$@"' _ | grep -v "rc=0"
  wait
  summary d_ default69.txt > /dev/null; summary a_ a768.txt
  ;;
f)
  for f in 8 4; do for c in castle_p30 herz_jesus_p25; do for s in 0 1 2; do
    echo "f${f}_${c}_3v_baseline_s$s baseline $c 3 $s --set model.init_fill=$f"
  done; done; done | xargs -P ${JOBS:-12} -L 1 bash -c 'one "$@"' _ | grep -v "rc=0"
  summary f fill.txt
  ;;
o)
  for c in ${SCENES:-dtu llff}; do sc=scan65; [ $c = llff ] && sc=fern
    for v in default hold; do a=""; [ $v = hold ] && a="--set train.hold_geometry=on"
      for m in baseline full; do for s in 0 1 2; do
        echo "o_${c}_${v}_${m}_s$s $m $c $sc 3 $s${a:+ $a}"  # no trailing blank: xargs -L would join the next line
      done; done
    done
  done | xargs -P ${JOBS:-12} -L 1 bash -c 'named "$@"' _ | grep -v "rc=0"
  summary o_ other.txt
  ;;
v)
  for v in ${VARIANTS:-nogrow sh0 mlr drop5 slr geo}; do
    for c in castle_p30 herz_jesus_p25; do for n in ${VIEWS:-3}; do for m in ${METHODS:-baseline}; do for s in 0 1 2; do
      echo "v_${v}_${c}_${n}v_${m}_s$s $m $c $n $s ${SET[$v]}"
    done; done; done; done
  done | xargs -P ${JOBS:-12} -L 1 bash -c 'one "$@"' _ | grep -v "rc=0"
  summary v_ variants.txt
  ;;
w)
  for v in ${VARIANTS}; do
    for c in castle_p30:3 castle_p30:6 castle_p30:9 herz_jesus_p25:3 herz_jesus_p25:6 herz_jesus_p25:9; do
      for m in baseline full; do for s in 0 1 2; do
        echo "w_${v}_${c%%:*}_${c##*:}v_${m}_s$s $m ${c%%:*} ${c##*:} $s ${SET[$v]}"
      done; done
    done
  done | xargs -P ${JOBS:-12} -L 1 bash -c 'one "$@"' _ | grep -v "rc=0"
  summary w_ wide.txt
  ;;
esac
