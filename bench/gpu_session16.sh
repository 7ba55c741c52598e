#!/usr/bin/env bash
# GPU runs of session 16, after the packed wheels are installed in /tmp/site and the scenes copied to $D.
#   T=seconds bash bench/gpu_session16.sh PHASE D RUNS [ARGS]
# k: issue 15: bench/train_speed.py with the loop warpgs_trainer_kernels (train.guard_kernels) beside the trainer,
#    the plain warpgs loop and gsplat (fern, 3 views, 3000 it, 50,000 frustum Gaussians), 3 repeats interleaved,
#    alone in one call (session 15 prepared it and had no device time left). It ran while train.guard_kernels was
#    off by default (its loop was then warpgs_trainer_kernels); with the default on, k and s run the same.
# q: issue 13: bench/pseudo_quality.py on the six capture cases (castle_p30 / herz_jesus_p25 at 3, 6, 9 views,
#    384x256, the baseline phase of a 3000-iteration full run, seed 0), every pseudo-view variant it knows.
# s: issue 15 with train.guard_kernels on by default: bench/train_speed.py (the trainer, the plain warpgs loop, gsplat,
#    the trainer with the torch-op guard), 3 repeats interleaved, alone in one call.
# r: issue 15: bench/rasterizer.py on a trained model's Gaussians: fern's baseline (3 views, 3000 it, frustum start,
#    as train_speed), its point_cloud.ply (SH degree 3) seen from fern's first test view at 1x, 2x and 3x its size
#    (SCALES=1,2,1 RARGS="--warmup 20 --iters 50 --profile": the repeat of 1x after 2x, the kernels' table).
# v G1 "SETS1" [G2 "SETS2"]: issue 13: the full method with each group of --set options, the six cases, seeds 0-2
#    (${JOBS:-36} runs at once); compared with session 14's default runs (pcff_*).
set -u
P=$1; D=$2; R=$3; shift 3; mkdir -p "$R" "$OUT"
export PYTHONPATH=/tmp/site:$PWD PYTHONUNBUFFERED=1 OMP_NUM_THREADS=1 MKL_NUM_THREADS=1
source "$(dirname "${BASH_SOURCE[0]}")/gpu_one.sh"
case $P in
k|s)
  python3 -m pip install -q --no-index --no-deps --target /tmp/site .device/gsplat/*.whl 2>/dev/null
  export MAX_JOBS=16 TORCH_CUDA_ARCH_LIST=9.0
  timeout ${T:-560} python3 bench/train_speed.py --data-root "$D" --set model.init=frustum --repeats 3 \
    --loops warpgs_trainer,plain_warpgs,plain_gsplat,warpgs_trainer_torch_guard \
    --out "$OUT/train_speed_cuda_$P.json" > "$OUT/train_speed_$P.log" 2>&1; echo "train_speed rc=$?"
  tail -16 "$OUT/train_speed_$P.log"
  exit 0
  ;;
r)
  python3 -m pip install -q --no-index --no-deps --target /tmp/site .device/gsplat/*.whl 2>/dev/null
  export MAX_JOBS=16 TORCH_CUDA_ARCH_LIST=9.0
  [ -f "$R/fern_base/point_cloud.ply" ] || python3 -m warpgs.pipelines.sparse --method baseline --data llff \
    --data-root "$D" --iterations 3000 --set model.init=frustum --device cuda --no-progress --out "$R/fern_base" \
    > "$OUT/fern_base.log" 2>&1
  tail -3 "$OUT/fern_base.log"
  timeout ${T:-400} python3 bench/rasterizer.py --ply "$R/fern_base/point_cloud.ply" --data llff --data-root "$D" \
    --scales ${SCALES:-1,2,3} ${RARGS:-} --out "$OUT/rasterizer_cuda_trained.json" 2>&1 \
    | tee "$OUT/rasterizer_trained.log" | grep -v diagnosis | grep -E "Gaussians|warpgs|gsplat|ratio|wrote"
  exit 0
  ;;
q)
  timeout ${T:-540} python3 bench/pseudo_quality.py --data-root "$D" --device cuda --cache "$R/pq_cache" \
    --out "$OUT/pseudo_quality.json" "$@" 2>&1 | grep -v "^warpgs" | tee "$OUT/pseudo_quality.log"
  exit 0
  ;;
v)
  export R D T END=$(( $(date +%s) + ${T:-540} ))
  while [ $# -ge 2 ]; do
    g=$1 sets=$2; shift 2
    for s in 0 1 2; do for sc in castle_p30 herz_jesus_p25; do for v in 3 6 9; do
      echo "${g}_${sc%%_*}${v}_full_s$s full $sc $v $s $sets"
    done; done; done
  done | xargs -P ${JOBS:-36} -L 1 bash -c 'one "$@"' _
  ;;
esac
tar cf "$OUT/runs_$P.tar" -C "$R" --exclude=test --exclude='cycle_*' --exclude=charts --exclude='*.md' \
  --exclude='checkpoint*.pt' --exclude='*.gif' --exclude='*.ply' --exclude='pseudo' --exclude=pq_cache .
ls -la "$OUT"
