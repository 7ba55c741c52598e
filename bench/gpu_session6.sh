#!/usr/bin/env bash
# GPU runs of session 6 (issue #13: the full method on real walk-around captures), on a lent 2-GPU host after
# the packed wheels are in /tmp/site and the scenes in $D:  bash bench/gpu_session6.sh PHASE D RUNS
#   x: exploration at images_8, 3000 it, castle_p30 / herz_jesus_p25 x 3 / 9 views: the full method without the
#      learning-rate restart, then with a pseudo-view mask, growth budget, no or stricter densification, no depth
#      prior; bench/select_variant.py picks the acceptance settings from them by a rule fixed beforehand
#   y1..y3: the acceptance runs with the capture defaults x led to (configs/nerfstudio.yaml), resumed across calls
# Runs are spread over the GPUs (GPUS, default 2) and share the cores (OMP_NUM_THREADS=1); each writes
# RUNS/<name>/metrics.json (gather: bench/gather_runs.py).
set -u
P=$1; D=$2; R=$3; mkdir -p "$R"
GPUS=${GPUS:-2}; source bench/gpu_runs.sh  # sp, spt, acceptance_i4
case $P in
x)
  NL="--set full.restart_lr=false"
  ST="--set full.densify_config.stereo.min_score=0.8 --set full.densify_config.stereo.min_consistent=2"
  for sc in castle_p30 herz_jesus_p25; do for v in 3 9; do
    A="--data $D/$sc --downscale 8 --views $v --iterations 3000 --set train.checkpoint_every=0"
    n=${sc:0:1}$v
    sp "${n}_b" $A --method baseline &
    sp "${n}_f_nl" $A --method full $NL &
    sp "${n}_f_nl_rel" $A --method full $NL --set full.pseudo_mask=reliable &
    sp "${n}_f_nl_gb" $A --method full $NL --set full.growth_budget=1.5 &
    sp "${n}_f_nl_nd" $A --method full $NL --set full.densify=false &
    sp "${n}_f_nl_strict" $A --method full $NL $ST &
    sp "${n}_f_nl_nodepth" $A --method full $NL --set full.input_depth_weight=0 --set full.depth_weight=0 &
    sp "${n}_f_combo" $A --method full $NL --set full.pseudo_mask=reliable --set full.growth_budget=1.5 $ST &
  done; done
  ;;
y1)  # acceptance with the capture defaults x led to (configs/nerfstudio.yaml: one learning-rate schedule, stricter
    # densification stereo; DropGaussian 0.2 in the full method): images_4, 10,000 it, 3/6/9 views, baseline and
    # full (SIGINT at T s, checkpointed, resumed by y2); images_8, 3000 it, seed 0: DropGaussian in the baseline and
    # in the full method (the ablations of what the full method adds)
  T=${T:-540}
  acceptance_i4 "$T"
  for sc in castle_p30 herz_jesus_p25; do for v in 3 9; do
    A="--data $D/$sc --downscale 8 --views $v --iterations 3000 --set train.checkpoint_every=0"
    n=${sc:0:1}$v
    sp "${n}_b_drop_s0" $A --method baseline --set train.drop_rate=0.2 &
    sp "${n}_full_s0" $A --method full &
  done; done
  ;;
y2)  # resume y1's images_4 runs; images_8 seeds 1 and 2 of the baseline and the full method
  T=${T:-540}
  for d in "$R"/*_i4; do [ -f "$d/metrics.json" ] || spt "$T" "$(basename "$d")" --resume "$d" & done
  for s in 1 2; do for sc in castle_p30 herz_jesus_p25; do for v in 3 9; do
    A="--data $D/$sc --downscale 8 --views $v --iterations 3000 --seed $s --set train.checkpoint_every=0"
    n=${sc:0:1}$v
    sp "${n}_baseline_s$s" $A --method baseline &
    sp "${n}_full_s$s" $A --method full &
  done; done; done
  ;;
y3)  # whatever y2 left unfinished
  T=${T:-540}
  for d in "$R"/*_i4; do [ -f "$d/metrics.json" ] || spt "$T" "$(basename "$d")" --resume "$d" & done
  ;;
esac
wait
python3 bench/gather_runs.py "$R" "$OUT/runs_$P.json" --logs "$OUT/logs_$P.txt"
