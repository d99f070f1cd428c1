"""lgs_jax.assets: the bundled default scene and its cameras."""

import numpy as np
import pytest

import lgs_jax


def test_default_scene_is_bundled():
    g = lgs_jax.default_scene()
    assert g.means.shape == (4721, 3) and g.sh_degree == 3
    cam = lgs_jax.default_camera()
    assert (cam.width, cam.height) == (1280, 720)


def test_default_camera_frames_the_label_and_orbit_views_stay():
    cam = lgs_jax.default_camera()
    assert (cam.width, cam.height) == (1280, 720)
    g = lgs_jax.default_scene()
    m = np.asarray(g.means, np.float64)
    t = m @ np.asarray(cam.viewmat, np.float64)[:3, :3].T + np.asarray(cam.viewmat)[:3, 3]
    u = cam.fx * t[:, 0] / t[:, 2] + cam.cx
    v = cam.fy * t[:, 1] / t[:, 2] + cam.cy
    inside = (u > 0) & (u < cam.width) & (v > 0) & (v < cam.height) & (t[:, 2] > 0)
    assert inside.mean() > 0.98  # the whole label in view ...
    assert np.ptp(np.percentile(u, [1, 99])) > 0.75 * cam.width  # ... filling the width
    assert lgs_jax.default_camera(None, width=320).height == 180
    assert lgs_jax.default_camera(7).width == 1280
    for bad in (-1, 8, 99):
        with pytest.raises(ValueError, match="orbit view 0..7"):
            lgs_jax.default_camera(bad)
