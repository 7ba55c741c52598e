#!/usr/bin/env bash
# GPU runs prepared in session 38 for the next session (wheels in /tmp/site; scenes in $D: llff_fern, dtu_scan65,
# blender_lego, castle_p30, herz_jesus_p25).
#   T=seconds bash bench/gpu_session39.sh PHASE D RUNS
# Issue 14's switch table (bench/suite.py --preset switches) has no rows yet for Binocular3DGS's two terms, the
# defaults of LLFF, DTU, Blender and the captures since session 36, and its reference rows (plain baseline, full) were
# measured on an H100 in sessions 12-13, by code that has changed since. These phases measure the reference rows and
# the four rows of those terms again, on today's code, into a new results folder (suite_cuda_h200_switches_s39), over
# every GPU of the machine (bench/suite.py spreads its runs over the visible GPUs; --time-limit stops the runs still
# going at their checkpoints, and the next call goes on from there).
# s: the synthetic room, fern, DTU and the six capture cases (labels below; seeds 0-2): 9 cases x 6 labels x 3 seeds =
#    162 runs, about two calls on two H200s.
# g: lego 8 views at 10,000 it, the same labels (18 runs).
# r: the captures at images_4 (768x512, 10,000 it; the size --data dl3dv trains at), the full method with its growth
#    stopped at half the run (full.refine_stop_fraction=0.5, LLFF's default since session 38: fern +0.23), 6 and 9 views
#    (3 views hold their geometry and do not grow), seeds 0-2 (12 runs). The reference is session 38's images_4 runs of
#    the default (s38/i.txt): there herz_jesus_p25 loses -0.05 to -0.20 against the baseline, with 43k Gaussians against
#    its 33k at 6 views. At 384x256 this setting gave herz 6 / 9 views +0.09 / +0.21 and castle 9 views -0.59 at seed 0
#    (s37/t.txt). Through bench/gpu_one.sh's queue (every GPU). r.txt.
# w: the same 12 cases with the pseudo views weighted x 0.05 instead of 0.2 (SYN3R's LLFF/DTU value): at images_4
#    herz_jesus_p25 loses most on test frame 8, between two inputs where the pseudo views are (-0.75 / -0.35 dB at 6 / 9
#    views), and on frame 0 before the first input (-0.38 / -0.21). w.txt.
# Session 39 ran s and g together as one bench/suite.py call over both GPUs (--scenes ...,lego_8v; 180 runs, every one
# finished, in three device calls: bench/results/suite_cuda_h200_switches_s39). r and w were not run (bench/gpu_session40.sh).
# Each suite call leaves results.json, switches.md / .json, summary.md and the two charts in $OUT (from $R/suite_out).
set -u
source "$(dirname "${BASH_SOURCE[0]}")/gpu_one.sh"
session_env "$@"; P=$1; D=$2; R=$3; shift 3
LABELS=${LABELS:-baseline,baseline+opacity_decay,baseline+binocular,full,full+opacity_decay,full+binocular}
suite_call() {  # suite_call CASES
  python3 bench/suite.py --device cuda --data-root "$D" --preset switches --only "$LABELS" --scenes "$1" \
    --jobs "${JOBS:-36}" --time-limit "${T:-540}" --out "$R/suite_out" --work "$R/sw" 2>&1 \
    | tee -a "$R/suite.log" | grep -E "^suite|stopped|failed" | tail -40
  cp "$R"/suite_out/{results.json,switches.md,switches.json,summary.md,psnr_vs_time.png,psnr_vs_gaussians.png} \
    "$R/suite.log" "$OUT/" 2>/dev/null
}
images4_full() {  # images4_full PREFIX [--set k=v ...]: the full method at images_4, 6 and 9 views, seeds 0-2, every GPU
  local prefix=$1; shift
  export R D END=$(( $(date +%s) + ${T:-540} ))
  { for s in 0 1 2; do for c in castle_p30 herz_jesus_p25; do for v in 6 9; do
      echo "one ${prefix}${c}_${v}v_full_s$s full $c $v $s $*"
    done; done; done; } | DS=4 IT=10000 run_lines 18
  summary "$prefix" "${prefix%_}.txt"
}
case $P in
s) suite_call synthetic,fern_3v,dtu65_3v,castle_p30_3v,castle_p30_6v,castle_p30_9v,herz_jesus_p25_3v,herz_jesus_p25_6v,herz_jesus_p25_9v ;;
g) suite_call lego_8v ;;
r) images4_full r_ --set full.refine_stop_fraction=0.5 ;;
w) images4_full w_ --set full.pseudo_weight=0.05 ;;
*) echo "unknown phase $P"; exit 2 ;;
esac
