#!/usr/bin/env bash
# GPU runs of session 26 (issue 13), after the packed wheels are installed in /tmp/site and the scenes copied to $D.
#   T=seconds bash bench/gpu_session26.sh PHASE D RUNS
# a: the captures at 3 views (castle_p30, herz_jesus_p25; 384x256, 3000 it, seeds 0-2), baseline and full, with the
#    initial sweep reaching the far end of the resolvable range when SfM finds fewer than geometry.min_points
#    (prefix a), and the full method with full.pseudo_mask=reliable (prefix r).
# b: DTU scan65 at 3 views (3000 it, seeds 0-2, baseline and full; its SfM finds 57 points, so its sweep changes too;
#    prefix b), and the captures at 6 and 9 views, full with full.pseudo_mask=reliable (prefix r).
# c: the captures at 6 and 9 views with the default config (baseline and full, seeds 0-2; prefix c), and castle_p30
#    3 views seed 0 again with geometry.extend_far the capture config's option (prefix c; it must equal a's).
set -u
source "$(dirname "${BASH_SOURCE[0]}")/gpu_one.sh"
session_env "$@"; P=$1; D=$2; R=$3; shift 3
export R D T
case $P in
a)
  { for c in castle_p30 herz_jesus_p25; do for s in 0 1 2; do
      for m in baseline full; do echo "a_${c}_3v_${m}_s$s $m $c 3 $s"; done
      echo "r_${c}_3v_full_s$s full $c 3 $s --set full.pseudo_mask=reliable"
    done; done; } | xargs -P ${JOBS:-18} -L 1 bash -c 'one "$@"' _ | grep -v "rc=0"
  summary a_ a3.txt; summary r_ r3.txt
  ;;
b)
  { for m in baseline full; do for s in 0 1 2; do echo "named b_dtu_${m}_s$s $m dtu scan65 3 $s"; done; done
    for c in castle_p30 herz_jesus_p25; do for v in 6 9; do for s in 0 1 2; do
      echo "one r_${c}_${v}v_full_s$s full $c $v $s --set full.pseudo_mask=reliable"
    done; done; done; } | xargs -P ${JOBS:-18} -L 1 bash -c '"$@"' _ | grep -v "rc=0"
  summary b_ dtu3.txt; summary r_ r69.txt
  ;;
c)
  { for c in castle_p30 herz_jesus_p25; do for v in 6 9; do for m in baseline full; do for s in 0 1 2; do
      echo "c_${c}_${v}v_${m}_s$s $m $c $v $s"
    done; done; done; done
    for m in baseline full; do echo "c_castle_p30_3v_${m}_s0 $m castle_p30 3 0"; done; } \
    | xargs -P ${JOBS:-26} -L 1 bash -c 'one "$@"' _ | grep -v "rc=0"
  summary c_ c69.txt
  ;;
*) echo "unknown phase $P"; exit 2 ;;
esac
