#!/usr/bin/env bash
# GPU runs prepared in session 41 for the next session (wheels in /tmp/site; scenes in $D: dtu_scan65, castle_p30,
# herz_jesus_p25). Written for one H200 (the kind lent in session 41); on two, run_lines spreads the runs.
#   T=seconds bash bench/gpu_session42.sh PHASE D RUNS          (ONLY=REGEX keeps the runs whose line matches)
# Session 41's seed-0 screen of the full method's parts (s41/s.txt) found its warped guidance worth +0.12 dB on
# average over the six captures (renders for guidance: -0.12), the densification from pseudo views nothing (-0.03),
# and the Pearson depth term on the pseudo views -0.07 (without it +0.07). In session 38 the pseudo views beat the
# render at held-out frames by 0.9 dB on herz_jesus_p25 6 views, yet the full method gains 0.14 there: the
# captures weigh every pseudo pixel x 0.2, the warped inputs' as well as the render's they were filled from.
# t: the CUDA tests of the weighted losses (tests/test_reliable_weight.py -k cuda); about 20 s.
# w: full.reliable_weight=5 (the warped inputs' pixels x 1, the paper's weight; the render's x 0.2), the six captures
#    at 384x256 and DTU, seeds 0-2 (21 runs, one call of one H200). Against s37/t.txt. w.txt.
# d: full.depth_weight=0, seeds 1 and 2 of the same (14 runs; seed 0 is s41/s.txt). d.txt.
# q: t, then w and d in one queue (35 runs, about two calls of one H200).
# Copy the summaries to bench/results/s42/; python bench/captures_table.py --session 42 prints the tables.
set -u
source "$(dirname "${BASH_SOURCE[0]}")/gpu_one.sh"
session_env "$@"; P=$1; D=$2; R=$3; shift 3
export R D T END=$(( $(date +%s) + ${T:-540} ))  # every run of the call stops by then
lines_v() {  # lines_v PREFIX "SEEDS" SETTING: the full method with SETTING, the six captures at 384x256 and DTU
  local pre=$1 seeds=$2 set=$3
  for s in $seeds; do
    echo "named ${pre}_dtu_full_s$s full dtu scan65 3 $s --set $set"
    for c in castle_p30 herz_jesus_p25; do for v in 3 6 9; do
      echo "one ${pre}_${c}_${v}v_full_s$s full $c $v $s --set $set"
    done; done
  done
}
lines_w() { lines_v w "0 1 2" full.reliable_weight=5.0; }
lines_d() { lines_v d "1 2" full.depth_weight=0; }
case $P in
t) cuda_tests tests/test_reliable_weight.py ;;
w) lines_w | run_lines 21; summary w_ w.txt ;;
d) lines_d | run_lines 14; summary d_ d.txt ;;
q) cuda_tests tests/test_reliable_weight.py || { echo "the CUDA tests failed: no runs"; exit 1; }
   { lines_w; lines_d; } | run_lines 35; summary w_ w.txt; summary d_ d.txt ;;
*) echo "unknown phase $P"; exit 2 ;;
esac
