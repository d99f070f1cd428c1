"""lgs_jax: differentiable 3D Gaussian Splatting in JAX, built around Local-GS.

Public API: `Gaussians`, `Camera`, `RasterConfig` (with its `KernelConfig`), `render`
(-> `RenderOutput`), `render_growing`, `pair_capacity` (the pair-buffer size for a pair count),
`count_pairs` (the pairs a render needs), `load_ply`, `save_ply`, `load_cameras`,
`save_cameras`, `stack_cameras`, `default_scene`, `load_dataset` (-> `Dataset`: COLMAP /
transforms.json captures).
"""

from .config import KernelConfig, RasterConfig
from .assets import default_camera, default_scene
from .io.cameras import load_cameras, save_cameras
from .io.datasets import Dataset, load_dataset
from .io.views import DatasetError
from .io.ply import PlyError, load_ply, save_ply
from .render import (BACKENDS, CapacityError, RenderOutput, RenderStats, count_pairs,
                     default_backend, pair_capacity, render, render_growing)
from .scene import Camera, Gaussians, stack_cameras

__all__ = [
    "BACKENDS", "Camera", "CapacityError", "Dataset", "DatasetError", "Gaussians",
    "KernelConfig", "PlyError", "RasterConfig", "RenderOutput", "RenderStats", "count_pairs",
    "default_backend",
    "default_camera", "default_scene", "load_cameras", "load_dataset", "load_ply", "pair_capacity",
    "render", "render_growing", "save_cameras", "save_ply", "stack_cameras",
]
__version__ = "0.1.0"
