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
# Each call leaves results.json, switches.md / .json, summary.md and the two charts in $OUT (from $R/suite_out).
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
case $P in
s) suite_call synthetic,fern_3v,dtu65_3v,castle_p30_3v,castle_p30_6v,castle_p30_9v,herz_jesus_p25_3v,herz_jesus_p25_6v,herz_jesus_p25_9v ;;
g) suite_call lego_8v ;;
*) echo "unknown phase $P"; exit 2 ;;
esac
