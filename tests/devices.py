"""The Warp devices the kernels' device-parametrised tests run on: the CPU, and CUDA where torch sees a GPU.

``WARPGS_TEST_DEVICES`` (comma-separated, e.g. ``cuda``) restricts them: a GPU machine whose Warp has no CPU
compiler runs the CUDA half with ``WARPGS_TEST_DEVICES=cuda python -m pytest tests/test_rasterizer.py ...``."""

from __future__ import annotations

import os

import torch

DEVICES = os.environ.get("WARPGS_TEST_DEVICES", "cpu" + (",cuda" if torch.cuda.is_available() else "")).split(",")
