"""lgs_jax.hoist: the hoisted 6-vector V (Local-GS Eq. 8) and the basis reproduce the quadratic
form of the exponent."""

import numpy as np

from lgs_jax import hoist


def test_hoist_equals_the_quadratic_form_float64():
    rng = np.random.default_rng(0)
    n = 200
    mean = rng.uniform(-100, 200, (n, 2))
    lmin, lmax, th = 0.3 + rng.exponential(2, n), 0.3 + rng.exponential(200, n), rng.uniform(0, 3, n)
    c, s = np.cos(th), np.sin(th)
    cov = np.stack([c * c * lmax + s * s * lmin, c * s * (lmax - lmin), s * s * lmax + c * c * lmin])
    det = cov[0] * cov[2] - cov[1] ** 2
    conic = np.stack([cov[2], -cov[1], cov[0]], -1) / det[:, None]
    log_o = np.log(rng.uniform(0.01, 1, n))
    origin = rng.integers(0, 10, (n, 2)) * 16.0
    xl, yl = rng.uniform(0, 16, n), rng.uniform(0, 16, n)
    v = np.asarray(hoist.hoist(mean, conic, log_o, origin))
    got = np.sum(v * np.asarray(hoist.basis(xl, yl)), -1)
    dx, dy = origin[:, 0] + xl - mean[:, 0], origin[:, 1] + yl - mean[:, 1]
    want = log_o - 0.5 * (conic[:, 0] * dx**2 + 2 * conic[:, 1] * dx * dy + conic[:, 2] * dy**2)
    np.testing.assert_allclose(got, want, rtol=1e-9, atol=1e-9)
    np.testing.assert_allclose(v[:, :3], np.stack([-0.5 * conic[:, 0], -conic[:, 1],
                                                   -0.5 * conic[:, 2]], -1))


def test_hoist_terms_vjp_is_the_transpose_of_eq8_float64():
    """The backward's explicit chain through Eq. 8 equals JAX's vjp of `hoist` (float64)."""
    import jax

    rng = np.random.default_rng(1)
    n = 100
    mean, conic = rng.uniform(-50, 80, (n, 2)), rng.uniform(-1, 1, (n, 3))
    log_o, origin = rng.uniform(-5, 0, n), rng.integers(0, 5, (n, 2)) * 16.0
    g = rng.normal(size=(n, 6))
    _, vjp = jax.vjp(lambda m, q, lo: hoist.hoist(m, q, lo, origin), mean, conic, log_o)
    d_mean, d_conic, d_log_o = (np.asarray(x) for x in vjp(g))
    assert d_mean.dtype == np.float64  # conftest enables x64
    got = [np.asarray(x) for x in hoist.hoist_terms_vjp(
        list(g.T), *conic.T, mean[:, 0] - origin[:, 0], mean[:, 1] - origin[:, 1])]
    np.testing.assert_allclose(np.stack(got[:3], -1), d_conic, rtol=1e-12, atol=1e-12)
    np.testing.assert_allclose(np.stack(got[3:5], -1), d_mean, rtol=1e-12, atol=1e-12)
    np.testing.assert_allclose(got[5], d_log_o, rtol=1e-12, atol=1e-12)
