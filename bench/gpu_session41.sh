#!/usr/bin/env bash
# GPU runs prepared in session 40 for the next session (wheels in /tmp/site; scenes in $D: llff_fern, dtu_scan65,
# blender_lego, castle_p30, herz_jesus_p25 with images_4).
#   T=seconds bash bench/gpu_session41.sh PHASE D RUNS          (ONLY=REGEX keeps the runs whose line matches)
# Session 40 added full.path_consistency (warpgs/pipelines/full.py): at each pseudo view trained on, the photos of the
# two inputs it lies between, warped into it with its rendered depth (pose_warp), should agree. Unlike the pseudo view's
# image, made once per cycle from the depth of that moment, the term reaches the depth every step. The baseline has no
# pseudo views; its runs are the defaults' (s36/b_all.txt, s36/c.txt, s36/g.txt).
# t: the CUDA tests of pose_warp (the term's warp) and of the term; about 30 s.
# c: the full method with full.path_consistency 1.0 and 0.3, the captures at 384x256, DTU and fern, seeds 0-2 (48 runs,
#    one call on two H200s). Against s37/t.txt (captures, DTU) and s38/l.txt (fern). c.txt.
# b: the baseline with train.path_consistency 1.0 and 0.3 (the same term at a path pose drawn each step, one more
#    render; warpgs/pathconsistency.py), the same cases (48 runs): whether a gain of c is the pseudo views' or the
#    term's alone. b.txt.
# i: the full method with full.path_consistency=1.0 at images_4 (768x512, 10,000 it), the six cases, seeds 0-2 (18 runs;
#    about two calls). Against s38/i.txt. i.txt.
# q: t, then c, b and i in one queue (about three calls on two H200s).
# s (added in session 41, after c: one H200 only): a seed-0 screen of the full method's parts on the six captures and DTU
#    (21 runs, one call): full.densify=false (no points from the pseudo views), full.depth_weight=0 (no Pearson depth
#    term on the pseudo views), full.guidance=render (the pseudo views are the model's own renders: no warped inputs).
#    Against s37/t.txt's seed 0. s.txt.
# Copy the summaries to bench/results/s41/; python bench/captures_table.py --session 41 prints the tables.
set -u
source "$(dirname "${BASH_SOURCE[0]}")/gpu_one.sh"
session_env "$@"; P=$1; D=$2; R=$3; shift 3
export R D T END=$(( $(date +%s) + ${T:-540} ))  # every run of the call stops by then
lines_w() {  # lines_w PREFIX METHOD KEY: METHOD with KEY=1.0 and 0.3, the captures at 384x256, DTU and fern, seeds 0-2
  local pre=$1 m=$2 key=$3
  for s in 0 1 2; do for w in 1.0 0.3; do
    local p="${pre}_pc${w/./}"
    echo "named ${p}_dtu_${m}_s$s $m dtu scan65 3 $s --set $key=$w"
    echo "named ${p}_fern_${m}_s$s $m llff fern 3 $s --set $key=$w"
    for c in castle_p30 herz_jesus_p25; do for v in 3 6 9; do
      echo "one ${p}_${c}_${v}v_${m}_s$s $m $c $v $s --set $key=$w"
    done; done
  done; done
}
lines_c() { lines_w c full full.path_consistency; }
lines_b() { lines_w b baseline train.path_consistency; }
lines_i() {
  for s in 0 1 2; do for c in castle_p30 herz_jesus_p25; do for v in 3 6 9; do
    echo "one4 i_${c}_${v}v_full_s$s full $c $v $s --set full.path_consistency=1.0"
  done; done; done
}
lines_s() {
  for v in densify=false depth_weight=0 guidance=render; do FERN=0 cases "s_${v%%=*}" full 0 "full.$v"; done
}
case $P in
t) cuda_tests tests/test_binocular.py tests/test_path_consistency.py ;;
c) lines_c | run_lines 48; summary c_ c.txt ;;
b) lines_b | run_lines 48; summary b_ b.txt ;;
i) lines_i | run_lines 18; summary i_ i.txt ;;
q) cuda_tests tests/test_binocular.py tests/test_path_consistency.py || { echo "the CUDA tests failed: no runs"; exit 1; }
   { lines_c; lines_b; lines_i; } | run_lines 48; summary c_ c.txt; summary b_ b.txt; summary i_ i.txt ;;
s) lines_s | run_lines 21; summary s_ s.txt ;;
*) echo "unknown phase $P"; exit 2 ;;
esac
