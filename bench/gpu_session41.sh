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
# i: the full method with full.path_consistency=1.0 at images_4 (768x512, 10,000 it), the six cases, seeds 0-2 (18 runs;
#    about two calls). Against s38/i.txt. i.txt.
# q: t, then c and i in one queue.
# Copy the summaries to bench/results/s41/; python bench/captures_table.py --session 41 prints the tables.
set -u
source "$(dirname "${BASH_SOURCE[0]}")/gpu_one.sh"
session_env "$@"; P=$1; D=$2; R=$3; shift 3
export R D T END=$(( $(date +%s) + ${T:-540} ))  # every run of the call stops by then
lines_c() {
  for s in 0 1 2; do for w in 1.0 0.3; do
    local p="c_pc${w/./}"
    echo "named ${p}_dtu_full_s$s full dtu scan65 3 $s --set full.path_consistency=$w"
    echo "named ${p}_fern_full_s$s full llff fern 3 $s --set full.path_consistency=$w"
    for c in castle_p30 herz_jesus_p25; do for v in 3 6 9; do
      echo "one ${p}_${c}_${v}v_full_s$s full $c $v $s --set full.path_consistency=$w"
    done; done
  done; done
}
lines_i() {
  for s in 0 1 2; do for c in castle_p30 herz_jesus_p25; do for v in 3 6 9; do
    echo "one4 i_${c}_${v}v_full_s$s full $c $v $s --set full.path_consistency=1.0"
  done; done; done
}
cuda_tests() {  # once per machine: a passed run leaves $R/t_ok (the tests on CUDA only: the packed Warp has no CPU
  [ -f "$R/t_ok" ] && return 0  # compiler)
  timeout 200 python3 -m pytest -q -p no:cacheprovider tests/test_binocular.py tests/test_path_consistency.py -k cuda 2>&1 \
    | tail -3 | tee "$OUT/t.log"
  grep -q " passed" "$OUT/t.log" && ! grep -q "failed\|error" "$OUT/t.log" && python3 -c "import torch; assert torch.cuda.is_available()" \
    && touch "$R/t_ok"
}
case $P in
t) cuda_tests ;;
c) lines_c | run_lines 48; summary c_ c.txt ;;
i) lines_i | run_lines 18; summary i_ i.txt ;;
q) cuda_tests || { echo "the CUDA tests failed: no runs"; exit 1; }
   { lines_c; lines_i; } | run_lines 48; summary c_ c.txt; summary i_ i.txt ;;
*) echo "unknown phase $P"; exit 2 ;;
esac
