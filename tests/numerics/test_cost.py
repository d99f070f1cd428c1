"""numerics.cost times the arithmetic of numerics.forms."""

import numpy as np

from numerics import cost, forms


def test_cost_kernels_compute_the_forms():
    """numerics.cost times the same arithmetic as forms.log_alpha (split into setup/evaluate):
    its float32 exponents equal the float64 exponent of the same Gaussians within the form's
    evaluation bound (hoisted forms: origin 0 in the form's own coordinates, as cost.setup)."""
    up = lambda x: np.asarray(x, np.float64)
    for form, (mean, conic, log_o, cov64) in cost.scene(64).items():
        pixels = cost.tile_pixels(form)
        got = np.asarray(cost.evaluate(form, cost.setup(form, mean, conic, log_o, cov64), pixels))
        want = forms.log_alpha("difference", up(mean)[:, None], up(pixels)[None],
                               up(conic)[:, None], up(log_o)[:, None])
        args = (mean[:, None], pixels[None], conic[:, None], log_o[:, None])
        bound = forms.evaluation_bound("global" if form.startswith(("global", "local")) else form,
                                       *(np.asarray(a) for a in args),
                                       tuple(a[:, None] for a in forms.principal_axes(up(cov64))))
        assert np.all(np.abs(got - want) <= bound + 1e-4 * np.abs(want)), form
