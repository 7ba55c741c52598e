#!/usr/bin/env bash
# GPU runs of session 12, after the packed wheels are installed in /tmp/site and the scenes copied to $D.
#   bash bench/gpu_session12.sh PHASE D RUNS
# a: the timed measurements with the fast launch path, nothing else on the GPU: the CUDA rasterizer tests,
#    bench/rasterizer.py against gsplat with its profile, bench/train_speed.py on fern, and bench/host_profile.py
#    (where the trainer's host time goes) (issue 15).
# b: issue 14's switch suite, seeds 1 and 2 (seed 0 is session 11's, bench/results/suite_cuda_switches): the new
#    default (baseline+drop) and the full method on fern, DTU and the captures at 3 and 9 views, and lego's
#    baseline, +drop and +opacity noise (10,000 iterations). The capture rows are issue 13's 384x256 table.
# c: the same seeds for the plain baseline and +opacity noise on fern, DTU and the captures.
# Results of b and c go to $RUNS/sw*/results.json (kept between calls) and back as one tar in $OUT.
set -u
P=$1; D=$2; R=$3; mkdir -p "$R" "$OUT"
export PYTHONPATH=/tmp/site:$PWD PYTHONUNBUFFERED=1 OMP_NUM_THREADS=1 MKL_NUM_THREADS=1
SIX=fern_3v,dtu65_3v,castle_p30_3v,herz_jesus_p25_3v,castle_p30_9v,herz_jesus_p25_9v
suite() {  # suite OUTDIR SCENES ONLY JOBS
  mkdir -p "$R/$1"
  timeout -s INT "${T:-540}" python3 bench/suite.py --device cuda --data-root "$D" --preset switches --scenes "$2" \
    --only "$3" --seeds 1,2 --jobs "$4" --out "$R/$1" --work "$R/work_$1" > "$R/$1/suite.log" 2>&1
  echo "suite $1 rc=$?"
}
case $P in
a)
  python3 -m pip install -q --no-index --no-deps --target /tmp/site .device/gsplat/*.whl
  export MAX_JOBS=16 TORCH_CUDA_ARCH_LIST=9.0
  WARPGS_TEST_DEVICES=cuda timeout 200 python3 -m pytest -q -p no:cacheprovider tests/test_rasterizer.py \
    tests/test_launch.py > "$OUT/tests_cuda.log" 2>&1; echo "tests rc=$?"; tail -3 "$OUT/tests_cuda.log"
  timeout 240 python3 bench/rasterizer.py --out "$OUT/rasterizer_cuda.json" --profile > "$OUT/rasterizer.log" 2>&1
  echo "rasterizer rc=$?"; grep -E "Gaussians|warpgs |gsplat |ratio" "$OUT/rasterizer.log"
  timeout 200 python3 bench/train_speed.py --data-root "$D" --set model.init=frustum \
    --out "$OUT/train_speed_cuda.json" > "$OUT/train_speed.log" 2>&1; echo "train_speed rc=$?"
  tail -8 "$OUT/train_speed.log"
  timeout 100 python3 bench/host_profile.py --data-root "$D" --set model.init=frustum --out "$OUT/host_profile.txt" \
    > /dev/null 2>&1; echo "host_profile rc=$?"; grep "===" "$OUT/host_profile.txt"
  ;;
b)
  suite sw "$SIX" baseline+drop,full 24 &
  suite swl lego_8v baseline,baseline+drop,baseline+opacity_noise 6 &
  wait
  tar cf "$OUT/suite_b.tar" -C "$R" sw/results.json sw/suite.log swl/results.json swl/suite.log
  grep -h "PSNR" "$R/sw/suite.log" "$R/swl/suite.log" | tail -40
  ;;
c)
  suite sw2 "$SIX" baseline,baseline+opacity_noise 24 &
  suite sw2l lego_8v baseline,baseline+opacity_noise 4 &
  wait
  tar cf "$OUT/suite_c.tar" -C "$R" sw2/results.json sw2/suite.log sw2l/results.json sw2l/suite.log
  grep -h "PSNR" "$R/sw2/suite.log" "$R/sw2l/suite.log" | tail -30
  ;;
esac
