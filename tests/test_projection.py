"""Projection against the independent float64 numpy oracle (tests/oracle.py)."""

import numpy as np
from hypothesis import given, strategies as st

from lgs_jax.projection import project
from tests import oracle, scenes


@given(seed=st.integers(0, 2**32 - 1), yaw=st.floats(-0.6, 0.6))
def test_projection_matches_oracle_float64(seed, yaw):
    g = scenes.scene(seed, sh_bases=16)
    cam = scenes.camera(dtype=np.float64, yaw=yaw)
    p = project(g, cam)
    want = oracle.project_all(g, cam)
    valid = np.asarray(p.valid)
    np.testing.assert_array_equal(valid, [w is not None for w in want])
    for i, w in enumerate(want):
        if w is None:
            continue
        np.testing.assert_allclose(p.mean2d[i], w["mean2d"], rtol=1e-11, atol=1e-9)
        np.testing.assert_allclose(p.conic[i], w["conic"], rtol=1e-9,
                                   atol=1e-12 * np.abs(w["conic"]).max())
        np.testing.assert_allclose(p.cov2d[i], w["cov2d"], rtol=1e-9,
                                   atol=1e-12 * np.abs(w["cov2d"]).max())
        np.testing.assert_allclose(p.depth[i], w["depth"], rtol=1e-13)
        np.testing.assert_allclose(p.opacity[i], w["o"], rtol=1e-13)
        np.testing.assert_allclose(p.rgb[i], w["rgb"], rtol=1e-11, atol=1e-12)


def test_invalid_gaussians_are_counted_and_finite():
    g = scenes.scene(7, kinds=("invalid", "behind", "normal"))
    p = project(g, scenes.camera(dtype=np.float64))
    invalid = np.asarray(p.invalid)
    assert invalid.any() and not np.asarray(p.valid)[invalid].any()
    for field in (p.mean2d, p.conic, p.rgb, p.opacity):
        assert np.all(np.isfinite(np.asarray(field)))


def test_opaque_logit_inf_is_valid():
    g = scenes.scene(3, kinds=("opaque",))
    p = project(g, scenes.camera(dtype=np.float64))
    want = oracle.project_all(g, scenes.camera(dtype=np.float64))
    np.testing.assert_array_equal(np.asarray(p.valid), [w is not None for w in want])
    assert np.all(np.asarray(p.opacity)[np.asarray(p.valid)] == 1.0)
