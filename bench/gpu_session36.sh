#!/usr/bin/env bash
# GPU runs of session 36: Binocular3DGS's two weight-free terms (Han et al., NeurIPS 2024), new switches
# train.opacity_decay (every opacity x (1 - rate) each step from strategy.refine_start_iter; theirs 0.005) and
# train.binocular (the render from the camera moved along its x axis warped back into the input with its rendered
# depth, L1 against the photo; warpgs/binocular.py). Scenes as in gpu_session35.sh (wheels in /tmp/site, pycolmap
# from .device/extra, scenes in $D).
#   T=seconds bash bench/gpu_session36.sh PHASE D RUNS          (ONLY=REGEX keeps the runs whose line matches)
# a: each switch alone over the current best settings, seeds 0-2: lego's best setting at 10,000 it (s33/a.txt: 24.35),
#    fern and DTU baselines at 3000 it (s35/r.txt: 21.36 / 23.32). 18 runs, one call. a.txt.
# b: the captures at 384x256 (3000 it), 3 / 6 / 9 views, both methods with the switch phase a liked (SW=...),
#    seeds 0-2. 36 runs, one call. b.txt.
# c: lego's best setting at 15,000 it (s34: 24.49) with SW, and the fern / DTU full method with SW, seeds 0-2. c.txt.
set -u
source "$(dirname "${BASH_SOURCE[0]}")/gpu_one.sh"
session_env "$@"; P=$1; D=$2; R=$3; shift 3
export R D T END=$(( $(date +%s) + ${T:-540} ))  # every run of the call stops by then
LRF="--set optim.means_lr_final=3.2e-5"
DEC="--set train.opacity_decay=0.005"
BIN="--set train.binocular=1"
SW=${SW:-$BIN}
case $P in
a)
  { for s in 0 1 2; do
      echo "lego a_lego_bin_s$s baseline $s 10000 $LEGO_BEST $LRF $BIN"
      echo "lego a_lego_dec_s$s baseline $s 10000 $LEGO_BEST $LRF $DEC"
      for k in bin dec; do
        [ $k = bin ] && X=$BIN || X=$DEC
        echo "named a_fern_${k}_s$s baseline llff fern 3 $s $X"
        echo "named a_dtu_${k}_s$s baseline dtu scan65 3 $s $X"
      done
    done; } | run_lines 18
  summary a_ a.txt
  ;;
b)
  { for s in 0 1 2; do for m in baseline full; do for c in castle_p30 herz_jesus_p25; do for v in 3 6 9; do
      echo "one b_${c}_${v}v_${m}_s$s $m $c $v $s $SW"
    done; done; done; done; } | run_lines 18
  summary b_ b.txt
  ;;
c)
  { for s in 0 1 2; do
      echo "lego c_lego15k_s$s baseline $s 15000 $LEGO_BEST $LRF $SW"
      echo "named c_fern_full_s$s full llff fern 3 $s $SW"
      echo "named c_dtu_full_s$s full dtu scan65 3 $s $SW"
    done; } | run_lines 9
  summary c_ c.txt
  ;;
*) echo "unknown phase $P"; exit 2 ;;
esac
