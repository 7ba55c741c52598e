#!/usr/bin/env bash
# GPU runs prepared in session 33 for the next session, after the packed wheels are installed in /tmp/site (and pycolmap
# from .device/extra for the captures) and the scenes copied to $D (blender_lego and dtu_scan65 from .gpudata/c, llff_fern
# and the captures' images_8 from .gpudata/a; the captures' images_4 from .gpudata/b for phase q).
#   T=seconds bash bench/gpu_session34.sh PHASE D RUNS
# p: issue 13. SYN3R's pseudo-view poses: each interior pose of a trajectory replaced by the most uncertain of 5 perturbed
#    candidates (pseudo.trajectory.perturb_candidates=5; translation sigma 0.1 x the distance between the two inputs, as
#    SYN3R; and 0.3; SIGMAS="10" runs only the first), the full method only, captures at 384x256, 3000 it, seeds 0-2 (36 runs; the default's runs are
#    session 28's s28/m369.txt, its baselines s28/c369.txt; python bench/captures_table.py --session 34). Session 33 found
#    the pseudo views hold the model only on the path through the inputs, while the capture's other frames lie 5-11 m
#    from it at 3 views. Resumable; prefix p_; p369.txt.
# q: the better of p's two at images_4 (768x512, 10,000 it), full only, seeds 0-2 (18 runs, two calls): VARIANT="--set
#    ..." chooses it. Prefix q_; q369.txt.
# l: issue 14, lego (10,000 it, seeds 0-2) around session 33's best (means_lr_final 3.2e-5, 24.35): final rates 4.8e-5
#    and 6.4e-5, 3.2e-5 with twice the initial rate, with 10k starting Gaussians, and at 15,000 it. 15 runs; l.txt.
#    ONLY=REGEX keeps the runs whose line matches (session 34's second l call: ONLY="15k|lrf64").
# b: means_lr_final=3.2e-5 with each config's defaults on fern, DTU and lego, both methods (18 runs; compare
#    bench/results/s31/o.txt): whether it may become a default under issue 14's rule; and p's perturbed poses (sigma
#    0.1) in the full method on fern and DTU, and CoR-GS's pair (train.co_reg) on DTU, both methods (12 runs; DTU's full
#    method is issue 14's other unmet point; session 33's CPU hint, seed 0: full 22.30 -> 22.98 with the pair, baseline
#    22.23; bench/results/s33/cpu.txt). PARTS (default "coreg lrf pert") picks and orders the three sets. Prefix b_; b.txt.
set -u
source "$(dirname "${BASH_SOURCE[0]}")/gpu_one.sh"
session_env "$@"; P=$1; D=$2; R=$3; shift 3
export R D T END=$(( $(date +%s) + ${T:-540} ))  # every run of the call stops by then
LRF="--set optim.means_lr_final=3.2e-5"
PERT="--set pseudo.trajectory.perturb_candidates=5"
case $P in
p)
  { for s in 0 1 2; do for c in castle_p30 herz_jesus_p25; do for v in 3 6 9; do
      for sg in ${SIGMAS:-10 30}; do
        echo "p_pert${sg}_${c}_${v}v_full_s$s full $c $v $s $PERT --set pseudo.trajectory.perturb_translation=0.$sg"
      done
    done; done; done; } | xargs -P ${JOBS:-18} -L 1 bash -c 'one "$@"' _ | grep -v "rc=0"
  summary p_ p369.txt
  ;;
q)
  { for s in 0 1 2; do for c in herz_jesus_p25 castle_p30; do for v in 3 6 9; do
      echo "q_${c}_${v}v_full_s$s full $c $v $s ${VARIANT:?VARIANT=\"--set ...\" names the variant}"
    done; done; done; } | DS=4 IT=10000 xargs -P ${JOBS:-9} -L 1 bash -c 'one "$@"' _ | grep -v "rc=0"
  summary q_ q369.txt
  ;;
l)
  { for s in 0 1 2; do
      echo "lego l_lrf48e6_s$s baseline $s 10000 $LEGO_BEST --set optim.means_lr_final=4.8e-5"
      echo "lego l_lrf64e6_s$s baseline $s 10000 $LEGO_BEST --set optim.means_lr_final=6.4e-5"
      echo "lego l_lrf32e6_lr2_s$s baseline $s 10000 $LEGO_BEST $LRF --set optim.means_lr=3.2e-4"
      echo "lego l_lrf32e6_init10k_s$s baseline $s 10000 $LEGO_BEST $LRF --set model.init_num=10000"
      echo "lego l_lrf32e6_15k_s$s baseline $s 15000 $LEGO_BEST $LRF"
    done; } | grep -E -- "${ONLY:-.}" | xargs -P ${JOBS:-15} -L 1 bash -c '"$@"' _ | grep -v "rc=0"
  summary l_ l.txt
  ;;
b)
  { for part in ${PARTS:-coreg lrf pert}; do for s in 0 1 2; do case $part in
      coreg)
        echo "named b_dtu_coreg_full_s$s full dtu scan65 3 $s --set train.co_reg=true"
        echo "named b_dtu_coreg_baseline_s$s baseline dtu scan65 3 $s --set train.co_reg=true" ;;
      lrf) for m in baseline full; do
        echo "lego b_lego_${m}_s$s $m $s 10000 $LRF"
        echo "named b_fern_${m}_s$s $m llff fern 3 $s $LRF"
        echo "named b_dtu_${m}_s$s $m dtu scan65 3 $s $LRF"
      done ;;
      pert)
        echo "named b_fern_pert10_full_s$s full llff fern 3 $s $PERT"
        echo "named b_dtu_pert10_full_s$s full dtu scan65 3 $s $PERT" ;;
    esac; done; done; } | xargs -P ${JOBS:-24} -L 1 bash -c '"$@"' _ | grep -v "rc=0"
  summary b_ b.txt
  ;;
*) echo "unknown phase $P"; exit 2 ;;
esac
