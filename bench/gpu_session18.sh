#!/usr/bin/env bash
# GPU runs of session 18 (issue 15: the training step as a CUDA graph), after the packed wheels are installed in
# /tmp/site and the scenes copied to $D.
#   T=seconds bash bench/gpu_session18.sh PHASE D RUNS
# g: the CUDA tests of the rasterizer (fixed-capacity render included) and of the optimiser and guard, then
#    bench/graph_check.py: the captured rasterizer and the trainer with and without graphs, bit for bit (fern).
# r: bench/rasterizer.py (no graphs there: one rasterize call forward and backward): the three random configurations
#    (the first again at the end), then fern's baseline trained (3 views, 3000 it, frustum start; graphs on) and its
#    Gaussians at 1x, 2x and 3x the test view.
# s: bench/train_speed.py: the trainer (graphs on, the default), the plain warpgs loop, gsplat and the trainer
#    without graphs, 3 repeats interleaved.
set -u
P=$1; D=$2; R=$3; shift 3; mkdir -p "$R" "$OUT"
export PYTHONPATH=/tmp/site:$PWD PYTHONUNBUFFERED=1 OMP_NUM_THREADS=1 MKL_NUM_THREADS=1
export MAX_JOBS=16 TORCH_CUDA_ARCH_LIST=9.0 WARPGS_TEST_DEVICES=cuda
source "$(dirname "${BASH_SOURCE[0]}")/gpu_one.sh"
case $P in
g)
  timeout ${T:-200} python3 -m pytest -q -x tests/test_rasterizer.py tests/test_sync.py -k "cuda or adam or masked or capacity" \
    2>&1 | tail -4 | tee "$OUT/tests_cuda.log"
  timeout ${T:-300} python3 bench/graph_check.py --data-root "$D" --iterations ${ITERS:-1000} \
    --out "$OUT/graph_check_cuda.json" 2>&1 | grep -v "^Module\|^Warp" | tee "$OUT/graph_check.log" | tail -40
  ;;
r)
  rasterizer_runs --warmup 20 --iters 50
  ;;
s)
  python3 -m pip install -q --no-index --no-deps --target /tmp/site .device/gsplat/*.whl 2>/dev/null
  timeout ${T:-560} python3 bench/train_speed.py --data-root "$D" --set model.init=frustum --repeats ${REPEATS:-3} \
    --loops warpgs_trainer,plain_warpgs,plain_gsplat,warpgs_trainer_eager \
    --out "$OUT/train_speed_cuda.json" > "$OUT/train_speed.log" 2>&1; echo "train_speed rc=$?"
  tail -14 "$OUT/train_speed.log"
  ;;
esac
ls -la "$OUT"
