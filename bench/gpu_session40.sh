#!/usr/bin/env bash
# GPU runs prepared in session 39 for the next session (wheels in /tmp/site; scenes in $D: llff_fern, dtu_scan65,
# blender_lego, castle_p30, herz_jesus_p25 with images_4).
#   T=seconds bash bench/gpu_session40.sh PHASE D RUNS          (ONLY=REGEX keeps the runs whose line matches)
# Session 39's switch table (bench/results/suite_cuda_h200_switches_s39) measured the binocular term alone on today's
# code: it lifts the baseline on every case (DTU +2.65, the captures +0.25 to +2.04) and gives the full method less
# (DTU: 24.45 against the baseline's 25.47 with it). Its partner is a sideways move of the input camera. Session 39 added
# train.binocular_partner: path (warpgs/binocular.py): the partner is a pose of the capture path next to the input, up
# to train.binocular_reach (0.5) of the way to a neighbouring input: where the test views of a walk-around capture lie
# (herz_jesus_p25 at images_4 loses most on test frame 8, between two inputs).
# p: the path partner with each config's defaults (binocular 1 on LLFF, DTU and the captures), both methods, seeds 0-2:
#    the six capture cases at 384x256, DTU and fern (48 runs, one call on two H200s). Against s36/b_all.txt +
#    s37/t.txt (captures), s36/c.txt + s37/t.txt (DTU), s36/c.txt + s38/l.txt (fern). p.txt.
# h: the same at reach 0.25 (48 runs). h.txt.
# i: the path partner at images_4 (768x512, 10,000 it), both methods, 6 and 9 views, seeds 0-2 (24 runs; about two
#    calls). Against s36/g.txt + s38/i.txt. i.txt.
# r, w: session 39's r and w (the full method at images_4 with its growth stopped at half the run / pseudo weight 0.05;
#    not run in session 39, whose device time went to the switch table): bash bench/gpu_session39.sh r|w.
# b (session 40): the binocular term from 0.25 of the run (train.binocular_start=0.25; default 0.5), both methods, the
#    captures at 384x256 and DTU, seeds 0-2 (42 runs). The full method makes its first pseudo views at 0.4 of the run
#    (full.baseline_fraction), before the term starts at 0.5: they hold the model to renders made without it (session
#    37). From 0.25 on, the pseudo views are made from a model the term has already shaped. b.txt.
# t: the binocular tests on CUDA first (pose_warp and the path partner have run on the CPU only): about 30 s.
# q: t, then p and i in one queue over every GPU of the machine (nothing runs if t fails).
# z (session 40): t, then p, b and i in one queue (the order of priority; a call that ends first leaves the rest for
#    the next call, which resumes).
# Copy the summaries to bench/results/s40/; python bench/captures_table.py --session 40 prints the tables.
set -u
source "$(dirname "${BASH_SOURCE[0]}")/gpu_one.sh"
session_env "$@"; P=$1; D=$2; R=$3; shift 3
export R D T END=$(( $(date +%s) + ${T:-540} ))  # every run of the call stops by then
lines_small() {  # lines_small PREFIX [--set k=v ...]: captures at 384x256, DTU and fern, both methods, seeds 0-2
  local p=$1; shift
  for s in 0 1 2; do for m in baseline full; do
    echo "named ${p}_dtu_${m}_s$s $m dtu scan65 3 $s $*"
    echo "named ${p}_fern_${m}_s$s $m llff fern 3 $s $*"
    for c in castle_p30 herz_jesus_p25; do for v in 3 6 9; do
      echo "one ${p}_${c}_${v}v_${m}_s$s $m $c $v $s $*"
    done; done
  done; done
}
lines_i() {
  for s in 0 1 2; do for m in baseline full; do for c in castle_p30 herz_jesus_p25; do for v in 6 9; do
    echo "one4 i_${c}_${v}v_${m}_s$s $m $c $v $s --set train.binocular_partner=path"
  done; done; done; done
}
case $P in
t) cuda_tests tests/test_binocular.py ;;
p) lines_small p --set train.binocular_partner=path | run_lines 48; summary p_ p.txt ;;
b) lines_small b --set train.binocular_start=0.25 | grep -v _fern_ | run_lines 48; summary b_ b.txt ;;
h) lines_small h --set train.binocular_partner=path --set train.binocular_reach=0.25 | run_lines 48; summary h_ h.txt ;;
i) lines_i | run_lines 24; summary i_ i.txt ;;
q) cuda_tests tests/test_binocular.py || { echo "the CUDA tests failed: no runs"; exit 1; }
   { lines_small p --set train.binocular_partner=path; lines_i; } | run_lines 48; summary p_ p.txt; summary i_ i.txt ;;
z) cuda_tests tests/test_binocular.py || { echo "the CUDA tests failed: no runs"; exit 1; }
   { lines_small p --set train.binocular_partner=path; lines_small b --set train.binocular_start=0.25 | grep -v _fern_
     lines_i; } | run_lines 48; summary p_ p.txt; summary b_ b.txt; summary i_ i.txt ;;
*) echo "unknown phase $P"; exit 2 ;;
esac
