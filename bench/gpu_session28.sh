#!/usr/bin/env bash
# GPU runs of session 28 (issue 13), after the packed wheels are installed in /tmp/site and the scenes copied to $D.
#   T=seconds bash bench/gpu_session28.sh PHASE D RUNS
# a: the captures' default with the far field on a cylinder around the capture (train.far_field_proxy=auto, chosen
#    leave-one-out over the inputs): castle_p30 and herz_jesus_p25 at 3, 6 and 9 views, baseline and full, seeds 0-2
#    (384x256, 3000 it; prefix c), and the rasterizer's far-field tests on CUDA.
# b: the same 36 runs with 24 far-field bands (train.far_field_bins=24; prefix b).
# i: issue 13's first acceptance point on session 28's default: castle_p30 and herz_jesus_p25 at 3, 6 and 9 views,
#    images_4 (768x512), 10,000 iterations, baseline and full, seed 0 (prefix i): every run completes and writes its
#    metrics (resumed from its checkpoint by a second call when one call's time is not enough).
# m: the full method of a's 18 cases with its pseudo views supervising every pixel (full.pseudo_mask=all; prefix m).
set -u
source "$(dirname "${BASH_SOURCE[0]}")/gpu_one.sh"
session_env "$@"; P=$1; D=$2; R=$3; shift 3
export R D T
case $P in
a)
  timeout 120 python3 -m pytest -q -x tests/test_farfield.py -k "not trainer" 2>&1 | tail -n 2 | tee "$OUT/tests_farfield_cuda.log"
  { for c in castle_p30 herz_jesus_p25; do for v in 3 6 9; do for m in baseline full; do for s in 0 1 2; do
      echo "c_${c}_${v}v_${m}_s$s $m $c $v $s"
    done; done; done; done; } | xargs -P ${JOBS:-36} -L 1 bash -c 'one "$@"' _ | grep -v "rc=0"
  summary c_ c369.txt
  ;;
b)
  { for c in castle_p30 herz_jesus_p25; do for v in 3 6 9; do for m in baseline full; do for s in 0 1 2; do
      echo "b_${c}_${v}v_${m}_s$s $m $c $v $s --set train.far_field_bins=24"
    done; done; done; done; } | xargs -P ${JOBS:-36} -L 1 bash -c 'one "$@"' _ | grep -v "rc=0"
  summary b_ b369.txt
  ;;
i)
  { for c in castle_p30 herz_jesus_p25; do for v in 3 6 9; do for m in baseline full; do
      echo "i_${c}_${v}v_${m}_s0 $m $c $v 0"
    done; done; done; } | DS=4 IT=10000 xargs -P ${JOBS:-12} -L 1 bash -c 'one "$@"' _
  summary i_ i369.txt
  grep -l "TrainingDiverged\|diverged" "$R"/i_*.log | tee "$OUT/i369_diverged.txt"
  ;;
m)
  { for c in castle_p30 herz_jesus_p25; do for v in 3 6 9; do for s in 0 1 2; do
      echo "m_${c}_${v}v_full_s$s full $c $v $s --set full.pseudo_mask=all"
    done; done; done; } | xargs -P ${JOBS:-18} -L 1 bash -c 'one "$@"' _ | grep -v "rc=0"
  summary m_ m369.txt
  ;;
*) echo "unknown phase $P"; exit 2 ;;
esac
