#!/usr/bin/env bash
# GPU runs of session 13, after the packed wheels are installed in /tmp/site and the scenes copied to $D.
#   bash bench/gpu_session13.sh PHASE D RUNS
# a: issue 15, nothing else on the GPU: the CUDA rasterizer tests with the compositing kernels' shared-memory
#    batches read as float4, bench/rasterizer.py against gsplat with that layout and (the file before it,
#    .ab/rasterize_old.py, swapped in) without it, and bench/train_speed.py on fern.
# b: issue 13: the full method on the captures with the growth budget that waits for the strategy's first
#    growth period (castle_p30 / herz_jesus_p25 at 3, 6 and 9 views, 384x256, 3000 it, seeds 0-2), and the
#    default baseline at 6 views. A call stopped by its time limit is continued by the next (--resume).
# c: issue 14: dropout and opacity noise together (Co-Adaptation) on fern, DTU, lego and the captures at 3 and
#    9 views, and the full method with dropout on DTU, seeds 0-2.
# d: issue 15 again, nothing else on the GPU, after the backward compiled per (fixed, with_depth) with launch
#    bounds (64 registers, 4 blocks an SM; the forward 48, 5 blocks), snapshots kept on the GPU and one
#    found_inf for every optimiser: the CUDA rasterizer tests, bench/rasterizer.py, the Nsight Compute
#    summary of the compositing kernels, bench/train_speed.py over 3 interleaved repeats, the host profile.
# Results go to $RUNS/<part>/results.json (kept between calls) and back as one tar in $OUT.
set -u
P=$1; D=$2; R=$3; mkdir -p "$R" "$OUT"
export PYTHONPATH=/tmp/site:$PWD PYTHONUNBUFFERED=1 OMP_NUM_THREADS=1 MKL_NUM_THREADS=1
CAP=castle_p30_3v,castle_p30_6v,castle_p30_9v,herz_jesus_p25_3v,herz_jesus_p25_6v,herz_jesus_p25_9v
suite() {  # suite OUTDIR SCENES ONLY JOBS
  mkdir -p "$R/$1"
  timeout -s INT "${T:-540}" python3 bench/suite.py --device cuda --data-root "$D" --preset switches --scenes "$2" \
    --only "$3" --seeds 0,1,2 --jobs "$4" --out "$R/$1" --work "$R/work_$1" >> "$R/$1/suite.log" 2>&1
  echo "suite $1 rc=$?"
}
case $P in
a)
  which ncu nsys 2>&1 | head -2
  python3 -m pip install -q --no-index --no-deps --target /tmp/site .device/gsplat/*.whl
  export MAX_JOBS=16 TORCH_CUDA_ARCH_LIST=9.0
  WARPGS_TEST_DEVICES=cuda timeout 200 python3 -m pytest -q -p no:cacheprovider tests/test_rasterizer.py \
    tests/test_launch.py > "$OUT/tests_cuda.log" 2>&1; echo "tests rc=$?"; tail -3 "$OUT/tests_cuda.log"
  timeout 240 python3 bench/rasterizer.py --out "$OUT/rasterizer_cuda.json" --profile > "$OUT/rasterizer.log" 2>&1
  echo "rasterizer rc=$?"; grep -E "Gaussians|warpgs |gsplat |ratio" "$OUT/rasterizer.log"
  cp warpgs/kernels/rasterize.py /tmp/rasterize_new.py && cp .ab/rasterize_old.py warpgs/kernels/rasterize.py
  timeout 120 python3 bench/rasterizer.py --out "$OUT/rasterizer_cuda_old.json" > "$OUT/rasterizer_old.log" 2>&1
  echo "rasterizer (old batch layout) rc=$?"; grep -E "Gaussians|warpgs |ratio" "$OUT/rasterizer_old.log"
  cp /tmp/rasterize_new.py warpgs/kernels/rasterize.py
  timeout 200 python3 bench/train_speed.py --data-root "$D" --set model.init=frustum \
    --out "$OUT/train_speed_cuda.json" > "$OUT/train_speed.log" 2>&1; echo "train_speed rc=$?"
  tail -8 "$OUT/train_speed.log"
  ;;
b)
  suite s13 "$CAP" full 18 &
  suite s13b castle_p30_6v,herz_jesus_p25_6v baseline+drop 6 &
  wait
  tar cf "$OUT/suite_b.tar" -C "$R" s13/results.json s13/suite.log s13b/results.json s13b/suite.log
  grep -h "PSNR\|failed" "$R/s13/suite.log" "$R/s13b/suite.log" | tail -30
  ;;
c)
  suite s13c fern_3v,dtu65_3v,castle_p30_3v,castle_p30_9v,herz_jesus_p25_3v,herz_jesus_p25_9v \
    baseline+drop+opacity_noise 18 &
  suite s13d dtu65_3v full+drop 3 &
  suite s13l lego_8v baseline+drop+opacity_noise 3 &
  wait
  tar cf "$OUT/suite_c.tar" -C "$R" s13c/results.json s13c/suite.log s13d/results.json s13d/suite.log \
    s13l/results.json s13l/suite.log
  grep -h "PSNR\|failed" "$R/s13c/suite.log" "$R/s13d/suite.log" "$R/s13l/suite.log" | tail -30
  ;;
d)
  python3 -m pip install -q --no-index --no-deps --target /tmp/site .device/gsplat/*.whl 2>/dev/null
  export MAX_JOBS=16 TORCH_CUDA_ARCH_LIST=9.0
  WARPGS_TEST_DEVICES=cuda timeout 200 python3 -m pytest -q -p no:cacheprovider tests/test_rasterizer.py \
    > "$OUT/tests_cuda.log" 2>&1; echo "tests rc=$?"; tail -1 "$OUT/tests_cuda.log"
  timeout 240 python3 bench/rasterizer.py --out "$OUT/rasterizer_cuda.json" --profile > "$OUT/rasterizer.log" 2>&1
  echo "rasterizer rc=$?"; grep -E "Gaussians|warpgs |gsplat |ratio" "$OUT/rasterizer.log"
  timeout 150 /usr/local/cuda/bin/ncu --kernel-name regex:"rasterize_(fwd|bwd)_cuda|rasterize_to_pixels" \
    --launch-skip 8 --launch-count 8 --section SpeedOfLight --section Occupancy --section LaunchStats \
    python3 bench/rasterizer.py --configs 138766x648x420 --iters 2 --warmup 2 --out /tmp/ncu_r.json > "$OUT/ncu.txt" 2>&1
  grep -E "^  [a-z_]+.*\(|Duration|Registers Per|Achieved Occupancy|Local Memory" "$OUT/ncu.txt" | head -40
  timeout 300 python3 bench/train_speed.py --data-root "$D" --set model.init=frustum --repeats 3 \
    --out "$OUT/train_speed_cuda.json" > "$OUT/train_speed.log" 2>&1; echo "train_speed rc=$?"
  tail -8 "$OUT/train_speed.log"
  ;;
esac
