#!/usr/bin/env bash
# GPU runs prepared in session 41 for the next session (wheels in /tmp/site; scenes in $D: dtu_scan65, castle_p30,
# herz_jesus_p25). Written for one H200 (the kind lent in session 41); on two, run_lines spreads the runs.
#   T=seconds bash bench/gpu_session42.sh PHASE D RUNS          (ONLY=REGEX keeps the runs whose line matches)
# Session 41's seed-0 screen of the full method's parts (s41/s.txt) found its warped guidance worth +0.12 dB on
# average over the six captures (renders for guidance: -0.12), the densification from pseudo views nothing (-0.03),
# and the Pearson depth term on the pseudo views -0.07 (without it +0.07). In session 38 the pseudo views beat the
# render at held-out frames by 0.9 dB on herz_jesus_p25 6 views, yet the full method gains 0.14 there: the
# captures weigh every pseudo pixel x 0.2, the warped inputs' as well as the render's they were filled from.
# On herz_jesus_p25 6 views 36-92% of a pseudo view's pixels are reliable (U < 0.5; the CPU run of session 41), on
# castle_p30 5-7% (session 38): at 5 herz's pseudo views weigh nearly what they did at pseudo weight 1, which lost
# 0.1-0.2 dB there in session 37. So a seed-0 screen of 5 and 2.5 first.
# t: the CUDA tests of the weighted losses (tests/test_reliable_weight.py -k cuda); about 20 s (passed in session 41).
# s: full.reliable_weight 5 and 2.5 (the warped inputs' pixels x 1 / x 0.5, the render's x 0.2), the six captures at
#    384x256 and DTU, seed 0 (14 runs), and full.depth_weight=0 at seeds 1 and 2 (14 runs; its seed 0 is s41/s.txt):
#    28 runs, one call of one H200 or a little more (session 41: about 42 runs in 890 s). w.txt, d.txt.
# w: seeds 1 and 2 of full.reliable_weight=$W (default 5.0; the better of s's two), 14 runs. w.txt.
# q: t, then s.
# x (written after s: reliable_weight lost, +0.28 / +0.30 against +0.38; depth_weight=0 over seeds 0-2 +0.38, the
#    same): the paper's schedule, full.cycle_iterations=1000: the baseline phase is the whole 3000-step baseline run and
#    the two cycles train 1000 steps more each, from the baseline's final model (with the default split the pseudo
#    views are made at step 1200, before the binocular term starts at 1500). Seeds 0-2 of the six captures and DTU
#    (x_*, 21 runs), and seed 0 of its control xc_*: the same 2000 extra steps without pseudo views, densification or
#    the inputs' depth prior (the baseline trained longer as it was). 28 runs of 5000 steps: two calls. x.txt.
# Copy the summaries to bench/results/s42/; python bench/captures_table.py --session 42 prints the tables.
set -u
source "$(dirname "${BASH_SOURCE[0]}")/gpu_one.sh"
session_env "$@"; P=$1; D=$2; R=$3; shift 3
export R D T END=$(( $(date +%s) + ${T:-540} ))  # every run of the call stops by then
lines_v() {  # lines_v PREFIX "SEEDS" SETTING [METHOD]: METHOD (default full) with SETTING, the six captures at 384x256 and DTU
  local s; for s in $2; do FERN=0 cases "$1" "${4:-full}" "$s" "$3"; done
}
rw_name() { local w=${1/./}; echo "rw${w:0:2}"; }  # 5.0 -> rw50, 2.5 -> rw25
lines_w() {  # lines_w "SEEDS" WEIGHT ...
  local seeds=$1; shift
  for w in "$@"; do lines_v "w_$(rw_name "$w")" "$seeds" full.reliable_weight=$w; done
}
lines_d() { lines_v d "1 2" full.depth_weight=0; }
screen() { { lines_w 0 5.0 2.5; lines_d; } | run_lines 28; summary w_ w.txt; summary d_ d.txt; }
lines_x() {
  lines_v x 0 full.cycle_iterations=1000
  lines_v xc 0 "full.cycle_iterations=1000 --set full.pseudo_weight=0 --set full.densify=false --set full.input_depth_weight=0"
  lines_v x "1 2" full.cycle_iterations=1000
}
# g (written after x: its control, the baseline phase and 2000 more steps without pseudo views, gave castle_p30 9 views
#    24.04 against the baseline's 22.70, seed 0, with 56,563 Gaussians against 15,716: the full method grows to
#    strategy.refine_stop_iter (full.refine_stop_fraction: 0, configs/full.yaml) where the baseline stops at half the
#    run, so its baseline phase is not the baseline): the baseline with the full method's growth schedule
#    (strategy.refine_stop_fraction=0), the six captures and DTU, seeds 0-2 (21 runs, 3000 steps). g.txt.
# h (run from the command line on two H200s after g, the same lines): the full method with the baseline's growth
#    schedule (full.refine_stop_fraction=0.5), the six captures and DTU, seeds 0-2 (21 runs). h.txt.
lines_g() { lines_v g "0 1 2" strategy.refine_stop_fraction=0 baseline; }
case $P in
t) cuda_tests tests/test_reliable_weight.py ;;
s) screen ;;
w) lines_w "1 2" "${W:-5.0}" | run_lines 14; summary w_ w.txt ;;
x) lines_x | run_lines 28; summary x x.txt ;;
g) lines_g | run_lines 21; summary g_ g.txt ;;
h) lines_v h "0 1 2" full.refine_stop_fraction=0.5 | run_lines 21; summary h_ h.txt ;;
q) cuda_tests tests/test_reliable_weight.py || { echo "the CUDA tests failed: no runs"; exit 1; }
   screen ;;
*) echo "unknown phase $P"; exit 2 ;;
esac
