"""lgs_jax.train.bilateral_grid: the slice against a float64 per-pixel trilinear interpolation
written as torch's grid_sample defines it (align_corners=True, border padding), colours outside
[0, 1] and images shorter than the row blocks included; the zero grid is the identity to the
bit; gradients against central differences; gsplat's total variation and learning-rate
schedule; a grid fitted alone follows a vignette and a tone curve far closer than one affine map
per photo can."""

import jax
import jax.numpy as jnp
import numpy as np
import optax
import pytest

from lgs_jax.train import Recipe, bilateral_grid as bg

SHAPE = (bg.COEFFS, bg.L, bg.Y, bg.X)


def _sample(grid, x, y, z):
    """grid (12, L, Y, X) at continuous cell coordinates (x, y, z), border-clamped, float64."""
    pos = [np.clip(t, 0, n - 1) for t, n in ((z, bg.L), (y, bg.Y), (x, bg.X))]
    lo = [min(int(np.floor(t)), n - 2) for t, n in zip(pos, (bg.L, bg.Y, bg.X))]
    out = np.zeros(bg.COEFFS)
    for dz in (0, 1):
        for dy in (0, 1):
            for dx in (0, 1):
                w = 1.0
                for t, low, d in zip(pos, lo, (dz, dy, dx)):
                    f = t - low
                    w *= f if d else 1 - f
                out += w * grid[:, lo[0] + dz, lo[1] + dy, lo[2] + dx]
    return out


def _reference(image, p):
    """(H, W, 12) coefficients of `bilateral_grid.coefficients`, one pixel at a time."""
    h, w, _ = image.shape
    grid = np.asarray(p, np.float64).reshape(SHAPE)
    out = np.zeros((h, w, bg.COEFFS))
    for i in range(h):
        for j in range(w):
            gray = float(np.dot(image[i, j], bg.GRAY))
            out[i, j] = _sample(grid, (j + 0.5) / w * (bg.X - 1), (i + 0.5) / h * (bg.Y - 1),
                                gray * (bg.L - 1))
    return out


@pytest.mark.parametrize("h,w", [(13, 10), (5, 7)])
def test_slice_is_the_trilinear_interpolation_of_grid_sample(h, w):
    rng = np.random.default_rng(h)
    image = rng.uniform(-0.2, 1.2, (h, w, 3))  # brightness clamped at both ends
    p = rng.normal(size=bg.SIZE)
    got = np.asarray(bg.coefficients(jnp.asarray(image), jnp.asarray(p)))
    np.testing.assert_allclose(got, _reference(image, p), rtol=0, atol=1e-12)
    a = _reference(image, p).reshape(h, w, 3, 4)
    want = image + np.einsum("hwij,hwj->hwi", a[..., :3], image) + a[..., 3]
    np.testing.assert_allclose(np.asarray(bg.corrected(jnp.asarray(image), jnp.asarray(p))),
                               want, rtol=0, atol=1e-12)


def test_the_zero_grid_changes_no_bit():
    image = np.random.default_rng(0).uniform(0, 1, (9, 11, 3)).astype(np.float32)
    out = bg.corrected(jnp.asarray(image), jnp.zeros(bg.SIZE, jnp.float32))
    np.testing.assert_array_equal(np.asarray(out), image)


def test_gradients_equal_central_differences():
    rng = np.random.default_rng(1)
    image = jnp.asarray(rng.uniform(0.05, 0.95, (6, 9, 3)))
    p = jnp.asarray(rng.normal(0, 0.3, bg.SIZE))
    weights = jnp.asarray(rng.normal(size=(6, 9, 3)))
    loss = jax.jit(lambda image, p: jnp.sum(weights * bg.corrected(image, p)))
    grads = jax.grad(loss, argnums=(0, 1))(image, p)
    for which, x in enumerate((image, p)):
        flat = np.asarray(x).ravel()
        for k in rng.choice(flat.size, 6, replace=False):
            e = np.zeros_like(flat)
            e[k] = 1e-6
            args = [image, p]
            args[which] = jnp.asarray((flat + e).reshape(x.shape))
            up = loss(*args)
            args[which] = jnp.asarray((flat - e).reshape(x.shape))
            fd = (up - loss(*args)) / 2e-6
            assert float(np.asarray(grads[which]).ravel()[k]) == pytest.approx(float(fd),
                                                                               rel=1e-5, abs=1e-8)


def test_total_variation_and_schedule_are_gsplats():
    g = np.random.default_rng(2).normal(size=(3,) + SHAPE)
    want = sum(np.sum(np.diff(g, axis=a) ** 2) / (np.diff(g, axis=a)[0].size) / 3
               for a in (2, 3, 4))  # gsplat: per axis the sum over the batch / count / batch
    assert float(bg.total_variation(jnp.asarray(g.reshape(3, -1)))) == pytest.approx(want,
                                                                                     rel=1e-12)
    lr = bg.schedule(Recipe(batch=4), 30_000)
    base = 2e-3 * 2
    assert float(lr(0)) == pytest.approx(0.01 * base, rel=1e-6)
    assert float(lr(500)) == pytest.approx(0.505 * base * 0.01 ** (500 / 30_000), rel=1e-6)
    assert float(lr(30_000)) == pytest.approx(base * 0.01, rel=1e-6)


def test_a_grid_fits_what_one_affine_map_cannot():
    """A photo with a vignette and a tone curve (dark tones lifted, bright ones kept): the grid
    fitted alone (Adam at 0.02, 300 steps) takes the squared error down 17x, to a fifth of one
    affine map's fitted the same way (`color_opt`'s model)."""
    h, w = 120, 160  # 57,600 values for the grid's 24,576: no memorizing
    rng = np.random.default_rng(3)
    image = rng.uniform(0, 1, (h, w, 3)).astype(np.float32)
    yy, xx = np.mgrid[0:h, 0:w]
    vignette = 1 - 0.4 * (((xx - w / 2) / w) ** 2 + ((yy - h / 2) / h) ** 2)
    target = jnp.asarray((image ** 0.7) * vignette[..., None], jnp.float32)

    def fit(model, size):
        loss = lambda p: jnp.mean((model(jnp.asarray(image), p) - target) ** 2)
        opt = optax.adam(0.02)

        @jax.jit
        def step(p, s):
            g = jax.grad(loss)(p)
            u, s = opt.update(g, s)
            return optax.apply_updates(p, u), s

        p = jnp.zeros(size, jnp.float32)
        s = opt.init(p)
        for _ in range(300):
            p, s = step(p, s)
        return float(loss(p))

    from lgs_jax.train import color_opt
    start = float(jnp.mean((jnp.asarray(image) - target) ** 2))
    grid, affine = fit(bg.corrected, bg.SIZE), fit(color_opt.corrected, color_opt.SIZE)
    assert grid < start / 10 and grid < affine / 3, (start, grid, affine)  # 17x; 4.7x
