"""Projection against the independent float64 numpy oracle (tests/oracle.py)."""

import numpy as np
from hypothesis import given, strategies as st

from lgs_jax.projection import project
from tests import oracle, scenes


@given(seed=st.integers(0, 2**32 - 1), yaw=st.floats(-0.6, 0.6), antialiased=st.booleans())
def test_projection_matches_oracle_float64(seed, yaw, antialiased):
    g = scenes.scene(seed, sh_bases=16)
    cam = scenes.camera(dtype=np.float64, yaw=yaw)
    p = project(g, cam, antialiased)
    want = oracle.project_all(g, cam, antialiased)
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
        o_rtol = 1e-13
        if antialiased:  # J Σc Jᵀ's entries and determinant cancel: ρ² to eps·|terms|/det
            t = w["terms"].max()  # |J| |Σc| |J|ᵀ bounds each product summed
            o_rtol += 1e-15 * t * (t + w["cov2d"].max()) / (w["rho"] ** 2 * np.prod(
                np.linalg.eigvalsh([[w["cov2d"][0], w["cov2d"][1]], [w["cov2d"][1], w["cov2d"][2]]])))
        np.testing.assert_allclose(p.opacity[i], w["o"], rtol=o_rtol)
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


def test_antialiasing_keeps_each_gaussians_integral():
    """ρ·o·2π·sqrt(det Σ2) = o·2π·sqrt(det(J Σc Jᵀ)): the dilated footprint integrates to the
    undilated one's; ρ is at most 1, near 1 for Gaussians much wider than the 0.3-pixel
    dilation and small for Gaussians much smaller than a pixel."""
    g = scenes.scene(4, kinds=("normal", "tiny", "huge_far", "opaque"))
    cam = scenes.camera(dtype=np.float64)
    plain, aa = project(g, cam), project(g, cam, True)
    valid = np.asarray(aa.valid)
    rho = np.asarray(aa.opacity)[valid] / np.asarray(plain.opacity)[valid]
    xx, xy, yy = np.asarray(plain.cov2d)[valid].T
    det_raw, det = (xx - 0.3) * (yy - 0.3) - xy * xy, xx * yy - xy * xy
    np.testing.assert_allclose(rho * np.sqrt(det), np.sqrt(det_raw), rtol=1e-9)
    assert np.all(rho <= 1) and rho.max() > 0.99 and rho.min() < 0.5
    for name in ("mean2d", "cov2d", "conic", "depth", "rgb"):
        np.testing.assert_array_equal(np.asarray(getattr(aa, name))[valid],
                                      np.asarray(getattr(plain, name))[valid], err_msg=name)
