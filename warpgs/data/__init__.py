"""Scenes: loaders for DL3DV / nerfstudio, COLMAP, LLFF, DTU and Blender, and the embedded synthetic scene.

Every loader returns a ``Scene`` whose cameras are in the library's convention (OpenCV axes,
world-to-camera ``viewmat``, ``K`` in pixels; see ``warpgs/__init__.py``). Entry point::

    from warpgs.data import load_scene
    scene = load_scene("llff", views=3)            # a name from configs/data/*.yaml
    scene = load_scene("/path/to/capture")          # a folder: its format is detected
    scene = load_scene("synthetic")                 # the default: generated once, cached, loaded as DL3DV
"""

from .blender import load_blender
from .dtu import load_dtu
from .llff import load_llff
from .nerfstudio import load_colmap, load_nerfstudio
from .registry import add_data_args, dataset_names, detect_format, load_scene, load_scene_from_args
from .scene import Camera, CameraTensors, DatasetNotFoundError, Scene, SceneError
from .synthetic import SyntheticConfig, ensure_synthetic, generate_capture, load_synthetic, write_dl3dv

__all__ = [
    "Camera",
    "CameraTensors",
    "DatasetNotFoundError",
    "Scene",
    "SceneError",
    "SyntheticConfig",
    "add_data_args",
    "dataset_names",
    "detect_format",
    "ensure_synthetic",
    "generate_capture",
    "load_blender",
    "load_colmap",
    "load_dtu",
    "load_llff",
    "load_nerfstudio",
    "load_scene",
    "load_scene_from_args",
    "load_synthetic",
    "write_dl3dv",
]
