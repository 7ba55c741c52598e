#!/usr/bin/env bash
# Issue 17's GPU acceptance, on a lent 2-GPU host (nvidia-h200-x2): the batch runner (warpgs.pipelines.batch, Ray)
# runs the same 8 runs (castle_p30 and herz_jesus_p25, 3 and 9 views, baseline and full, seed 0, 768x512,
# 3,000 iterations) on one GPU, then on two; bench/batch_scaling.py compares the wall times (target: 2 GPUs
# <= 0.6x 1 GPU) and every run's metrics (target: identical).
#
# Packages: from the main checkout (pack.sh writes .git/info/exclude, which a git worktree does not have),
#   ../shared/device/pack.sh full ray==2.60.0 msgpack protobuf jsonschema jsonschema-specifications referencing \
#     rpds-py attrs click
# (ray's own dependencies the GPU image lacks; ray's cp312 wheel is 79 MB, so it is split into parts too), then
# copy the parts there one call each as ../shared/device/README.md says, the last with install.sh. The scenes:
# copy ../shared/data/castle_p30 and herz_jesus_p25 (images_4 and transforms.json, 12 MB) into .gpudata/ and
# carry it. Then, one call per phase (each well within the 10-minute limit of a call):
#   bash bench/gpu_batch.sh 1 .gpudata RUNS      # the 8 runs on one GPU (about 5 minutes expected)
#   bash bench/gpu_batch.sh 2 .gpudata RUNS      # the same on two GPUs
#   bash bench/gpu_batch.sh compare .gpudata RUNS  # -> $OUT/batch_scaling.json (and the two results folders)
set -u
P=$1; D=$2; R=$3; mkdir -p "$R"
export PYTHONPATH=/tmp/site:$PWD PYTHONUNBUFFERED=1 OMP_NUM_THREADS=1 MKL_NUM_THREADS=1
case $P in
1) python3 bench/batch_scaling.py run --gpus 1 --data-root "$D" --out "$R/gpu1" ;;
2) python3 bench/batch_scaling.py run --gpus 2 --data-root "$D" --out "$R/gpu2" ;;
compare)
  python3 bench/batch_scaling.py compare "$R/gpu1" "$R/gpu2" --json "$OUT/batch_scaling.json"
  for g in gpu1 gpu2; do
    mkdir -p "$OUT/$g" && cp "$R/$g"/results.* "$R/$g"/*.png "$OUT/$g/" 2>/dev/null
    tail -n 40 "$R/$g"/logs/*.log > "$OUT/$g/logs_tail.txt" 2>/dev/null
  done ;;
*) echo "usage: bash bench/gpu_batch.sh 1|2|compare SCENES RUNS" >&2; exit 2 ;;
esac
