#!/usr/bin/env bash
# GPU runs of session 30 (issue 13: the full method's gain over the baseline on the captures), after the packed
# wheels are installed in /tmp/site and the scenes copied to $D.
#   T=seconds bash bench/gpu_session30.sh PHASE D RUNS
# b: the captures' 36 runs (both methods, 3/6/9 views, seeds 0-2; prefix b) with the path-floater pass also on the
#    straight lines between the inputs and 9 poses per pair (train.path_floaters_paths=both,
#    train.path_floaters_poses=9), prepared in session 29 (bench/gpu_session29.sh b), plus the full method at 3
#    views (where it gains least: +0.26 castle, +0.05 herz) with 17 poses per trajectory instead of 9
#    (pseudo.trajectory.n_frames=17; prefix x_n17) and the pseudo views' loss x2 (full.pseudo_weight=2; prefix
#    x_pw2; session 29 measured x0.5: +0.37 dB against +0.40). Resumable: a second call finishes what the first
#    could not. Run (one H100): the 48 processes together ran out of GPU memory in 4 runs (their metrics.json said
#    stopped_early out_of_memory at the last good step); those were moved aside and resumed from their checkpoints.
# i: the 12 images_4 runs (768x512, 10,000 it, seed 0, both methods, 3/6/9 views; prefix i) with the captures'
#    default after b (the path-floater pass on both paths, 9 poses): every run completes and writes its metrics, none
#    stops on a divergence (issue 13's first acceptance point; session 28: bench/results/s28/i369.txt). Resumed from
#    the checkpoints by a second call.
# r: (issue 15, with the device time left) bench/rasterizer.py against gsplat 1.5.3 (.device/gsplat) on the issue's three
#    configurations and the first again, then bench/train_speed.py on fern 3 views, 3000 it, DropGaussian 0.2 (the
#    trainer against the gsplat loop), as sessions 20 and 24 ran them.
# f: session 29's phase f (the collapsed castle_p30 9-view runs re-run and diagnosed), bench/gpu_session29.sh f.
set -u
source "$(dirname "${BASH_SOURCE[0]}")/gpu_one.sh"
session_env "$@"; P=$1; D=$2; R=$3; shift 3
export R D T
case $P in
b)
  { for c in castle_p30 herz_jesus_p25; do for v in 3 6 9; do for m in baseline full; do for s in 0 1 2; do
      echo "b_${c}_${v}v_${m}_s$s $m $c $v $s --set train.path_floaters_paths=both --set train.path_floaters_poses=9"
    done; done; done; done
    for c in castle_p30 herz_jesus_p25; do for s in 0 1 2; do
      echo "x_n17_${c}_3v_full_s$s full $c 3 $s --set pseudo.trajectory.n_frames=17"
      echo "x_pw2_${c}_3v_full_s$s full $c 3 $s --set full.pseudo_weight=2"
    done; done; } | xargs -P ${JOBS:-48} -L 1 bash -c 'one "$@"' _ | grep -v "rc=0"
  summary b_ b369.txt
  summary x_ x3.txt
  ;;
i)
  { for c in castle_p30 herz_jesus_p25; do for v in 3 6 9; do for m in baseline full; do
      echo "i_${c}_${v}v_${m}_s0 $m $c $v 0"
    done; done; done; } | DS=4 IT=10000 xargs -P ${JOBS:-12} -L 1 bash -c 'one "$@"' _
  summary i_ i369.txt
  grep -l "TrainingDiverged\|diverged\|out_of_memory" "$R"/i_*.log "$R"/i_*/metrics.json 2>/dev/null | tee "$OUT/i369_stopped.txt"
  ;;
r)
  python3 -m pip install -q --no-index --no-deps --target /tmp/site .device/gsplat/*.whl 2>/dev/null
  timeout ${T:-240} python3 bench/rasterizer.py --warmup 10 --iters 20 --rounds ${ROUNDS:-7} --out "$OUT/rasterizer_cuda.json" \
    --configs 138766x648x420,555000x1280x720,1100000x1920x1080,138766x648x420 2>&1 | tee "$OUT/rasterizer.log" \
    | grep -E "Gaussians|ratio|paired|wrote"
  timeout ${T:-240} python3 bench/train_speed.py --data-root "$D" --out "$OUT/train_speed_cuda.json" --set model.init=frustum \
    --set train.drop_rate=0.2 2>&1 | grep -v "^Module\|^Warp" | tee "$OUT/train_speed.log" | tail -12
  ;;
f)
  bash "$(dirname "${BASH_SOURCE[0]}")/gpu_session29.sh" f "$D" "$R"
  ;;
*) echo "unknown phase $P"; exit 2 ;;
esac
