#!/usr/bin/env bash
# GPU runs of session 15, after the packed wheels are installed in /tmp/site and the scenes copied to $D.
#   T=seconds bash bench/gpu_session15.sh PHASE D RUNS
# a: issue 13 at 384x256, 3000 iterations, seeds 0-2, the six capture cases (castle_p30 / herz_jesus_p25 at 3,
#    6, 9 views), over the session-14 capture defaults (configs/nerfstudio.yaml: far field, path clearance 0.2):
#    vc_*: train.view_clearance 0.5, baseline and full (the three-seed table session 14 left as the next step);
#    ed_*: the full method with full.early_depth (the inputs' plane-sweep depth prior from the first step).
# c: the full method without its depth terms: nd_* full.depth_weight=0 and full.input_depth_weight=0; ni_* only
#    full.input_depth_weight=0 (a's ed_* lost 2-4 dB at castle 6 / 9 views), 384x256, seeds 0-2, the six cases.
# d: more pseudo-view supervision: pw_* full.pseudo_weight=2; bf_* full.baseline_fraction=0.25 (pseudo views from
#    step 750 instead of 1200), 384x256, seeds 0-2, the six cases.
# s: issue 15's ratios with this code (no speed change since session 13): bench/rasterizer.py against gsplat 1.5.3
#    (.device/gsplat) and bench/train_speed.py on fern (3 views, 3000 it, 50,000 frustum Gaussians), 3 repeats
#    (session 15 gave it 300 s, which ran out during the third repeat: now 450 s).
# k: (for the next session) bench/train_speed.py with the loop warpgs_trainer_kernels (train.guard_kernels; since session
#    16 the default, and the loop that compares is warpgs_trainer_torch_guard) beside
#    the trainer, the plain warpgs loop and gsplat, 3 repeats interleaved, alone in one call.
# Each run: bench/gpu_one.sh's one (python -m warpgs.pipelines.sparse, resumed when a call's time ran out).
# The default runs these are compared with: session 14's pcff_* (bench/gpu_session14.sh c).
set -u
P=$1; D=$2; R=$3; mkdir -p "$R" "$OUT"
export PYTHONPATH=/tmp/site:$PWD PYTHONUNBUFFERED=1 OMP_NUM_THREADS=1 MKL_NUM_THREADS=1
source "$(dirname "${BASH_SOURCE[0]}")/gpu_one.sh"
variants() {  # variants G1 "SETS1" G2 "SETS2": the full method with each, the six cases, seeds 0-2, ${JOBS:-36} at once
  export R D T END=$(( $(date +%s) + ${T:-540} ))
  for s in 0 1 2; do for sc in castle_p30 herz_jesus_p25; do for v in 3 6 9; do
    echo "$1_${sc%%_*}${v}_full_s$s full $sc $v $s $2"
    echo "$3_${sc%%_*}${v}_full_s$s full $sc $v $s $4"
  done; done; done | xargs -P ${JOBS:-36} -L 1 bash -c 'one "$@"' _
}
VC="--set train.view_clearance=0.5"
ED="--set full.early_depth=true"
case $P in
a)
  export R D T END=$(( $(date +%s) + ${T:-540} ))
  { for s in 0 1 2; do for sc in castle_p30 herz_jesus_p25; do for v in 3 6 9; do
      c=${sc%%_*}$v
      echo "vc_${c}_full_s$s full $sc $v $s $VC"
      echo "ed_${c}_full_s$s full $sc $v $s $ED"
    done; done; done
    for s in 0 1 2; do for sc in castle_p30 herz_jesus_p25; do for v in 3 6 9; do
      echo "vc_${sc%%_*}${v}_base_s$s baseline $sc $v $s $VC"
    done; done; done; } | xargs -P ${JOBS:-24} -L 1 bash -c 'one "$@"' _
  ;;
c)
  variants nd "--set full.depth_weight=0 --set full.input_depth_weight=0" ni "--set full.input_depth_weight=0"
  ;;
d)
  variants pw "--set full.pseudo_weight=2" bf "--set full.baseline_fraction=0.25"
  ;;
s)
  python3 -m pip install -q --no-index --no-deps --target /tmp/site .device/gsplat/*.whl 2>/dev/null
  export MAX_JOBS=16 TORCH_CUDA_ARCH_LIST=9.0
  timeout 240 python3 bench/rasterizer.py --out "$OUT/rasterizer_cuda.json" > "$OUT/rasterizer.log" 2>&1
  echo "rasterizer rc=$?"; grep -E "Gaussians|warpgs |gsplat |ratio" "$OUT/rasterizer.log"
  timeout 450 python3 bench/train_speed.py --data-root "$D" --set model.init=frustum --repeats 3 \
    --out "$OUT/train_speed_cuda.json" > "$OUT/train_speed.log" 2>&1; echo "train_speed rc=$?"
  tail -8 "$OUT/train_speed.log"
  exit 0
  ;;
k)
  python3 -m pip install -q --no-index --no-deps --target /tmp/site .device/gsplat/*.whl 2>/dev/null
  export MAX_JOBS=16 TORCH_CUDA_ARCH_LIST=9.0
  timeout 560 python3 bench/train_speed.py --data-root "$D" --set model.init=frustum --repeats 3 \
    --loops warpgs_trainer,plain_warpgs,plain_gsplat,warpgs_trainer_torch_guard \
    --out "$OUT/train_speed_cuda_kernels.json" > "$OUT/train_speed_kernels.log" 2>&1; echo "train_speed rc=$?"
  tail -16 "$OUT/train_speed_kernels.log"
  exit 0
  ;;
esac
tar cf "$OUT/runs_$P.tar" -C "$R" --exclude=test --exclude='cycle_*' --exclude=charts --exclude='*.md' \
  --exclude='checkpoint*.pt' --exclude='*.gif' --exclude='*.ply' --exclude='pseudo' .
ls -la "$OUT"
