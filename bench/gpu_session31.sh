#!/usr/bin/env bash
# GPU runs prepared in session 30 for the next session (issue 13), after the packed wheels are installed in /tmp/site
# and the scenes (images_4 and images_8) copied to $D.
#   T=seconds bash bench/gpu_session31.sh PHASE D RUNS
# j: images_4 (768x512), 10,000 it, seeds 1 and 2, both methods, 3/6/9 views, with the captures' default since
#    session 30 (the path-floater pass on both paths, 9 poses; prefix j) and with session 28's (the spline, 3
#    poses; prefix k). Session 30's seed 0 at this size (bench/results/s30/i369.txt against s28/i369.txt) gave the
#    new default -0.26 dB on average for the baseline and -0.06 for the full method, where the three seeds at
#    384x256 gave +0.24 / +0.08: these 24 runs say which holds at 768x512. 12 at a time (24 ran a GPU out of memory
#    in session 30); runs stopped on out of memory or by the call's end are resumed by the next call.
#    Copy $OUT/j369.txt and k369.txt to bench/results/s31/, then: python bench/captures_table.py --session 31
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
*) echo "unknown phase $P"; exit 2 ;;
esac
