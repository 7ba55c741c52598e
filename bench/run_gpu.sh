#!/usr/bin/env bash
# What the GPU figures in bench/results/ come from: run on the lent GPU machine (see
# ../shared/device/README.md) after the packed wheels were installed into /tmp/site.
# Installs gsplat 1.5.3 from .device/gsplat, runs the rasterizer tests on CUDA, then the benchmark.
set -uo pipefail
export PYTHONPATH=/tmp/site:$PWD PYTHONUNBUFFERED=1 MAX_JOBS=16 TORCH_CUDA_ARCH_LIST=9.0
out=${OUT:-bench/results}
python3 -m pip install -q --no-index --no-deps --target /tmp/site .device/gsplat/*.whl
nvidia-smi --query-gpu=name,driver_version --format=csv,noheader
WARPGS_TEST_DEVICES=cuda python3 -m pytest -q -p no:cacheprovider tests/test_rasterizer.py 2>&1 | tee "$out/tests_gpu.log" | tail -5
python3 bench/rasterizer.py --out "$out/rasterizer_cuda.json" "$@" 2>&1 | tee "$out/bench_gpu.log"
