"""lgs_jax.scene: Gaussians and Camera (validation goes through `render`: tests/test_render.py)."""

import numpy as np

import lgs_jax


def test_resized_crop_shows_the_centre_of_the_view():
    """A point that projects to the centre column stays there, and one at the left edge of the
    wide view moves left of the cropped image by the cropped margin."""
    cam = lgs_jax.Camera(viewmat=np.eye(4, dtype=np.float32), fx=np.float32(50),
                         fy=np.float32(50), cx=np.float32(32), cy=np.float32(18), width=64,
                         height=36)
    crop = cam.resized(18, 18)  # scale 0.5 (height), then 32 -> 18 columns: 7 cut on each side
    assert float(crop.fx) == 25.0 and float(crop.cx) == 9.0 and float(crop.cy) == 9.0
    assert cam.resized() is cam
