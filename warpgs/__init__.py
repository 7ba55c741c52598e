"""warpgs: sparse-view 3D Gaussian Splatting with test-time video completion, on NVIDIA Warp.

Camera convention (the only one used inside the library; loaders convert at the boundary):
OpenCV axes — x right, y down, z forward. A camera is given by ``viewmat``, the 4x4 world-to-camera
matrix, and ``K``, the 3x3 intrinsics in pixels, with pixel (j, i) covering [j, j+1) x [i, i+1) so its
centre is at (j + 0.5, i + 0.5). Quaternions are (w, x, y, z).
"""

__version__ = "0.1.0"

import os as _os
import platform as _platform

import torch as _torch

# torch picks its CPU kernels by the processor's vector width: on a CPU with AVX-512 its reductions round
# differently from an AVX2 CPU's, so the same CPU command gave other figures on another x86 machine (session 27: the
# no-argument run 19.98 -> 21.84 with AVX-512 kernels, 20.30 -> 22.05 with AVX2 ones, in the same time). Where no
# CUDA device is visible (a CPU run), warpgs asks for the AVX2 kernels on x86 unless ATEN_CPU_CAPABILITY is set
# (``avx512`` gives the wider kernels back). It must be set before torch first dispatches a CPU kernel, so here,
# before any submodule does. GPU runs are left as they were (their figures were measured that way).
CPU_CAPABILITY = "avx2"
if _platform.machine().lower() in ("x86_64", "amd64") and not _torch.cuda.is_available():
    _os.environ.setdefault("ATEN_CPU_CAPABILITY", CPU_CAPABILITY)
