#!/usr/bin/env bash
# GPU runs of session 44 (wheels in /tmp/site; scenes in $D: llff_fern, dtu_scan65, castle_p30, herz_jesus_p25,
# blender_lego). One H200.
#   T=seconds bash bench/gpu_session44.sh PHASE D RUNS          (ONLY=REGEX keeps the runs whose line matches)
# Issue 14's DTU point (full >= baseline + 1 dB; today 26.62 against 26.37). DTU's 25 test cameras sit in the rows of
# its camera grid above and below the row of its three inputs (0.38 of an input spacing from the nearest pose of the
# pseudo views' path at the median, 0.92 at most); neither the path nor the binocular term's sideways partner goes
# there. Two new switches, measured on DTU at seeds 0-2, 3000 it:
# a: - the full method's pseudo views also on copies of the path moved up and down (pseudo.trajectory.offsets, each
#      frame turned to keep its look-at point; warpgs/pseudo/trajectory.py offset_trajectories): +-0.5 (median distance
#      0.18, max 0.52) and +-0.5, +-1.0;
#    - the binocular term's partner moved in a direction of the image plane drawn each step (train.binocular_axes=xy),
#      in both methods;
#    - both together in the full method.
#    (15 runs.) a.txt.
# c: (after a: every variant of a within 0.1 dB of the default or below it) the moved copies' pseudo views weighing
#    more: +-0.5 with full.reliable_weight=5 (their warped pixels weigh 1, the paper's weight) and with
#    full.pseudo_weight=0.5 (6 runs). c.txt.
# b: (after a) the switch(es) a keeps, on the other scenes: FULLSET / BOTHSET (--set values; empty: none) on the
#    captures at 384x256 and fern, seeds 0-2. b.txt.
# Copy the summaries to bench/results/s44/.
set -u
source "$(dirname "${BASH_SOURCE[0]}")/gpu_one.sh"
session_env "$@"; P=$1; D=$2; R=$3; shift 3
export R D T END=$(( $(date +%s) + ${T:-540} ))  # every run of the call stops by then
OFF5="pseudo.trajectory.offsets=[-0.5,0.5]"
OFF10="pseudo.trajectory.offsets=[-1.0,-0.5,0.5,1.0]"
lines_a() {
  for s in 0 1 2; do
    echo "named a_off5_dtu_full_s$s full dtu scan65 3 $s --set $OFF5"
    echo "named a_off10_dtu_full_s$s full dtu scan65 3 $s --set $OFF10"
    echo "named a_bxy_dtu_baseline_s$s baseline dtu scan65 3 $s --set train.binocular_axes=xy"
    echo "named a_bxy_dtu_full_s$s full dtu scan65 3 $s --set train.binocular_axes=xy"
    echo "named a_both_dtu_full_s$s full dtu scan65 3 $s --set $OFF5 --set train.binocular_axes=xy"
  done
}
lines_c() {
  for s in 0 1 2; do
    echo "named c_off5rw5_dtu_full_s$s full dtu scan65 3 $s --set $OFF5 --set full.reliable_weight=5"
    echo "named c_off5pw5_dtu_full_s$s full dtu scan65 3 $s --set $OFF5 --set full.pseudo_weight=0.5"
  done
}
lines_b() {
  for s in 0 1 2; do
    [ -n "${FULLSET:-}" ] && cases b_f full "$s" "$FULLSET" | grep -v _dtu_
    [ -n "${BOTHSET:-}" ] && for m in baseline full; do cases b_x $m "$s" "$BOTHSET" | grep -v _dtu_; done
  done
}
case $P in
a) lines_a | run_lines 15; summary a_ a.txt ;;
c) lines_c | run_lines 6; summary c_ c.txt ;;
b) lines_b | run_lines 48; summary b_ b.txt ;;
*) echo "unknown phase $P"; exit 2 ;;
esac
