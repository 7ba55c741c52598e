#!/usr/bin/env bash
# GPU runs prepared in session 36 for the next session (wheels in /tmp/site, pycolmap from .device/extra, scenes in $D:
# llff_fern, dtu_scan65 and the captures' images_8 for phase s; the captures' images_4 from .gpudata/b for phase i).
#   T=seconds bash bench/gpu_session37.sh PHASE D RUNS          (ONLY=REGEX keeps the runs whose line matches)
# Session 36 made opacity decay and binocular consistency the defaults of LLFF, DTU, Blender and the captures. They
# raised the baseline more than the full method: full - baseline is now +0.13 dB on average over the captures at
# 384x256, -0.04 on fern, -0.58 on DTU. The full method makes its first pseudo views at 0.4 of the run (step 1200 of
# 3000), before the binocular term starts (0.5): those views hold the model to a render made without it.
# s: train.binocular_start=0.2 (the term from step 600, before the first pseudo views), both methods, fern, DTU and
#    the captures at 384x256, 3 / 6 / 9 views, seeds 0-2 (48 runs, two calls; JOBS 24). Compare s36/c.txt, b_all.txt.
# p: the full method with its pseudo views weighted 0.2 (full.pseudo_weight; SYN3R's code uses 0.05-0.2) at the default
#    start, fern, DTU and the captures at 384x256, seeds 0-2 (24 runs, one call). p.txt.
# i: the captures at images_4 (768x512, 10,000 it) with session 36's defaults, seeds 1-2, both methods (24 runs, about
#    three calls); seed 0 is s36/g.txt.
# t (session 37, run first): a screen at seed 0 of the full method's settings that session 36's curves point to, at
#    384x256 (3000 it) on the six capture cases, fern and DTU: on DTU the baseline gains 1.8 dB in the 300 steps after
#    the binocular term starts (step 1500) and the full method 0.6, held by pseudo views made at step 1200 without it.
#    Variants: s (train.binocular_start=0.2, both methods), p (full.pseudo_weight=0.2), sp (both), bf
#    (full.baseline_fraction=0.6: the first pseudo views after the term starts), r (full.refine_stop_fraction=0.5:
#    the full method stops growing at half the run, as the baseline). 48 runs, one call. t.txt.
# w (after t: full.pseudo_weight=0.2 gives full - baseline +0.38 dB on the captures over seeds 0-2, DTU +0.25): weights
#    0.1 and 0.05 on the six capture cases and DTU, seed 0 (14 runs, one short call). w.txt.
set -u
source "$(dirname "${BASH_SOURCE[0]}")/gpu_one.sh"
session_env "$@"; P=$1; D=$2; R=$3; shift 3
export R D T END=$(( $(date +%s) + ${T:-540} ))  # every run of the call stops by then
case $P in
t)
  declare -A V=([s]="--set train.binocular_start=0.2" [p]="--set full.pseudo_weight=0.2"
                [sp]="--set train.binocular_start=0.2 --set full.pseudo_weight=0.2"
                [bf]="--set full.baseline_fraction=0.6" [r]="--set full.refine_stop_fraction=0.5")
  { for s in ${SEEDS:-0}; do for v in ${VARIANTS:-s p sp bf r}; do
      ms=full; [ "$v" = s ] && ms="full baseline"
      for m in $ms; do
        echo "named t_${v}_fern_${m}_s$s $m llff fern 3 $s ${V[$v]}"
        echo "named t_${v}_dtu_${m}_s$s $m dtu scan65 3 $s ${V[$v]}"
        for c in castle_p30 herz_jesus_p25; do for n in 3 6 9; do
          echo "one t_${v}_${c}_${n}v_${m}_s$s $m $c $n $s ${V[$v]}"
        done; done
      done
    done; done; } | run_lines 24
  summary t_ t.txt
  ;;
w)
  { for pw in ${WEIGHTS:-0.1 0.05}; do
      echo "named w${pw}_dtu_full_s0 full dtu scan65 3 0 --set full.pseudo_weight=$pw"
      for c in castle_p30 herz_jesus_p25; do for n in 3 6 9; do
        echo "one w${pw}_${c}_${n}v_full_s0 full $c $n 0 --set full.pseudo_weight=$pw"
      done; done
    done; } | run_lines 24
  summary w w.txt
  ;;
s)
  BS="--set train.binocular_start=0.2"
  { for s in 0 1 2; do for m in full baseline; do
      echo "named s_fern_${m}_s$s $m llff fern 3 $s $BS"
      echo "named s_dtu_${m}_s$s $m dtu scan65 3 $s $BS"
      for c in castle_p30 herz_jesus_p25; do for v in 3 6 9; do
        echo "one s_${c}_${v}v_${m}_s$s $m $c $v $s $BS"
      done; done
    done; done; } | run_lines 24
  summary s_ s.txt
  ;;
p)
  PW="--set full.pseudo_weight=0.2"
  { for s in 0 1 2; do
      echo "named p_fern_full_s$s full llff fern 3 $s $PW"
      echo "named p_dtu_full_s$s full dtu scan65 3 $s $PW"
      for c in castle_p30 herz_jesus_p25; do for v in 3 6 9; do
        echo "one p_${c}_${v}v_full_s$s full $c $v $s $PW"
      done; done
    done; } | run_lines 24
  summary p_ p.txt
  ;;
i)
  { for s in 1 2; do for m in full baseline; do for c in castle_p30 herz_jesus_p25; do for v in 3 6 9; do
      echo "one i_${c}_${v}v_${m}_s$s $m $c $v $s"
    done; done; done; done; } | DS=4 IT=10000 run_lines 12
  summary i_ i.txt
  ;;
*) echo "unknown phase $P"; exit 2 ;;
esac
