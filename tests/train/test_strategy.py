"""Densification in static shapes (lgs_jax.train.ops / strategy / pool): every operation on a
small pool, parameters and Adam moments against hand-computed expectations (gsplat 1.5.3's
rules), pool growth, the strategies' schedules and refinements. Eager and small: fast."""

import math

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from lgs_jax.projection import quat_to_rotmat
from lgs_jax.train import Recipe, ops, optim, pool as P, step as S
from lgs_jax.train.strategy import DefaultStrategy, MCMCStrategy, StepInfo

F32 = np.float32


def _pool(n_active=4, size=8, opacities=None, log_scales=None):
    """A pool with distinct, recognisable parameters: means[i] = (i, 10 i, 100 i), ..."""
    i = np.arange(size, dtype=F32)
    o = np.full(size, 0.5, F32) if opacities is None else np.asarray(opacities, F32)
    params = dict(means=np.stack([i, 10 * i, 100 * i], 1),
                  quats=np.tile(np.array([1, 0, 0, 0], F32), (size, 1)),
                  log_scales=np.tile(np.log(np.array([0.1, 0.2, 0.3], F32)), (size, 1))
                  if log_scales is None else np.asarray(log_scales, F32),
                  logit_opacities=np.log(o / (1 - o)),
                  sh=np.concatenate([i[:, None, None] * np.ones((size, 1, 3), F32),
                                     np.zeros((size, 3, 3), F32)], 1))
    params = {k: jnp.asarray(v, jnp.float32) for k, v in params.items()}
    return P.Pool(params, jnp.arange(size) < n_active)


def _opt_state(pool):
    """Adam state whose moments are recognisable: mu = 1000 + slot, nu = 2000 + slot."""
    state = optim.optimizer(Recipe(), 100, 1.0).init(pool.params)
    rows = lambda base: (lambda g, m: jnp.broadcast_to(
        P.rows(jnp.arange(pool.size), m) + base, m.shape).astype(m.dtype))
    adam = state[0]
    return (adam._replace(mu=optim.map_moments(adam.mu, rows(1000.0)),
                          nu=optim.map_moments(adam.nu, rows(2000.0))),) + state[1:]


def _mu(opt_state, group="means"):
    m = np.asarray(opt_state[0].mu[group])
    return m.reshape(len(m), -1)[:, 0]


def _nu(opt_state, group="means"):
    m = np.asarray(opt_state[0].nu[group])
    return m.reshape(len(m), -1)[:, 0]


def _p(pool, k):
    return np.asarray(pool.params[k])


def test_allocate_pairs_candidates_with_free_slots_by_priority():
    want = jnp.array([1, 0, 1, 1, 0, 0, 0, 0], bool)
    free = jnp.array([0, 0, 0, 0, 1, 0, 1, 0], bool)
    src, filled, granted = ops.allocate(want, free)  # slot order: 0 -> 4, 2 -> 6, 3 gets none
    assert np.asarray(filled).tolist() == [0, 0, 0, 0, 1, 0, 1, 0]
    assert np.asarray(src).tolist() == [0, 1, 2, 3, 0, 5, 2, 7]
    assert np.asarray(granted).tolist() == [1, 0, 1, 0, 0, 0, 0, 0]
    prio = jnp.array([0.1, 9, 0.3, 0.2, 0, 0, 0, 0])  # highest first: 2 -> 4, 3 -> 6
    src, filled, granted = ops.allocate(want, free, prio)
    assert np.asarray(src).tolist() == [0, 1, 2, 3, 2, 5, 3, 7]
    assert np.asarray(granted).tolist() == [0, 0, 1, 1, 0, 0, 0, 0]


def test_duplicate_copies_parameters_with_zero_moments():
    pool, opt = _pool(), None
    opt = _opt_state(pool)
    new, new_opt, granted = ops.duplicate(pool, opt, jnp.array([0, 1, 0, 1, 0, 0, 0, 0], bool))
    assert np.asarray(new.active).tolist() == [1, 1, 1, 1, 1, 1, 0, 0]
    for k in pool.params:
        np.testing.assert_array_equal(_p(new, k)[[4, 5]], _p(pool, k)[[1, 3]])
        np.testing.assert_array_equal(_p(new, k)[:4], _p(pool, k)[:4])
    assert _mu(new_opt).tolist() == [1000, 1001, 1002, 1003, 0, 0, 1006, 1007]
    assert _nu(new_opt, "sh").tolist() == [2000, 2001, 2002, 2003, 0, 0, 2006, 2007]
    assert int(new_opt[0].count) == int(opt[0].count)  # Adam's step count is shared, kept
    assert np.asarray(granted).sum() == 2


def test_split_places_two_children_and_zeroes_their_moments():
    pool = _pool()
    q = np.array([np.cos(0.3), 0, 0, np.sin(0.3)], F32)  # 0.6 rad about z
    pool = P.Pool(dict(pool.params, quats=pool.params["quats"].at[2].set(q)), pool.active)
    opt, key = _opt_state(pool), jax.random.key(7)
    new, new_opt, granted = ops.split(pool, opt, jnp.arange(8) == 2, key)
    eps = np.asarray(jax.random.normal(key, (2, 8, 3), jnp.float32))
    r = np.asarray(quat_to_rotmat(jnp.asarray(q[None])))[0].astype(np.float64)
    s = np.array([0.1, 0.2, 0.3])
    assert np.asarray(new.active).tolist() == [1, 1, 1, 1, 1, 0, 0, 0]
    for slot, k in ((2, 0), (4, 1)):  # child 1 in the parent's slot, child 2 in the free one
        np.testing.assert_allclose(_p(new, "means")[slot], [2, 20, 200] + r @ (s * eps[k, 2]),
                                   rtol=1e-6)
        np.testing.assert_allclose(_p(new, "log_scales")[slot], np.log(s / 1.6), rtol=1e-6)
        for name in ("quats", "logit_opacities", "sh"):
            np.testing.assert_array_equal(_p(new, name)[slot], _p(pool, name)[2])
    for name in pool.params:
        np.testing.assert_array_equal(_p(new, name)[[0, 1, 3]], _p(pool, name)[[0, 1, 3]])
    assert _mu(new_opt, "log_scales").tolist() == [1000, 1001, 0, 1003, 0, 1005, 1006, 1007]
    revised, _, _ = ops.split(pool, opt, jnp.arange(8) == 2, key, revised_opacity=True)
    o = 1 / (1 + np.exp(-_p(revised, "logit_opacities")[[2, 4]]))
    np.testing.assert_allclose(o, 1 - np.sqrt(0.5), rtol=1e-6)


def test_prune_frees_slots_and_zeroes_their_moments():
    pool = _pool()
    opt = _opt_state(pool)
    new, new_opt = ops.prune(pool, opt, jnp.array([0, 1, 0, 0, 0, 0, 1, 0], bool))
    assert np.asarray(new.active).tolist() == [1, 0, 1, 1, 0, 0, 0, 0]
    assert _mu(new_opt, "quats").tolist() == [1000, 0, 1002, 1003, 1004, 1005, 1006, 1007]
    assert _nu(new_opt, "quats").tolist() == [2000, 0, 2002, 2003, 2004, 2005, 2006, 2007]


def test_reset_opacity_clamps_and_zeroes_only_opacity_moments():
    pool = _pool(opacities=[0.5, 0.001, 0.02, 0.009, 0.5, 0.5, 0.5, 0.5])
    opt = _opt_state(pool)
    new, new_opt = ops.reset_opacity(pool, opt, 0.01)
    o = 1 / (1 + np.exp(-_p(new, "logit_opacities").astype(np.float64)))
    np.testing.assert_allclose(o[:4], [0.01, 0.001, 0.01, 0.009], rtol=1e-5)
    assert _mu(new_opt, "logit_opacities").tolist() == [0] * 8
    assert _nu(new_opt, "logit_opacities").tolist() == [0] * 8
    assert _mu(new_opt, "means").tolist() == list(range(1000, 1008))


def _gsplat_relocation(o, n):
    """gsplat's CUDA relocation kernel, transcribed in float64."""
    new_o = 1 - (1 - o) ** (1 / n)
    denom = sum(math.comb(i - 1, k) * (-1) ** k / math.sqrt(k + 1) * new_o ** (k + 1)
                for i in range(1, n + 1) for k in range(i))
    return new_o, o / denom


@pytest.mark.parametrize("n", [1, 2, 3, 7, 20])
def test_relocation_formula_equals_gsplats_kernel(n):
    o = np.array([0.01, 0.2, 0.5, 0.9, 0.99])
    new_o, new_s = ops.relocation(jnp.asarray(o, jnp.float32), jnp.ones((5, 3), jnp.float32),
                                  jnp.full(5, n))
    for j in range(5):
        want_o, want_factor = _gsplat_relocation(o[j], n)
        assert abs(float(new_o[j]) - want_o) <= 1e-7 + 1e-5 * want_o
        np.testing.assert_allclose(np.asarray(new_s[j]), want_factor, rtol=2e-4)
    if n == 1:  # one share: the Gaussian itself
        np.testing.assert_allclose(np.asarray(new_o), o, rtol=1e-6)
        np.testing.assert_allclose(np.asarray(new_s), 1.0, rtol=1e-5)


def _assert_relocated(new, slots, want_o, factor):
    """Slots hold gsplat's relocated opacity and scales (the test pool's are 0.1, 0.2, 0.3)."""
    for slot in slots:
        o = 1 / (1 + np.exp(-float(_p(new, "logit_opacities")[slot])))
        assert abs(o - want_o) < 1e-6
        np.testing.assert_allclose(np.exp(_p(new, "log_scales")[slot]),
                                   factor * np.array([0.1, 0.2, 0.3]), rtol=1e-5)


def test_relocate_moves_dead_onto_the_alive_one():
    """One alive Gaussian (slot 1): both dead slots (0, 3) copy it; it is shared 3 ways."""
    pool = _pool(opacities=[0.004, 0.6, 0.5, 0.005, 0.5, 0.5, 0.5, 0.5])
    pool = P.Pool(pool.params, jnp.array([1, 1, 0, 1, 0, 0, 0, 0], bool))
    opt = _opt_state(pool)
    dead = jax.nn.sigmoid(pool.params["logit_opacities"]) <= 0.005
    new, new_opt, moved = ops.relocate(pool, opt, dead, jax.random.key(0), 0.005)
    assert np.asarray(moved).tolist() == [1, 0, 0, 1, 0, 0, 0, 0]
    want_o, factor = _gsplat_relocation(0.6, 3)
    _assert_relocated(new, (0, 1, 3), want_o, factor)
    for slot in (0, 1, 3):
        np.testing.assert_array_equal(_p(new, "means")[slot], _p(pool, "means")[1])
    np.testing.assert_array_equal(_p(new, "means")[2], _p(pool, "means")[2])  # inactive
    # gsplat zeroes the sampled source's moments; the dead slots keep theirs
    assert _mu(new_opt, "means").tolist() == [1000, 0, 1002, 1003, 1004, 1005, 1006, 1007]
    none_alive = ops.relocate(pool, opt, pool.active, jax.random.key(0), 0.005)
    assert not np.asarray(none_alive[2]).any()


def test_relocate_samples_only_alive_gaussians_by_opacity():
    o = np.full(64, 0.001)
    o[[3, 9]] = [0.8, 0.2]  # alive: slot 3 four times as likely as slot 9
    pool = _pool(64, 64, opacities=o)
    dead = jax.nn.sigmoid(pool.params["logit_opacities"]) <= 0.005
    new, _, moved = ops.relocate(pool, _opt_state(pool), dead, jax.random.key(3), 0.005)
    assert int(np.asarray(moved).sum()) == 62
    src = _p(new, "means")[np.asarray(moved), 0].astype(int)
    assert set(src) <= {3, 9} and (src == 3).sum() > 2 * (src == 9).sum()


def test_sampling_is_linear_in_the_pool():
    """Relocation draws a source per slot in O(N) memory: at 2^16 slots an N x N draw (as
    jax.random.categorical(shape=(N,)) makes) would need 17 GB of temporaries."""
    pool = _pool(2**15, 2**16)
    dead = jnp.arange(pool.size) % 3 == 0
    f = jax.jit(lambda p, o, d, k: ops.relocate(p, o, d, k, 0.005))
    compiled = f.lower(pool, _opt_state(pool), dead, jax.random.key(0)).compile()
    assert compiled.memory_analysis().temp_size_in_bytes < 2**28


def test_sample_add_copies_sampled_sources_into_free_slots():
    pool = _pool(opacities=[0.7] + [0.5] * 7)
    pool = P.Pool(pool.params, jnp.arange(8) == 0)  # one active Gaussian
    opt = _opt_state(pool)
    new, new_opt, added = ops.sample_add(pool, opt, 2, jax.random.key(1), 0.005)
    assert np.asarray(new.active).tolist() == [1, 1, 1, 0, 0, 0, 0, 0]
    want_o, factor = _gsplat_relocation(0.7, 3)
    _assert_relocated(new, (0, 1, 2), want_o, factor)
    for slot in (0, 1, 2):
        np.testing.assert_array_equal(_p(new, "sh")[slot], _p(pool, "sh")[0])
    # the new slots start with zero moments; the source keeps its own (gsplat)
    assert _mu(new_opt, "means").tolist() == [1000, 0, 0, 1003, 1004, 1005, 1006, 1007]


def test_inject_noise_follows_the_covariance_and_opacity_gate():
    pool = _pool(opacities=[0.001, 0.5, 0.001, 0.001, 0.5, 0.5, 0.5, 0.5], n_active=3)
    key = jax.random.key(5)
    new = ops.inject_noise(pool, key, 2.0)
    eps = np.asarray(jax.random.normal(key, (8, 3), jnp.float32), np.float64)
    gate = lambda o: 1 / (1 + np.exp(-100 * ((1 - o) - 0.995)))
    s2 = np.array([0.1, 0.2, 0.3]) ** 2  # identity rotations: Σ = diag(s²)
    for i, o in ((0, 0.001), (1, 0.5), (2, 0.001)):
        np.testing.assert_allclose(_p(new, "means")[i] - _p(pool, "means")[i],
                                   s2 * eps[i] * gate(o) * 2.0, rtol=1e-4, atol=1e-7)
    np.testing.assert_array_equal(_p(new, "means")[3:], _p(pool, "means")[3:])  # inactive


def test_grow_keeps_everything_and_pads_with_inactive_zeros():
    pool = _pool(4, 4)
    opt = _opt_state(pool)
    state = DefaultStrategy().init(pool, 2.0)
    state = dict(state, grad2d=state["grad2d"] + 3.0)
    big, big_opt, big_state = P.grow(pool, opt, state, 8)
    assert big.size == 8 and np.asarray(big.active).tolist() == [1] * 4 + [0] * 4
    for k in pool.params:
        np.testing.assert_array_equal(_p(big, k)[:4], _p(pool, k))
        assert not _p(big, k)[4:].any()
    assert _mu(big_opt, "sh").tolist() == [1000, 1001, 1002, 1003, 0, 0, 0, 0]
    assert np.asarray(big_state["grad2d"]).tolist() == [3.0] * 4 + [0.0] * 4
    assert float(big_state["scene_scale"]) == 2.0 and int(big_opt[0].count) == int(opt[0].count)
    with pytest.raises(ValueError, match="not larger"):
        P.grow(pool, opt, state, 4)


def test_inactive_slots_are_culled_and_get_zero_gradients():
    import lgs_jax

    pool = _pool(2, 4)
    cam = lgs_jax.Camera(jnp.eye(4).at[2, 3].set(5.0), 50.0, 50.0, 16.0, 16.0, 32, 32)

    def loss(params):
        g = P.render_gaussians(params, pool.active)
        out = lgs_jax.render(g, cam, capacity=64)
        return jnp.sum(out.image), out.stats

    grads, stats = jax.jit(jax.grad(loss, has_aux=True))(pool.params)  # one compile, not many
    assert int(stats.n_valid) <= 2 and int(stats.n_transparent) >= 2
    for k, g in grads.items():
        assert not np.asarray(g)[2:].any(), k


def _info(grads, visible, w=20, h=10):
    return StepInfo(jnp.asarray(grads, jnp.float32), jnp.asarray(visible), 0.0, w, h)


def test_default_step_accumulates_gsplats_normalised_screen_gradient():
    pool = _pool(3, 4)
    s = DefaultStrategy(refine_stop_iter=10)
    state = s.init(pool, 1.0)
    g = np.zeros((2, 4, 2), F32)
    g[0, 0] = [0.3, 0.4]  # view 0: scaled by (W/2·B, H/2·B) = (20, 10)
    g[1, 0] = [0.1, 0.0]
    g[0, 3] = [9.0, 9.0]  # inactive: not counted
    vis = np.array([[1, 1, 0, 1], [1, 0, 0, 1]], bool)
    state, _, _ = s.step(state, pool, None, _info(g, vis), 5, None)
    np.testing.assert_allclose(np.asarray(state["grad2d"]),
                               [math.hypot(6, 4) + 2.0, 0, 0, 0], rtol=1e-6)
    assert np.asarray(state["count"]).tolist() == [2, 1, 0, 0]
    after, _, _ = s.step(state, pool, None, _info(g, vis), 10, None)  # from refine_stop_iter
    np.testing.assert_array_equal(np.asarray(after["grad2d"]), np.asarray(state["grad2d"]))


def test_default_schedule_is_gsplats():
    s = DefaultStrategy()
    due = [i for i in range(0, 16000) if s.refine_due(i)]
    assert due[0] == 600 and due[-1] == 14900 and all(i % 100 == 0 for i in due)
    assert len(due) == 144  # 600, 700, ..., 14900: opacity reset never (gsplat 1.5.3)
    reset = DefaultStrategy(opacity_reset=True, refine_start_iter=20000)
    assert [i for i in range(16000) if reset.refine_due(i)] == [3000, 6000, 9000, 12000]
    m = MCMCStrategy()
    due = [i for i in range(0, 26000) if m.refine_due(i)]
    assert due[0] == 600 and due[-1] == 24900 and len(due) == 244


def test_default_refine_clones_splits_prunes_and_zeroes_stats():
    """Slot 0: high gradient, small -> cloned; 1: high, large -> split; 2: low opacity ->
    pruned; 3: low gradient -> kept. scene_scale 10: small means max scale <= 0.1."""
    ls = np.log(np.array([[0.05] * 3, [0.5] * 3, [0.05] * 3, [0.05] * 3] + [[0.1] * 3] * 4))
    pool = _pool(4, 8, opacities=[0.5, 0.5, 0.004, 0.5] + [0.5] * 4, log_scales=ls)
    s = DefaultStrategy()
    state = dict(s.init(pool, 10.0), grad2d=jnp.array([0.01, 0.02, 0.0, 0.0001, 0, 0, 0, 0]),
                 count=jnp.array([10.0, 10, 10, 10, 0, 0, 0, 0]))  # means 1e-3, 2e-3, 0, 1e-5
    opt = _opt_state(pool)
    state2, new, new_opt, rep = s.refine(state, pool, opt, 600, jax.random.key(0), 8)
    rep = {k: int(v) for k, v in rep.items()}
    assert rep == dict(cloned=1, split=1, pruned=1, needed=2, free=4, reset=0, ok=1)
    assert np.asarray(new.active).tolist() == [1, 1, 0, 1, 1, 1, 0, 0]
    np.testing.assert_array_equal(_p(new, "means")[4], _p(pool, "means")[0])  # the clone
    np.testing.assert_allclose(np.exp(_p(new, "log_scales")[[1, 5]]), 0.5 / 1.6, rtol=1e-6)
    assert not np.asarray(state2["grad2d"]).any() and not np.asarray(state2["count"]).any()
    assert _mu(new_opt).tolist() == [1000, 0, 0, 1003, 0, 0, 1006, 1007]
    idle = s.refine(state, pool, opt, 650, jax.random.key(0), 8)  # not a refinement step
    assert np.asarray(idle[1].active).tolist() == np.asarray(pool.active).tolist()


def test_mcmc_refine_relocates_and_adds_five_percent():
    o = np.full(64, 0.5)
    o[[0, 5]] = 0.001
    pool = _pool(40, 64, opacities=o)
    s = MCMCStrategy()
    _, new, _, rep = s.refine({}, pool, _opt_state(pool), 600, jax.random.key(0), 64)
    rep = {k: int(v) for k, v in rep.items()}
    assert rep == dict(relocated=2, added=2, needed=2, free=24, ok=1)  # 40 + 40 // 20 = 42
    assert int(np.asarray(new.active).sum()) == 42
    assert float(jnp.min(jax.nn.sigmoid(new.params["logit_opacities"])[new.active])) > 0.005
    capped = s.refine({}, pool, _opt_state(pool), 600, jax.random.key(0), 41)[3]
    assert int(capped["needed"]) == 1  # the run's cap


def test_copy_rows_in_chunks_equals_a_gather():
    """`ops.copy_rows` in chunks of 3 (a partial last chunk, one chunk, none) writes each taker
    its source's row, the other rows as they were: the bits of where(takers, x[sources], x)."""
    rng = np.random.default_rng(0)
    params = dict(a=jnp.asarray(rng.normal(size=(20, 3)), jnp.float32),
                  b=jnp.asarray(rng.normal(size=(20, 2, 3)), jnp.float32))
    for taken in ([1, 4, 6, 7, 11, 12, 19], [2, 3], []):
        takers = np.isin(np.arange(20), taken)
        sources = np.where(takers, rng.choice(np.flatnonzero(~takers), 20), np.arange(20))
        got = jax.jit(ops.copy_rows, static_argnames="chunk")(
            params, jnp.asarray(takers), jnp.asarray(sources), chunk=3)
        for k, x in params.items():
            want = np.where(P.rows(takers, x), np.asarray(x)[sources], x)
            np.testing.assert_array_equal(got[k], want)


def test_relocate_and_add_is_relocate_then_sample_add_applied_only_where_finite():
    """MCMC's refinement in one (`ops.relocate_and_add`, its rows written in place) gives the
    bits of `relocate` then `sample_add`; where a share would make a scale infinite, nothing is
    applied (ok False) and the state keeps its bits."""
    o = np.full(64, 0.5)
    o[[0, 5, 7]] = 0.001
    pool, keys = _pool(40, 64, opacities=o), jax.random.split(jax.random.key(2))
    dead = jax.nn.sigmoid(pool.params["logit_opacities"]) <= 0.005
    def apart(pool, opt_state):
        p1, o1, moved = ops.relocate(pool, opt_state, dead, keys[0])
        p2, o2, added = ops.sample_add(p1, o1, 5, keys[1])
        return p2, o2, moved, added
    p2, o2, moved, added = jax.jit(apart)(pool, _opt_state(pool))
    got = jax.jit(ops.relocate_and_add)(pool, _opt_state(pool), dead, 5, keys)
    for a, b in zip(jax.tree.leaves((p2, o2, moved, added)), jax.tree.leaves(got[:4])):
        np.testing.assert_array_equal(a, b)
    assert bool(got[4]) and int(moved.sum()) == 3 and int(added.sum()) == 5
    scales = np.asarray(pool.params["log_scales"]).copy()
    scales[:40] = 100.0  # finite, but exp(100) is not in float32: a share's scale is infinite
    bad = P.Pool(dict(pool.params, log_scales=jnp.asarray(scales)), pool.active)
    got = jax.jit(ops.relocate_and_add)(bad, _opt_state(bad), dead, 5, keys)
    assert not bool(got[4]) and not np.asarray(got[2]).any() and not np.asarray(got[3]).any()
    for a, b in zip(jax.tree.leaves((bad, _opt_state(bad))), jax.tree.leaves(got[:2])):
        np.testing.assert_array_equal(a, b)


def test_clone_and_split_is_duplicate_then_split_applied_only_where_finite():
    """3DGS's growth in one (`ops.clone_and_split`, its rows written in place) gives the bits
    of `duplicate` then `split`, clones not split; where a child's scale would be infinite,
    nothing is applied (ok False) and the state keeps its bits."""
    pool = _pool(6, 16)
    clone = jnp.arange(16) < 2
    grow = jnp.arange(16) < 4
    priority = jnp.arange(16, dtype=jnp.float32)

    def apart(pool, opt_state):
        p1, o1, cloned = ops.duplicate(pool, opt_state, clone, priority)
        p2, o2, split = ops.split(p1, o1, grow & ~clone, jax.random.key(1), priority)
        return p2, o2, cloned, split
    want = jax.jit(apart)(pool, _opt_state(pool))
    got = jax.jit(lambda p, o: ops.clone_and_split(p, o, clone, grow & ~clone,
                                                   jax.random.key(1), priority))(
        pool, _opt_state(pool))
    for a, b in zip(jax.tree.leaves(want), jax.tree.leaves(got[:4])):
        np.testing.assert_array_equal(a, b)
    assert bool(got[4]) and int(got[2].sum()) == 2 and int(got[3].sum()) == 2
    assert int(got[0].active.sum()) == 10
    scales = np.asarray(pool.params["log_scales"]).copy()
    scales[3] = 100.0  # a parent whose scale exp(100) is not a float32
    bad = P.Pool(dict(pool.params, log_scales=jnp.asarray(scales)), pool.active)
    got = ops.clone_and_split(bad, _opt_state(bad), clone, grow & ~clone, jax.random.key(1),
                              priority)
    assert not bool(got[4]) and not np.asarray(got[2]).any() and not np.asarray(got[3]).any()
    for a, b in zip(jax.tree.leaves((bad, _opt_state(bad))), jax.tree.leaves(got[:2])):
        np.testing.assert_array_equal(a, b)


@pytest.mark.parametrize("strategy", [MCMCStrategy(), DefaultStrategy()],
                         ids=["mcmc", "default"])
def test_a_refinement_in_place_holds_no_second_copy_of_the_pool(strategy):
    """A refinement with the state donated (`fit`'s), SH degree 3: XLA's temporaries are under
    the parameters' bytes (gathering the whole pool, as both once did, took twice them: the
    peak of a run's memory)."""
    n = 2**16
    pool = _pool(n // 3, n)
    pool = P.Pool(dict(pool.params, sh=jnp.zeros((n, 16, 3), jnp.float32)), pool.active)
    compiled = S._refine_in_place.lower(strategy.init(pool, 10.0), pool, _opt_state(pool), 600,
                                        jax.random.key(0), strategy=strategy, cap=n).compile()
    params = sum(x.nbytes for x in jax.tree.leaves(pool.params))
    assert compiled.memory_analysis().temp_size_in_bytes < params


def test_refine_grows_the_pool_by_doubling_until_it_fits():
    """A full pool of 4: the clones need 2 slots -> grown to 8 first, then applied; at the cap
    (4) the highest-gradient candidate wins."""
    ls = np.log(np.full((4, 3), 0.05))
    pool = _pool(4, 4, log_scales=ls)
    s = DefaultStrategy()
    state = dict(s.init(pool, 10.0), grad2d=jnp.array([0.01, 0.0, 0.03, 0.0]),
                 count=jnp.ones(4))
    opt = _opt_state(pool)
    state2, new, new_opt, rep = S.refine(s, state, pool, opt, 600, jax.random.key(0), 100)
    assert rep["grown_to"] == 8 and rep["cloned"] == 2 and new.size == 8
    assert np.asarray(new.active).tolist() == [1] * 6 + [0] * 2
    assert state2["grad2d"].shape == (8,) and _mu(new_opt).shape == (8,)
    pool5 = _pool(4, 5, log_scales=np.log(np.full((5, 3), 0.05)))
    state5 = dict(s.init(pool5, 10.0), grad2d=jnp.array([0.01, 0.0, 0.03, 0.0, 0.0]),
                  count=jnp.ones(5))
    _, new, _, rep = S.refine(s, state5, pool5, _opt_state(pool5), 600, jax.random.key(0), 5)
    assert rep["grown_to"] == 0 and rep["cloned"] == 1
    np.testing.assert_array_equal(_p(new, "means")[4], _p(pool5, "means")[2])


def test_refine_in_place_gives_the_same_bits_and_uses_up_its_arguments():
    """`fit`'s refinement donates the state: the same result as the kept call, at the pool's
    largest size and below it; where the pool must grow first, the grown state is the one
    used up and the result is the kept call's."""
    o = np.full(64, 0.5)
    o[[0, 5]] = 0.001
    pool = _pool(40, 64, opacities=o)
    s = MCMCStrategy()
    for cap in (64, 128):  # the largest pool; below it, with room for the additions
        kept = S.refine(s, {}, pool, _opt_state(pool), 600, jax.random.key(0), cap)
        copy = jax.tree.map(jnp.copy, (pool, _opt_state(pool)))
        done = S.refine(s, {}, *copy, 600, jax.random.key(0), cap, in_place=True)
        for a, b in zip(jax.tree.leaves(kept[:3]), jax.tree.leaves(done[:3])):
            np.testing.assert_array_equal(a, b)
        assert kept[3] == done[3] and kept[3]["grown_to"] == 0
        assert all(x.is_deleted() for x in jax.tree.leaves(copy)), cap
    full = _pool(4, 4, log_scales=np.log(np.full((4, 3), 0.05)))  # clones need 2 more slots
    d = DefaultStrategy()
    state = dict(d.init(full, 10.0), grad2d=jnp.array([0.01, 0.0, 0.03, 0.0]),
                 count=jnp.ones(4))
    kept = S.refine(d, state, full, _opt_state(full), 600, jax.random.key(0), 100)
    args = jax.tree.map(jnp.copy, (state, full, _opt_state(full)))
    done = S.refine(d, *args, 600, jax.random.key(0), 100, in_place=True)
    assert kept[3] == done[3] and done[3]["grown_to"] == 8
    for a, b in zip(jax.tree.leaves(kept[:3]), jax.tree.leaves(done[:3])):
        np.testing.assert_array_equal(a, b)
