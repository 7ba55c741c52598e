#!/usr/bin/env bash
# GPU runs of session 11, after the packed wheels are installed in /tmp/site and the scenes copied to $D.
#   bash bench/gpu_session11.sh PHASE D RUNS
# a: the CUDA rasterizer tests; gsplat's kernels compiled; in the background on the same GPU, runs that check
#    the README's GPU figures against the code with fused Adam (seed 0; README medians over seeds 0-2), the
#    lego run the viewer's screenshot is taken from, and DropGaussian probes for issue 14 (lego, fern, DTU).
# b: the timed measurements, nothing else on the GPU: the viewer's frame rate (issue 18), bench/rasterizer.py
#    against gsplat with its per-kernel profile, and bench/train_speed.py on fern (issue 15).
# c: issue 14's switch table (bench/suite.py --preset switches), seed 0: the baseline, DropGaussian, opacity noise,
#    the scale regulariser and the full method on fern, DTU and the captures at 3 and 9 views, all at once.
# d: the same preset's CoR-GS rows (train.co_reg, 4 renders a step) at 3 views, and lego's opacity noise / scale
#    regulariser (10,000 iterations).
set -u
P=$1; D=$2; R=$3; mkdir -p "$R" "$OUT"
GPUS=1; source bench/gpu_runs.sh
case $P in
a)
  python3 -m pip install -q --no-index --no-deps --target /tmp/site .device/gsplat/*.whl
  D8="--data-root $D"
  spt 500 lego_b --method baseline --data blender $D8 &
  spt 500 lego_d2 --method baseline --data blender $D8 --set train.drop_rate=0.2 &
  spt 500 lego_d1 --method baseline --data blender $D8 --set train.drop_rate=0.1 &
  spt 500 fern_b --method baseline --data llff $D8 --iterations 3000 &
  spt 500 fern_d2 --method baseline --data llff $D8 --iterations 3000 --set train.drop_rate=0.2 &
  spt 500 fern_f --method full --data llff $D8 --iterations 3000 &
  spt 500 dtu_b --method baseline --data dtu $D8 --iterations 3000 &
  spt 500 dtu_f --method full --data dtu $D8 --iterations 3000 &
  spt 500 dtu_d2 --method baseline --data dtu $D8 --iterations 3000 --set train.drop_rate=0.2 &
  for sc in castle_p30 herz_jesus_p25; do for v in 3 9; do
    spt 500 "${sc:0:1}${v}_b" --method baseline --data "$D/$sc" --downscale 8 --views $v --iterations 3000 &
  done; done
  WARPGS_TEST_DEVICES=cuda timeout 240 python3 -m pytest -q -p no:cacheprovider tests/test_rasterizer.py \
    > "$OUT/tests_cuda.log" 2>&1; echo "tests rc=$?"; tail -3 "$OUT/tests_cuda.log"
  MAX_JOBS=16 TORCH_CUDA_ARCH_LIST=9.0 timeout 300 python3 -c "
import torch, gsplat
m = torch.rand(100, 3, device='cuda'); q = torch.nn.functional.normalize(torch.rand(100, 4, device='cuda'), dim=-1)
s = torch.rand(100, 3, device='cuda') * 0.01; o = torch.rand(100, device='cuda'); c = torch.rand(100, 3, device='cuda')
K = torch.tensor([[100., 0, 50], [0, 100., 50], [0, 0, 1]], device='cuda')[None]
V = torch.eye(4, device='cuda')[None]; V[0, 2, 3] = 2
img, _, _ = gsplat.rasterization(m, q, s, o, c, V, K, 100, 100); print('gsplat compiled', img.shape)
" > "$OUT/gsplat_build.log" 2>&1; echo "gsplat rc=$?"
  wait
  python3 bench/gather_runs.py "$R" "$OUT/runs_a.json" --logs "$OUT/logs_a.txt"
  if [ -f "$R/lego_b/point_cloud.ply" ]; then
    tar cf - -C "$R" lego_b/point_cloud.ply lego_b/config.yaml lego_b/metrics.json | xz -T0 -6 > /tmp/lego.tar.xz
    split -b 15000000 -d -a 1 /tmp/lego.tar.xz "$OUT/lego_b.tar.xz."
  fi
  ls -la "$OUT"
  ;;
b)
  export MAX_JOBS=16 TORCH_CUDA_ARCH_LIST=9.0
  python3 bench/viewer_fps.py --device cuda --out "$OUT/viewer_fps_cuda.json" 2>&1 | tail -4
  [ -f "$R/lego_b/point_cloud.ply" ] && python3 bench/viewer_fps.py --device cuda --ply "$R/lego_b/point_cloud.ply" \
    --out "$OUT/viewer_fps_cuda_lego.json" 2>&1 | tail -2
  timeout 200 python3 bench/rasterizer.py --out "$OUT/rasterizer_cuda.json" --profile > "$OUT/rasterizer.log" 2>&1
  echo "rasterizer rc=$?"; tail -25 "$OUT/rasterizer.log"
  timeout 330 python3 bench/train_speed.py --data-root "$D" --set model.init=frustum \
    --loops warpgs_trainer,plain_warpgs,plain_gsplat,warpgs_trainer_sync1 --out "$OUT/train_speed_cuda.json" \
    > "$OUT/train_speed.log" 2>&1; echo "train_speed rc=$?"; tail -15 "$OUT/train_speed.log"
  ;;
c|d)
  if [ "$P" = c ]; then
    SC=fern_3v,dtu65_3v,castle_p30_3v,herz_jesus_p25_3v,castle_p30_9v,herz_jesus_p25_9v
    ONLY=baseline,baseline+drop,baseline+opacity_noise,baseline+scale_reg,full
  else
    SC=fern_3v,dtu65_3v,castle_p30_3v,herz_jesus_p25_3v,lego_8v
    ONLY=baseline+co_reg,baseline+opacity_noise,baseline+scale_reg
  fi
  mkdir -p "$OUT/sw"; [ -f "$R/sw_results.json" ] && cp "$R/sw_results.json" "$OUT/sw/results.json"
  timeout -s INT "${T:-540}" python3 bench/suite.py --device cuda --data-root "$D" --preset switches --scenes "$SC" \
    --only "$ONLY" --seeds 0 --jobs 30 --out "$OUT/sw" --work "$R/sw" > "$OUT/suite_$P.log" 2>&1
  echo "suite rc=$?"
  cp "$OUT/sw/results.json" "$R/sw_results.json" 2>/dev/null
  python3 bench/suite.py --summary-only --preset switches --out "$OUT/sw" >> "$OUT/suite_$P.log" 2>&1
  grep -E "PSNR|suite:" "$OUT/suite_$P.log" | tail -45
  ;;
esac
