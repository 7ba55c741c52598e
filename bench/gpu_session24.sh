#!/usr/bin/env bash
# GPU runs of session 24 (issue 15: the rasterizer within 1.1x gsplat at 138k), after the packed wheels are installed
# in /tmp/site and the scenes copied to $D.
#   T=seconds bash bench/gpu_session24.sh PHASE D RUNS
# t: the rasterizer's CUDA tests (against the oracle, finite differences, the fixed-capacity render), then
#    bench/rasterizer_timeline.py at 138,766 Gaussians 648x420 and 256,000 at 1280x720 (where the GPU idles and what
#    runs, warpgs against gsplat; JSON in $OUT).
# r: bench/rasterizer.py in ROUNDS (default 11) interleaved rounds on the random configurations (the issue's 555K and
#    1.1M too, 138k again at the end); h: bench/rasterizer_host.py at 138k (host time per call, cProfile).
# f: bench/rasterizer.py on fern's trained Gaussians (its baseline trained into $R/fern_base unless it is there) at
#    1x-3x, and bench/graph_check.py on plain fern (with and without CUDA graphs bit for bit).
# s: bench/train_speed.py on fern 3 views, 3000 it (warpgs's trainer against the gsplat loop); session 24 ran it as
#    `s D RUNS --set train.drop_rate=0.2 --set model.init=frustum` (the packed wheels there have no pycolmap).
# (The session's first lease ran t, r and f on a build that kept the Warp-written CUDA forward beside the native one
# and timed both in the same rounds (bench/rasterizer.py --variants then); bench/results/s24/variants/.)
set -u
source "$(dirname "${BASH_SOURCE[0]}")/gpu_one.sh"
session_env "$@"; P=$1; D=$2; R=$3; shift 3
export R D T
python3 -m pip install -q --no-index --no-deps --target /tmp/site .device/gsplat/*.whl 2>/dev/null
case $P in
t)
  timeout ${T:-300} python3 -m pytest -q -x tests/test_rasterizer.py -k cuda 2>&1 | tail -3 | tee "$OUT/tests_cuda.log"
  for c in 138766x648x420 256000x1280x720; do
    IFS=x read -r n w h <<< "$c"
    timeout ${T:-300} python3 bench/rasterizer_timeline.py --gaussians "$n" --width "$w" --height "$h" \
      --out "$OUT/timeline_$c.json" 2>&1 | grep -v "^Module\|^Warp\|CUDA extension\|Warning\|warn" | tee "$OUT/timeline_$c.txt"
  done
  ;;
r)
  CONFIGS=138766x648x420,256000x1280x720,555000x1280x720,1000000x1920x1080,1100000x1920x1080,138766x648x420
  timeout ${T:-400} python3 bench/rasterizer.py --warmup 10 --iters 20 --rounds ${ROUNDS:-11} \
    --out "$OUT/rasterizer_cuda.json" --configs $CONFIGS 2>&1 | tee "$OUT/rasterizer.log" \
    | grep -E "Gaussians|ratio|paired|wrote"
  ;;
h)
  timeout ${T:-200} python3 bench/rasterizer_host.py 2>&1 | grep -v "^Module\|^Warp" > "$OUT/host_profile_138k.txt"
  grep "ms/call" "$OUT/host_profile_138k.txt"
  ;;
f)
  [ -f "$R/fern_base/point_cloud.ply" ] || python3 -m warpgs.pipelines.sparse --method baseline --data llff \
    --data-root "$D" --iterations 3000 --set model.init=frustum --device cuda --no-progress --out "$R/fern_base" \
    > "$OUT/fern_base.log" 2>&1
  tail -2 "$OUT/fern_base.log"
  timeout ${T:-300} python3 bench/rasterizer.py --ply "$R/fern_base/point_cloud.ply" --data llff --data-root "$D" \
    --scales 1,2,3 --warmup 10 --iters 20 --rounds ${ROUNDS:-11} --out "$OUT/rasterizer_cuda_trained.json" \
    2>&1 | tee "$OUT/rasterizer_trained.log" | grep -E "Gaussians|ratio|paired|wrote"
  gc plain
  ;;
s)
  timeout ${T:-400} python3 bench/train_speed.py --data-root "$D" --out "$OUT/train_speed_cuda.json" "$@" 2>&1 \
    | grep -v "^Module\|^Warp" | tee "$OUT/train_speed.log" | tail -15
  ;;
esac
