#!/usr/bin/env bash
# GPU runs of session 17 (issue 15), after the packed wheels are installed in /tmp/site and the scenes copied to $D.
#   T=seconds bash bench/gpu_session17.sh PHASE D RUNS
# c: correctness first: the CUDA tests of the rasterizer and the optimiser (tests/test_rasterizer.py,
#    tests/test_sync.py), fern's baseline trained (3 views, 3000 it, frustum start, as train_speed; its PLY is the
#    trained model of r), then .device/s17/compare_bwd.py: the new backward accumulation (reduce-scatter) and SH
#    kernels against HEAD's, gradients bit for bit, on random Gaussians and on that model.
# r: bench/rasterizer.py --profile: the three random configurations (the first again at the end: the first one
#    measured in a process has come out slow), then the trained model at 1x, 2x and 3x fern's
#    test view; per-kernel tables of warpgs and gsplat.
# s: bench/train_speed.py (the trainer, the plain warpgs loop, gsplat), 3 repeats interleaved, then
#    bench/host_profile.py --busy (cumulative, the three loops): where the host time goes and the GPU's busy share.
# l: issue 14: lego (8 views, 10,000 it) with DropGaussian + opacity noise 0.8 (the best setting so far, 23.90) and
#    one change each: SH degree 1, SH degree 0, grow_grad2d 0.0004, init_num 10,000; seeds 0-2, all at once
#    (the blender scene copied to $D/blender_lego first).
set -u
P=$1; D=$2; R=$3; shift 3; mkdir -p "$R" "$OUT"
export PYTHONPATH=/tmp/site:$PWD PYTHONUNBUFFERED=1 OMP_NUM_THREADS=1 MKL_NUM_THREADS=1
export MAX_JOBS=16 TORCH_CUDA_ARCH_LIST=9.0
python3 -m pip install -q --no-index --no-deps --target /tmp/site .device/gsplat/*.whl 2>/dev/null
fern_base() {
  [ -f "$R/fern_base/point_cloud.ply" ] || python3 -m warpgs.pipelines.sparse --method baseline --data llff \
    --data-root "$D" --iterations 3000 --set model.init=frustum --device cuda --no-progress --out "$R/fern_base" \
    > "$OUT/fern_base.log" 2>&1
  tail -2 "$OUT/fern_base.log"
}
case $P in
c)
  timeout ${T:-300} python3 -m pytest -q -x tests/test_rasterizer.py tests/test_sync.py -k "cuda or adam or masked" \
    2>&1 | tail -5 | tee "$OUT/tests_cuda.log"
  fern_base
  python3 .device/s17/compare_bwd.py "$R/fern_base/point_cloud.ply" "$D" 2>&1 | grep -v "^Module\|^Warp" \
    | tee "$OUT/compare_bwd.log"
  ;;
r)
  timeout ${T:-500} python3 bench/rasterizer.py --profile --warmup 20 --iters 50 --out "$OUT/rasterizer_cuda.json" \
    --configs 138766x648x420,256000x1280x720,1000000x1920x1080,138766x648x420 2>&1 \
    | tee "$OUT/rasterizer.log" | grep -E "Gaussians|  warpgs|  gsplat |ratio|wrote"
  fern_base
  timeout ${T:-500} python3 bench/rasterizer.py --ply "$R/fern_base/point_cloud.ply" --data llff --data-root "$D" \
    --scales 1,2,3 --warmup 20 --iters 50 --profile --out "$OUT/rasterizer_cuda_trained.json" 2>&1 \
    | tee "$OUT/rasterizer_trained.log" | grep -E "Gaussians|  warpgs|  gsplat |ratio|wrote"
  ;;
s)
  timeout ${T:-560} python3 bench/train_speed.py --data-root "$D" --set model.init=frustum --repeats 3 \
    --loops warpgs_trainer,plain_warpgs,plain_gsplat \
    --out "$OUT/train_speed_cuda.json" > "$OUT/train_speed.log" 2>&1; echo "train_speed rc=$?"
  tail -8 "$OUT/train_speed.log"
  timeout 200 python3 bench/host_profile.py --data-root "$D" --set model.init=frustum --sort cumulative --top 40 \
    --busy --loops warpgs_trainer,plain_warpgs,plain_gsplat --out "$OUT/host_profile.txt" 2>&1 \
    | grep -E "===|busy" ; echo "host_profile rc=$?"
  ;;
l)
  lego() {
    local name=$1 seed=$2; shift 2
    [ -f "$R/$name/metrics.json" ] && return 0
    timeout -s INT ${T:-540} python3 -m warpgs.pipelines.sparse --method baseline --data blender --scene lego \
      --views 8 --data-root "$D" --device cuda --no-progress --seed "$seed" --set train.drop_rate=0.2 \
      --set train.opacity_noise=0.8 --out "$R/$name" "$@" > "$R/$name.log" 2>&1
    echo "$name rc=$? $(grep -h 'test: PSNR' "$R/$name.log" | tail -1)"
  }
  export -f lego; export R D T
  for s in 0 1 2; do
    echo "lego_noise_s$s $s"
    echo "lego_sh1_s$s $s --set model.sh_degree=1"
    echo "lego_sh0_s$s $s --set model.sh_degree=0"
    echo "lego_grad4_s$s $s --set strategy.grow_grad2d=0.0004"
    echo "lego_init10k_s$s $s --set model.init_num=10000"
  done | xargs -P 15 -L 1 bash -c 'lego "$@"' _
  tar cf "$OUT/lego_runs.tar" -C "$R" --exclude=test --exclude=charts --exclude='*.ply' --exclude='checkpoint*.pt' \
    --exclude='*.gif' $(cd "$R" && ls -d lego_* 2>/dev/null)
  ;;
esac
ls -la "$OUT"
