"""lgs_jax.train.step: the views of a step one after another (`over_views`): a renderer's
conditions on per-view values run one branch per view, not every branch (as under vmap)."""

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from lgs_jax.train import step


@pytest.mark.parametrize("views,vectorize,branches", [
    (1, False, ["yes"]), (3, False, ["yes", "no", "yes"]),
    (3, True, ["no", "yes"])])  # vmap: each branch over the whole batch
def test_views_run_their_own_branch_only(views, vectorize, branches):
    ran = []

    def one(g, cam, target, offsets, look):
        def branch(name):
            def run(x):
                jax.debug.callback(lambda: ran.append(name))
                return x + (1.0 if name == "yes" else -1.0)
            return run
        out = jax.lax.cond(cam > 0, branch("yes"), branch("no"), g * target)
        return out, look["w"] * 2

    cams = jnp.asarray([1.0, -1.0, 2.0][:views])
    f = jax.jit(lambda g, c, t, w: step.over_views(one, 1, vectorize)(g, c, t, None, dict(w=w)))
    out, w = f(jnp.float32(2.0), cams, jnp.arange(views, dtype=jnp.float32),
               jnp.ones((views, 2)))
    jax.effects_barrier()
    want = 2.0 * np.arange(views) + np.where(np.asarray(cams) > 0, 1.0, -1.0)
    np.testing.assert_array_equal(np.asarray(out), want)
    assert w.shape == (views, 2) and sorted(ran) == sorted(branches), ran
