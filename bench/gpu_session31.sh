#!/usr/bin/env bash
# GPU runs prepared in session 30 for the next session (issue 13), after the packed wheels are installed in /tmp/site
# and the scenes (images_4 and images_8) copied to $D.
#   T=seconds bash bench/gpu_session31.sh PHASE D RUNS
# j: images_4 (768x512), 10,000 it, seeds 1 and 2, both methods, 3/6/9 views, with the captures' default since
#    session 30 (the path-floater pass on both paths, 9 poses; prefix j) and with session 28's (the spline, 3
#    poses; prefix k). Session 30's seed 0 at this size (bench/results/s30/i369.txt against s28/i369.txt) gave the
#    new default -0.26 dB on average for the baseline and -0.06 for the full method, where the three seeds at
#    384x256 gave +0.24 / +0.08: these 48 runs say which holds at 768x512. 12 at a time (24 ran a GPU out of memory
#    in session 30); runs stopped on out of memory or by the call's end are resumed by the next call.
#    Copy $OUT/j369.txt and k369.txt to bench/results/s31/, then: python bench/captures_table.py --session 31
# o: the other scenes' current figures over three seeds (issue 14's "every PSNR a median over 3 seeds, with the code
#    of today"): fern 3 views and DTU scan65 3 views (3000 it) and lego 8 views (10,000 it), baseline and full with
#    their configs' defaults, seeds 0-2; and lego with session 17's best baseline setting (DropGaussian 0.2, opacity
#    noise 0.8, SH degree 1) at 10,000 and at 20,000 iterations (its test curve still rose at 10,000). Needs lego and
#    DTU in $D too (blender_lego, dtu_scan65 beside llff_fern). Summary lines in $OUT/o.txt:
#    python bench/seed_medians.py bench/results/s31/o.txt prints their medians over the seeds.
set -u
source "$(dirname "${BASH_SOURCE[0]}")/gpu_one.sh"
session_env "$@"; P=$1; D=$2; R=$3; shift 3
export R D T END=$(( $(date +%s) + ${T:-540} ))  # every run of the call stops by then
case $P in
j)
  { for s in 1 2; do for c in castle_p30 herz_jesus_p25; do for v in 3 6 9; do for m in baseline full; do
      echo "j_${c}_${v}v_${m}_s$s $m $c $v $s"
      echo "k_${c}_${v}v_${m}_s$s $m $c $v $s --set train.path_floaters_paths=spline --set train.path_floaters_poses=3"
    done; done; done; done; } | DS=4 IT=10000 xargs -P ${JOBS:-12} -L 1 bash -c 'one "$@"' _ | grep -v "rc=0"
  summary j_ j369.txt
  summary k_ k369.txt
  ;;
o)
  { for s in 0 1 2; do
      echo "lego o_lego_best20k_s$s baseline $s 20000 $LEGO_BEST"
      for m in baseline full; do echo "lego o_lego_${m}_s$s $m $s 10000"; done
      echo "lego o_lego_best_s$s baseline $s 10000 $LEGO_BEST"
    done
    for s in 0 1 2; do for m in baseline full; do
      echo "named o_fern_${m}_s$s $m llff fern 3 $s"
      echo "named o_dtu_${m}_s$s $m dtu scan65 3 $s"
    done; done; } | xargs -P ${JOBS:-12} -L 1 bash -c '"$@"' _ | grep -v "rc=0"
  summary o_ o.txt
  ;;
*) echo "unknown phase $P"; exit 2 ;;
esac
