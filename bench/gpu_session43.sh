#!/usr/bin/env bash
# GPU runs prepared in session 42 for the next session (wheels in /tmp/site; scenes in $D: llff_fern, dtu_scan65,
# castle_p30, herz_jesus_p25). Written for one H200 or two (run_lines spreads the runs over the GPUs it finds).
#   T=seconds bash bench/gpu_session43.sh PHASE D RUNS          (ONLY=REGEX keeps the runs whose line matches)
# Session 42 (README "Session 42"): the full method grows to strategy.refine_stop_iter (full.refine_stop_fraction: 0),
# the baseline stops at half the run. Both growing: baseline castle_p30 6 / 9 views +0.26 / +1.19, herz_jesus_p25 6 / 9
# views -0.25 / -0.25, DTU -0.06, and full - baseline +0.22 dB on average; both stopping at half: the full method -0.26
# (castle 9 views -1.07), full - baseline +0.12. The pseudo views hold the growing model where the growing baseline
# over-fits (herz 6 / 9 views: full 20.21 / 22.71 against 19.83 / 22.36).
# m: both methods stopping growth at 0.75 of the run (strategy.refine_stop_fraction=0.75 for the baseline,
#    full.refine_stop_fraction=0.75 for the full method), the captures at 384x256, DTU and fern, seeds 0-2 (48 runs:
#    one call on two H200s, two on one). Against the defaults (s36/b_all.txt, s36/c.txt, s37/t.txt, s38/l.txt). m.txt.
# b: the full method's growth in its cycles, full.growth_budget 0 (no cap) and 2.0 (the default 1.0 keeps the count of
#    the first growth period), the captures at 384x256 and DTU, seed 0 (14 runs). Against s37/t.txt's seed 0. b.txt.
# p: the full method growing more where it grows (strategy.grow_grad2d=0.0003 in the full runs only; the captures'
#    config has 0.0005, session 6; DTU keeps 3D-GS's 0.0002, so there it grows less), the captures at 384x256 and DTU,
#    seed 0 (7 runs). b.txt (b_gg3_...).
# q: m, then b and p.
# c (written after q's results): CoR-GS's pair (train.co_reg=true, its defaults) on DTU in both methods, seeds 0-2, then in
#    the full method on the six captures at 384x256, seed 0 (12 runs, each two to four times a run's cost; JOBS at a time,
#    default 8; session 43 ran it with JOBS=12 in 334 s). c.txt.
# Copy the summaries to bench/results/s43/.
set -u
source "$(dirname "${BASH_SOURCE[0]}")/gpu_one.sh"
session_env "$@"; P=$1; D=$2; R=$3; shift 3
export R D T END=$(( $(date +%s) + ${T:-540} ))  # every run of the call stops by then
lines_m() {
  for s in 0 1 2; do
    cases m baseline "$s" strategy.refine_stop_fraction=0.75
    cases m full "$s" full.refine_stop_fraction=0.75
  done
}
lines_b() {
  FERN=0 cases b_gb0 full 0 full.growth_budget=0
  FERN=0 cases b_gb20 full 0 full.growth_budget=2.0
}
lines_c() {
  for s in 0 1 2; do for m in baseline full; do FERN=0 cases c_cr $m $s train.co_reg=true | grep _dtu_; done; done
  FERN=0 cases c_cr full 0 train.co_reg=true | grep -v _dtu_
}
lines_p() { FERN=0 cases b_gg3 full 0 strategy.grow_grad2d=0.0003; }
case $P in
m) lines_m | run_lines 48; summary m_ m.txt ;;
b) lines_b | run_lines 14; summary b_ b.txt ;;
p) lines_p | run_lines 7; summary b_ b.txt ;;
c) lines_c | JOBS=${JOBS:-8} run_lines 12; summary c_ c.txt ;;
q) { lines_m; lines_b; lines_p; } | run_lines 69; summary m_ m.txt; summary b_ b.txt ;;
*) echo "unknown phase $P"; exit 2 ;;
esac
