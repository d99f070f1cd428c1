"""numerics.cost times the arithmetic of numerics.forms and numerics.centre."""

import jax.numpy as jnp
import numpy as np

from numerics import centre, cost, forms, split


def test_cost_kernels_compute_the_forms():
    """numerics.cost times the same arithmetic as forms.log_alpha (split into setup/evaluate):
    its float32 exponents equal the float64 exponent of the same Gaussians within the form's
    evaluation bound (hoisted forms: origin 0 in the form's own coordinates, as cost.setup;
    split forms: the centre hi + lo, their offset rounding once as the difference form's)."""
    up = lambda x: np.asarray(x, np.float64)
    for form, (mean, conic, log_o, cov64) in cost.scene(64).items():
        pixels = cost.tile_pixels(form.split("+")[0])
        got = np.asarray(cost.evaluate(form, cost.setup(form, mean, conic, log_o, cov64), pixels))
        if form.endswith("+split"):
            mean = up(mean[0]) + up(mean[1])
        want = forms.log_alpha("difference", up(mean)[:, None], up(pixels)[None],
                               up(conic)[:, None], up(log_o)[:, None])
        args = (mean[:, None], pixels[None], conic[:, None], log_o[:, None])
        bound = forms.evaluation_bound("global" if form.startswith(("global", "local")) else
                                       form.split("+")[0], *(np.asarray(a) for a in args),
                                       tuple(a[:, None] for a in forms.principal_axes(up(cov64))))
        assert np.all(np.abs(got - want) <= bound + 1e-4 * np.abs(want)), form


def test_projection_carries_the_split_centre_and_plain_centre_has_the_floor():
    """lgs_jax.projection's float32 centre mean2d + mean2d_lo and split.centre_split (jitted,
    as timed: the same arithmetic, compiled apart) equal the float64 centre of the same float32
    parameters to 1e-8 px at 16K, mean2d being that centre rounded (|mean2d_lo| <= ulp/2);
    split.plain_centre, the centre in one float32 number, errs by ~1e-3 px (a few ulps of its
    terms, which are ~width/2: the camera transform's rounding at the scene's size)."""
    import jax

    import lgs_jax
    from lgs_jax.projection import project

    rng = np.random.default_rng(0)
    g, cam, _ = centre.sample(rng, 256, 16384, 16, 1.0)
    view, fx, fy, cx, cy, width, height = cam
    args = (jnp.asarray(g.means), jnp.asarray(view)) + tuple(jnp.float32(v)
                                                           for v in (fx, fy, cx, cy))
    p32 = project(g, lgs_jax.Camera(viewmat=view, fx=fx, fy=fy, cx=cx, cy=cy, width=width,
                                    height=height))
    valid = np.asarray(p32.valid)
    t = np.asarray(g.means, np.float64) @ view[:3, :3].T.astype(np.float64) + view[:3, 3]
    exact = np.stack([float(fx) * t[:, 0] / t[:, 2] + float(cx),
                      float(fy) * t[:, 1] / t[:, 2] + float(cy)], -1)[valid]
    up = lambda x: np.asarray(x, np.float64)[valid]
    hi, lo = p32.mean2d, p32.mean2d_lo
    assert np.abs(up(hi) + up(lo) - exact).max() < 1e-8
    assert np.all(np.abs(up(lo)) <= np.spacing(np.abs(np.asarray(hi)[valid])) / 2)
    hi, lo = jax.jit(split.centre_split)(*args)
    assert np.abs(up(hi) + up(lo) - exact).max() < 1e-8
    plain = np.asarray(jax.jit(split.plain_centre)(*args))[valid]
    ulp = np.spacing(np.float32(width))  # of the centre's terms (fx·tx/tz and cx are ~width/2)
    assert np.abs(plain - np.asarray(p32.mean2d)[valid]).max() <= 8 * ulp
    assert np.abs(plain - exact).max() > 1e-4
