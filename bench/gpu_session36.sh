#!/usr/bin/env bash
# GPU runs of session 36: Binocular3DGS's two weight-free terms (Han et al., NeurIPS 2024), new switches
# train.opacity_decay (every opacity x (1 - rate) each step from strategy.refine_start_iter; theirs 0.005) and
# train.binocular (the render from the camera moved along its x axis warped back into the input with its rendered
# depth, L1 against the photo; warpgs/binocular.py). Scenes as in gpu_session35.sh (wheels in /tmp/site, pycolmap
# from .device/extra, scenes in $D).
#   T=seconds bash bench/gpu_session36.sh PHASE D RUNS          (ONLY=REGEX keeps the runs whose line matches)
# a: each switch alone over the current best settings, seeds 0-2: lego's best setting at 10,000 it (s33/a.txt: 24.35),
#    fern and DTU baselines at 3000 it (s35/r.txt: 21.36 / 23.32). 18 runs, one call. a.txt.
# b (after a: decay lego 24.80, fern 22.60, DTU 24.57; binocular DTU 25.67, fern 21.66, lego 24.34): the captures at
#    384x256 (3000 it), 3 / 6 / 9 views, both methods, each switch and both, seed 0 (36 runs, one call). b.txt.
# c: both switches on lego (10,000 it), fern and DTU baselines; the full method on fern and DTU with the decay and with
#    both, seeds 0-2 (21 runs). c.txt.
# d (after b and c: both switches raise every case; captures seed 0 baseline +0.3..+1.5): both switches at seeds 1-2 on
#    the captures (384x256, both methods, 24 runs) and the synthetic room (its config, seeds 0-2, both methods, each
#    switch alone and both: 18 runs). d.txt.
set -u
source "$(dirname "${BASH_SOURCE[0]}")/gpu_one.sh"
session_env "$@"; P=$1; D=$2; R=$3; shift 3
export R D T END=$(( $(date +%s) + ${T:-540} ))  # every run of the call stops by then
LRF="--set optim.means_lr_final=3.2e-5"
DEC="--set train.opacity_decay=0.005"
BIN="--set train.binocular=1"
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
  { for m in baseline full; do for c in castle_p30 herz_jesus_p25; do for v in 3 6 9; do
      echo "one b_${c}_${v}v_${m}_dec_s0 $m $c $v 0 $DEC"
      echo "one b_${c}_${v}v_${m}_bin_s0 $m $c $v 0 $BIN"
      echo "one b_${c}_${v}v_${m}_db_s0 $m $c $v 0 $DEC $BIN"
    done; done; done; } | run_lines 18
  summary b_ b.txt
  ;;
c)
  { for s in 0 1 2; do
      echo "lego c_lego_db_s$s baseline $s 10000 $LEGO_BEST $LRF $DEC $BIN"
      echo "named c_fern_db_s$s baseline llff fern 3 $s $DEC $BIN"
      echo "named c_dtu_db_s$s baseline dtu scan65 3 $s $DEC $BIN"
      for k in dec db; do
        [ $k = dec ] && X=$DEC || X="$DEC $BIN"
        echo "named c_fern_full_${k}_s$s full llff fern 3 $s $X"
        echo "named c_dtu_full_${k}_s$s full dtu scan65 3 $s $X"
      done
    done; } | run_lines 21
  summary c_ c.txt
  ;;
d)
  { for s in 1 2; do for m in baseline full; do for c in castle_p30 herz_jesus_p25; do for v in 3 6 9; do
      echo "one b_${c}_${v}v_${m}_db_s$s $m $c $v $s $DEC $BIN"
    done; done; done; done
    for s in 0 1 2; do for m in baseline full; do
      echo "sparse_run d_room_${m}_db_s$s --method $m --data synthetic --seed $s --set train.eval_every=100 $DEC $BIN"
      echo "sparse_run d_room_${m}_dec_s$s --method $m --data synthetic --seed $s --set train.eval_every=100 $DEC"
      echo "sparse_run d_room_${m}_bin_s$s --method $m --data synthetic --seed $s --set train.eval_every=100 $BIN"
    done; done; } | run_lines 21
  summary b_ b_all.txt > /dev/null
  summary d_ d.txt
  ;;
e)
  # blender.yaml's own defaults (not lego's best setting) with both switches, both methods, seeds 0-2 (s31/o.txt: 23.67 / 23.30)
  { for s in 0 1 2; do for m in baseline full; do
      echo "lego e_lego_${m}_db_s$s $m $s 10000 $DEC $BIN"
    done; done; } | run_lines 6
  summary e_ e.txt
  ;;
f)
  # after the defaults changed (both switches in llff, dtu, blender and nerfstudio.yaml): lego's full method with
  # blender.yaml's defaults, seeds 0-2 (phase e's full runs did not finish in its call)
  { for s in 0 1 2; do echo "lego f_lego_full_s$s full $s 10000"; done; } | run_lines 3
  summary f_ f.txt
  ;;
g)
  # the captures at images_4 (768x512, 10,000 it; issue 13's setting) with the new defaults, both methods, seed 0 (12 runs;
  # the rows of s35/c69.txt and s28/i369.txt had neither switch). g.txt.
  { for m in baseline full; do for c in castle_p30 herz_jesus_p25; do for v in 3 6 9; do
      echo "one g_${c}_${v}v_${m}_s0 $m $c $v 0"
    done; done; done; } | DS=4 IT=10000 run_lines 12
  summary g_ g.txt
  ;;
*) echo "unknown phase $P"; exit 2 ;;
esac
