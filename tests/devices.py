"""The Warp devices the kernels' device-parametrised tests run on: the CPU, and CUDA where torch sees a GPU.

``WARPGS_TEST_DEVICES`` (comma-separated, e.g. ``cuda``) restricts them: the GPU machine's packed Warp has no CPU
compiler (``bench/gpu_one.sh`` session_env sets it there)."""

from __future__ import annotations

import os

import torch

DEVICES = os.environ.get("WARPGS_TEST_DEVICES", "cpu" + (",cuda" if torch.cuda.is_available() else "")).split(",")
