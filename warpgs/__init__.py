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
# differently from an AVX2 CPU's, so the same CPU command gave other figures on another x86 machine (the
# no-argument run 19.98 -> 21.84 with AVX-512 kernels, 20.30 -> 22.05 with AVX2 ones, in the same time). Where no
# CUDA device is visible (a CPU run), warpgs asks for the AVX2 kernels on x86 unless ATEN_CPU_CAPABILITY is set
# (``avx512`` gives the wider kernels back). It must be set before torch first dispatches a CPU kernel, so here,
# before any submodule does. GPU runs are left as they were (their figures were measured that way).
#
# The same holds for MKL, the BLAS of torch's x86 wheels (matrix products: torch.cdist's distances for the initial
# scales, the weight-free video prior's DCT): it picks its kernels by the processor too, and a product rounds
# differently on another: on a 2-core Intel Xeon with AVX-512 the initial scales of the no-argument run
# differed in the last bits from those MKL's AVX2 kernels give, and the baseline ended at 19.62 instead of 20.78
# (full 22.47 / 22.52). MKL's conditional numerical reproducibility ``COMPATIBLE`` branch gives the same results on
# every x86 processor (Intel's documentation), so CPU runs ask for it; ``MKL_CBWR`` set by the user is kept. Like
# ATEN_CPU_CAPABILITY, MKL reads it on its first call, so it is set here.
CPU_CAPABILITY = "avx2"
MKL_BRANCH = "COMPATIBLE"
if _platform.machine().lower() in ("x86_64", "amd64") and not _torch.cuda.is_available():
    _os.environ.setdefault("ATEN_CPU_CAPABILITY", CPU_CAPABILITY)
    _os.environ.setdefault("MKL_CBWR", MKL_BRANCH)
