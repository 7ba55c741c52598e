#!/usr/bin/env bash
# GPU runs of session 5 (issue #13, real walk-around captures), on the lent GPU after the packed wheels are in
# /tmp/site and the scenes in $D (castle_p30, herz_jesus_p25, llff_fern, dtu_scan65, blender_lego):
#   bash bench/gpu_session5.sh PHASE D RUNS
#   a: images_8, 3000 it: initialisations (frustum / sfm / stereo / sfm+stereo / + random) x castle, herz x 3, 9
#      views, the full method with the capture default; fern and DTU with frustum vs sfm+stereo (29 runs at once:
#      too many for 16 cores, none finished; b-d are its runs in smaller groups)
#   b, c, d: exploration at images_8, 3000 it (bench/results/real_captures/session5_explore_{b,c,d}.json)
#   e1, e2, e3: the acceptance runs (images_4, 10k it, resumed across calls) and the regressions
#      (bench/results/real_captures/session5_final.json; README table: bench/real_captures_table.py)
# Runs go in parallel on the one GPU; each writes RUNS/<name>/metrics.json (gather: bench/gather_runs.py).
set -u
P=$1; D=$2; R=$3; mkdir -p "$R"
GPUS=1; source bench/gpu_runs.sh  # sp, spt, acceptance_i4; many runs share 16 cores
case $P in
a)
  sp warm --data "$D/castle_p30" --downscale 8 --views 3 --method full --iterations 40 --set train.checkpoint_every=0
  for sc in castle_p30 herz_jesus_p25; do for v in 3 9; do
    A="--data $D/$sc --downscale 8 --views $v --iterations 3000 --set train.checkpoint_every=0"
    n=${sc:0:1}$v
    sp "${n}_b_frustum" $A --method baseline --set model.init=frustum &
    sp "${n}_b_sfm" $A --method baseline --set model.init=sfm &
    sp "${n}_b_stereo" $A --method baseline --set model.init=stereo &
    sp "${n}_b_ss" $A --method baseline &
    sp "${n}_b_ssr" $A --method baseline --set model.init_random=20000 &
    sp "${n}_f_ss" $A --method full &
  done; done
  F="--data llff --data-root $D --iterations 3000 --set train.checkpoint_every=0"
  sp fern_b $F --method baseline &
  sp fern_b_ss $F --method baseline --set model.init=sfm+stereo &
  sp fern_f_ss $F --method full --set model.init=sfm+stereo &
  T="--data dtu --data-root $D --iterations 3000 --set train.checkpoint_every=0"
  sp dtu_b $T --method baseline &
  sp dtu_b_ss $T --method baseline --set model.init=sfm+stereo &
  ;;
b)  # a's runs that matter most, fewer at once
  for sc in castle_p30 herz_jesus_p25; do for v in 3 9; do
    A="--data $D/$sc --downscale 8 --views $v --iterations 3000 --set train.checkpoint_every=0"
    n=${sc:0:1}$v
    sp "${n}_b_ss" $A --method baseline &
    sp "${n}_f_ss" $A --method full &
  done; done
  sp c3_b_ssr --data "$D/castle_p30" --downscale 8 --views 3 --iterations 3000 --method baseline --set model.init_random=20000 &
  sp h3_b_stereo --data "$D/herz_jesus_p25" --downscale 8 --views 3 --iterations 3000 --method baseline --set model.init=stereo &
  sp fern_b_ss --data llff --data-root "$D" --iterations 3000 --method baseline --set model.init=sfm+stereo &
  sp dtu_b_ss --data dtu --data-root "$D" --iterations 3000 --method baseline --set model.init=sfm+stereo &
  ;;
c)  # which points: SfM alone, stereo alone, stricter stereo, less densification
  for sc in castle_p30 herz_jesus_p25; do for v in 3 9; do
    sp "${sc:0:1}${v}_b_sfm" --data "$D/$sc" --downscale 8 --views $v --iterations 3000 --method baseline \
       --set train.checkpoint_every=0 --set model.init=sfm &
  done; done
  C9="--data $D/castle_p30 --downscale 8 --views 9 --iterations 3000 --method baseline --set train.checkpoint_every=0"
  C3="--data $D/castle_p30 --downscale 8 --views 3 --iterations 3000 --method baseline --set train.checkpoint_every=0"
  sp c9_b_stereo $C9 --set model.init=stereo &
  sp c9_b_strict $C9 --set geometry.stereo.min_consistent=2 --set geometry.stereo.min_score=0.8 --set geometry.stereo.neighbours=3 &
  sp c9_b_g5 $C9 --set strategy.grow_grad2d=0.0005 &
  sp c3_b_g5 $C3 --set strategy.grow_grad2d=0.0005 &
  sp c3_b_sfm_g5 $C3 --set model.init=sfm --set strategy.grow_grad2d=0.0005 &
  sp c9_b_sfm_g5 $C9 --set model.init=sfm --set strategy.grow_grad2d=0.0005 &
  ;;
d)  # capture defaults: SfM points, less densification; SH degree; the full method's pseudo weight / densification
  G="--downscale 8 --iterations 3000 --set train.checkpoint_every=0 --set model.init=sfm --set strategy.grow_grad2d=0.0005"
  C="--data $D/castle_p30 $G"; H="--data $D/herz_jesus_p25 $G"
  sp c3_b $C --views 3 --method baseline --set geometry.min_points=20 &
  sp h3_b $H --views 3 --method baseline &
  sp h9_b $H --views 9 --method baseline &
  sp c3_b_sh1 $C --views 3 --method baseline --set geometry.min_points=20 --set model.sh_degree=1 &
  sp h3_b_sh1 $H --views 3 --method baseline --set model.sh_degree=1 &
  sp c9_f $C --views 9 --method full &
  sp c9_f_pw $C --views 9 --method full --set full.pseudo_weight=0.2 &
  sp c9_f_nd $C --views 9 --method full --set full.densify=false &
  sp c3_f $C --views 3 --method full --set geometry.min_points=20 &
  sp c3_f_pw $C --views 3 --method full --set geometry.min_points=20 --set full.pseudo_weight=0.2 &
  sp h3_f $H --views 3 --method full &
  sp h3_f_pw $H --views 3 --method full --set full.pseudo_weight=0.2 &
  sp h9_f $H --views 9 --method full &
  sp h9_f_pw $H --views 9 --method full --set full.pseudo_weight=0.2 &
  ;;
e1)  # acceptance: images_4, 10,000 it, 3/6/9 views, baseline and full (stopped with SIGINT at T s, checkpointed,
    # resumed by e2); images_8, 3000 it: the 3- and 9-view baselines and full runs of the issue's setting
  T=${T:-540}
  acceptance_i4 "$T"
  for sc in castle_p30 herz_jesus_p25; do for v in 3 9; do
    n=${sc:0:1}$v
    sp "${n}_baseline_i8" --data "$D/$sc" --downscale 8 --views $v --method baseline --iterations 3000 &
    sp "${n}_full_i8" --data "$D/$sc" --downscale 8 --views $v --method full --iterations 3000 &
  done; done
  ;;
e2)  # resume e1's images_4 runs; fern, DTU, lego and the synthetic room with this code; no-densify ablation
  T=${T:-540}
  for d in "$R"/*_i4; do spt "$T" "$(basename "$d")" --resume "$d" & done
  sp fern --data llff --data-root "$D" --iterations 3000 --method compare --jobs 1 &
  sp dtu --data dtu --data-root "$D" --iterations 3000 --method compare --jobs 1 &
  sp synth --method compare --jobs 1 &
  for sc in castle_p30 herz_jesus_p25; do for v in 3 9; do
    sp "${sc:0:1}${v}_full_nd_i8" --data "$D/$sc" --downscale 8 --views $v --method full --iterations 3000 \
       --set full.densify=false &
  done; done
  ;;
e3)  # whatever e2 left unfinished; lego
  T=${T:-540}
  for d in "$R"/*_i4; do [ -f "$d/metrics.json" ] || spt "$T" "$(basename "$d")" --resume "$d" & done
  sp lego --data blender --data-root "$D" --method baseline &
  ;;
esac
wait
python3 bench/gather_runs.py "$R" "$OUT/runs_$P.json" --logs "$OUT/logs_$P.txt"
