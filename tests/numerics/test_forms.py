"""numerics.forms: every form's float32 evaluation error stays within its derived bound, and the
float64 evaluations of all forms agree.

Domain: 2D covariance eigenvalues λ₂ in [0.3, 0.3 + e^8], condition number κ up to 1e6, any
rotation; centres up to 3000 px from the pixel; pixel coordinates up to 16384 (16K images);
opacity in [1/255, 1]. Inputs are rounded to the evaluation dtype first and the reference is the
float64 evaluation of the same form on those rounded inputs (evaluation error only).
"""

import numpy as np
from hypothesis import given, strategies as st

from numerics import forms
from tests.scenes import float_arrays

M = 16


def _gaussians(dtype, log_kappa, theta, log_lmin, offset, angle, pixel_xy, logit):
    lmin = 0.3 + np.exp(log_lmin)
    lmax = lmin * np.exp(log_kappa)
    cov = forms.covariance(lmax, lmin, theta)
    conic = forms.conic(cov)
    pixel = np.floor(pixel_xy) + 0.5
    mean = pixel + offset[:, None] * np.stack([np.cos(angle), np.sin(angle)], -1)
    log_o = -np.log1p(np.exp(-logit))
    lam1, lam2, e1 = forms.principal_axes(cov)
    cast = lambda x: np.asarray(x, dtype)
    return (cast(mean), cast(pixel), cast(conic), cast(log_o),
            (cast(lam1), cast(lam2), cast(e1)))


@given(log_kappa=float_arrays(0, np.log(1e6), M), theta=float_arrays(0, np.pi, M),
       log_lmin=float_arrays(-6, 8, M), offset=float_arrays(0, 3000, M),
       angle=float_arrays(0, 2 * np.pi, M), px=float_arrays(0, 16383, M),
       py=float_arrays(0, 16383, M), logit=float_arrays(np.log(1 / 254), 12, M))
def test_float32_error_within_bound(log_kappa, theta, log_lmin, offset, angle, px, py, logit):
    args32 = _gaussians(np.float32, log_kappa, theta, log_lmin, offset, angle,
                        np.stack([px, py], -1), logit)
    mean, pixel, conic, log_o, axes = args32
    up = lambda x: np.asarray(x, np.float64)
    for form in forms.FORMS + ("whitened",):
        got = forms.log_alpha(form, mean, pixel, conic, log_o, axes)
        assert got.dtype == np.float32, form
        want = forms.log_alpha(form, up(mean), up(pixel), up(conic), up(log_o),
                               tuple(up(a) for a in axes))
        bound = forms.evaluation_bound(form, mean, pixel, conic, log_o, axes)
        err = np.abs(up(got) - want)
        worst = np.argmax(err - bound)
        assert np.all(err <= bound), (form, err[worst], bound[worst])


@given(seed=st.integers(0, 2**32 - 1))
def test_float64_evaluations_of_all_forms_agree(seed):
    rng = np.random.default_rng(seed)
    args = _gaussians(np.float64, rng.uniform(0, np.log(1e4), M), rng.uniform(0, np.pi, M),
                      rng.uniform(-3, 5, M), rng.uniform(0, 40, M), rng.uniform(0, 7, M),
                      rng.uniform(0, 4096, (M, 2)), rng.uniform(-5, 10, M))
    results = {f: forms.log_alpha(f, *args[:4], args[4]) for f in forms.FORMS + ("whitened",)}
    for f, r in results.items():
        np.testing.assert_allclose(r, results["difference"], rtol=1e-9, atol=1e-7, err_msg=f)
