"""warpgs: sparse-view 3D Gaussian Splatting with test-time video completion, on NVIDIA Warp.

Camera convention (the only one used inside the library; loaders convert at the boundary):
OpenCV axes — x right, y down, z forward. A camera is given by ``viewmat``, the 4x4 world-to-camera
matrix, and ``K``, the 3x3 intrinsics in pixels, with pixel (j, i) covering [j, j+1) x [i, i+1) so its
centre is at (j + 0.5, i + 0.5). Quaternions are (w, x, y, z).
"""

__version__ = "0.1.0"
