"""`sh.sh_sums`' hand-written vjp against autodiff of the sums it replaces, bit for bit."""

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from lgs_jax.sh import sh_basis_terms, sh_sums


def _plain(basis, sh, keep):
    """The sums as `projection` wrote them before `sh_sums`: differentiated by autodiff."""
    return [sum(b * jnp.where(keep, sh[:, k, c], 0.0) for k, b in enumerate(basis))
            for c in range(3)]


@pytest.mark.parametrize("bases", [1, 4, 9, 16])
@pytest.mark.parametrize("dtype", [np.float32, np.float64])
def test_sh_sums_vjp_equals_autodiff(bases, dtype):
    """Op by op (no jit, so no fusion can reorder either side): the sums, ∂L/∂sh (0 on rows
    not kept, NaN coefficients there included) and ∂L/∂basis equal autodiff's to the bit."""
    rng = np.random.default_rng(bases)
    n = 64
    d = rng.normal(size=(3, n))
    d /= np.linalg.norm(d, axis=0)
    basis = sh_basis_terms(*(jnp.asarray(x, dtype) for x in d), bases)
    sh = rng.normal(size=(n, bases, 3)).astype(dtype)
    keep = rng.random(n) > 0.2
    sh[~keep, 0, 1] = np.nan  # masked rows: must not reach a gradient
    cts = [jnp.asarray(rng.normal(size=n), dtype) for _ in range(3)]
    with jax.disable_jit():
        got, got_vjp = jax.vjp(lambda b, s: sh_sums(b, s, jnp.asarray(keep)), basis, sh)
        want, want_vjp = jax.vjp(lambda b, s: _plain(b, s, jnp.asarray(keep)), basis, sh)
        (got_b, got_sh), (want_b, want_sh) = got_vjp(cts), want_vjp(cts)
    for a, b in zip(got + got_b + [got_sh], want + want_b + [want_sh]):
        np.testing.assert_array_equal(np.asarray(a), np.asarray(b))
    assert np.all(np.asarray(got_sh)[~keep] == 0)
