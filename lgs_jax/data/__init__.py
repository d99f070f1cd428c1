"""The bundled default scene: `fruit_drops` (4,721 Gaussians, SH degree 3, MIT, PlayCanvas
SuperSplat; see LICENSE.fruit_drops.txt) with its 8 orbit cameras (1280x720)."""

from __future__ import annotations

from importlib import resources

SCENE = "fruit_drops.ply"
CAMERAS = "fruit_drops_cameras.json"


def default_scene():
    """The bundled fruit_drops scene as float32 `Gaussians`."""
    from ..io.ply import load_ply

    with resources.as_file(resources.files(__name__) / SCENE) as path:
        return load_ply(path)


def default_camera(view: int = 0, width: int | None = None, height: int | None = None):
    """Orbit view `view` (0..7) of the default scene, 1280x720 unless resized."""
    from ..io.cameras import load_cameras

    with resources.as_file(resources.files(__name__) / CAMERAS) as path:
        return load_cameras(path, width=width, height=height)[view]
