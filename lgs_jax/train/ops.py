"""Densification operations on a pool, in static shapes: gsplat 1.5.3's `strategy/ops.py`.

Each is a pure function (pool, opt_state, ...) -> (pool, opt_state, ...) that jits: masks in,
masks out, new Gaussians placed in free slots (`allocate`), Adam moments carried as gsplat does:

  duplicate      the copy gets the original's parameters and zero moments; the original keeps its
                 moments.
  split          the Gaussian becomes two: means + R·diag(s)·ε_k (ε_k ~ N(0, I), k = 1, 2),
                 log-scales log(s / 1.6), the rest copied (revised_opacity: opacity
                 1 − sqrt(1 − o), arXiv:2404.06109); child 1 takes the original's slot, child 2 a
                 free one; both get zero moments.
  prune          slots become free; their moments are zeroed (so Adam leaves them still).
  reset_opacity  logit opacities clamped to at most logit(value); every opacity moment zeroed
                 (the other groups keep theirs).
  relocate       (MCMC) each dead slot copies an alive Gaussian sampled with probability ∝ opacity;
                 a Gaussian sampled n − 1 times is shared n ways (`relocation`, Eq. 9 of 3DGS as
                 MCMC): its opacity and scale change and its moments are zeroed. The dead slots
                 keep their own (old) moments, as in gsplat and the paper's code.
  sample_add     (MCMC) n new Gaussians copy sampled ones as in relocate; the new slots get zero
                 moments, the sampled sources keep theirs (gsplat).
  inject_noise   (MCMC) means += Σ·ε·σ(100·((1 − o) − 0.995))·scaler, ε ~ N(0, I),
                 Σ = R diag(s²) Rᵀ; no moment changes.

Where gsplat appends new Gaussians, these fill free slots in ascending slot order; candidates
are taken in `priority` order (highest first) when the free slots run short (at the cap).
Random numbers come from a JAX key (gsplat uses torch's generator, so draws differ).
"""

from __future__ import annotations

import math

import jax
import jax.numpy as jnp
import numpy as np

from ..projection import quat_to_rotmat
from .optim import carry_moments
from .pool import Pool, rows

N_MAX = 51  # largest share count of `relocation` (gsplat's binomial table is 51 x 51)


def allocate(want, free, priority=None):
    """Pair candidate Gaussians (`want`) with `free` slots.

    Candidates are ranked by `priority`, highest first (ties and priority None: slot order);
    free slots in ascending order; the r-th candidate gets the r-th free slot, while slots last.
    Returns (src, filled, granted): filled[j] is a free slot that receives a Gaussian, src[j] its
    candidate (src[j] = j for other slots), granted[i] a candidate that got a slot.
    """
    n = want.shape[0]
    idx = jnp.arange(n)
    key = jnp.where(want, 0.0 if priority is None else -priority, jnp.inf)
    order = jnp.argsort(key, stable=True)  # candidates first
    free_rank = jnp.cumsum(free) - 1
    filled = free & (free_rank < jnp.sum(want))
    src = jnp.where(filled, order[jnp.clip(free_rank, 0, n - 1)], idx)
    granted = want & (jnp.argsort(order) < jnp.sum(free))
    return src, filled, granted


def duplicate(pool: Pool, opt_state, mask, priority=None):
    """Clone the active Gaussians in `mask` into free slots. Returns (pool, opt_state, granted)."""
    src, filled, granted = allocate(mask & pool.active, ~pool.active, priority)
    params = {k: v[src] for k, v in pool.params.items()}
    return Pool(params, pool.active | filled), carry_moments(opt_state, src, filled), granted


def _covariance_factor(params):
    """(R, s): rotation matrices of the normalised quaternions and scales exp(log_scales)."""
    return quat_to_rotmat(params["quats"]), jnp.exp(params["log_scales"])


def split(pool: Pool, opt_state, mask, key, priority=None, revised_opacity: bool = False):
    """Split the active Gaussians in `mask` in two (module docstring). Returns (pool, opt_state,
    granted)."""
    src, filled, granted = allocate(mask & pool.active, ~pool.active, priority)
    p = {k: v[src] for k, v in pool.params.items()}  # child 2's slots hold their parent
    child = granted | filled
    r, s = _covariance_factor(p)
    eps = jax.random.normal(key, (2,) + p["means"].shape, p["means"].dtype)
    eps = jnp.where(filled[:, None], eps[1][src], eps[0])  # child k of Gaussian i: ε_k[i]
    offset = jnp.sum(r * (s * eps)[:, None, :], -1)  # R·diag(s)·ε as multiply-adds
    new = dict(p, means=p["means"] + offset, log_scales=jnp.log(s / 1.6))
    if revised_opacity:
        o = 1.0 - jnp.sqrt(1.0 - jax.nn.sigmoid(p["logit_opacities"]))
        new["logit_opacities"] = jnp.log(o / (1.0 - o))
    params = {k: jnp.where(rows(child, v), new[k], v) for k, v in p.items()}
    return (Pool(params, pool.active | filled), carry_moments(opt_state, src, child), granted)


def prune(pool: Pool, opt_state, mask):
    """Free the active slots in `mask`, zeroing their moments. Returns (pool, opt_state)."""
    gone = mask & pool.active
    return (Pool(pool.params, pool.active & ~gone),
            carry_moments(opt_state, jnp.arange(pool.size), gone))


def reset_opacity(pool: Pool, opt_state, value: float):
    """Clamp opacities to at most `value` (gsplat: logit(value) in float32, then a clamp) and
    zero the opacity group's moments. Returns (pool, opt_state)."""
    lo = pool.params["logit_opacities"]
    v = jnp.asarray(value, lo.dtype)
    params = dict(pool.params, logit_opacities=jnp.minimum(lo, jnp.log(v / (1 - v))))
    fresh = jnp.ones(pool.size, bool)
    return (Pool(params, pool.active),
            carry_moments(opt_state, jnp.arange(pool.size), fresh, groups=("logit_opacities",)))


def _share_table() -> np.ndarray:
    """T[n, k] = (−1)^k C(n, k + 1) / sqrt(k + 1) for k < n (0 elsewhere), n = 0..N_MAX."""
    t = np.zeros((N_MAX + 1, N_MAX))
    for n in range(N_MAX + 1):
        for k in range(n):
            t[n, k] = (-1) ** k * math.comb(n, k + 1) / math.sqrt(k + 1)
    return t


def relocation(opacities, scales, ratios):
    """gsplat's `compute_relocation` (3DGS as MCMC, Eq. 9): a Gaussian shared n ways
    (n = ratios clamped to [1, 51]) gets opacity o' = 1 − (1 − o)^(1/n) and scales s·o / D with

        D = Σ_{i=1..n} Σ_{k=0..i−1} C(i−1, k) (−1)^k o'^(k+1) / sqrt(k + 1)
          = Σ_{k=0..n−1} (−1)^k C(n, k+1) o'^(k+1) / sqrt(k + 1)   (Σ_{i>k} C(i−1, k) = C(n, k+1)).

    Returns (new opacities (N,), new scales (N, 3)), in the inputs' dtype."""
    dt = opacities.dtype
    n = jnp.clip(ratios, 1, N_MAX).astype(jnp.int32)
    new_o = 1.0 - jnp.power(1.0 - opacities, 1.0 / n.astype(dt))
    table = jnp.asarray(_share_table(), dt)
    denom, power = jnp.zeros_like(new_o), new_o
    for k in range(N_MAX):
        denom = denom + table[:, k][n] * power
        power = power * new_o
    return new_o, scales * (opacities / denom)[:, None]


def _share(params, sources, counts, min_opacity: float):
    """params with each sampled source (counts > 0) given its relocated opacity and scale for
    counts + 1 shares, opacity clamped to [min_opacity, 1 − float32 ε] (gsplat)."""
    o = jax.nn.sigmoid(params["logit_opacities"])
    new_o, new_s = relocation(o, jnp.exp(params["log_scales"]), counts + 1)
    new_o = jnp.clip(new_o, min_opacity, 1.0 - float(np.finfo(np.float32).eps))
    hit = counts > 0
    return dict(params, logit_opacities=jnp.where(hit, jnp.log(new_o / (1 - new_o)),
                                                  params["logit_opacities"]),
                log_scales=jnp.where(hit[:, None], jnp.log(new_s), params["log_scales"]))


def _sample(key, pool: Pool, eligible, takers):
    """(sources, counts, ok): for every slot in `takers` a Gaussian drawn from `eligible` with
    probability ∝ opacity (sources[j] = j elsewhere), and how often each was drawn. ok is
    False (and nothing drawn) when no eligible Gaussian has opacity > 0."""
    o = jax.nn.sigmoid(pool.params["logit_opacities"])
    eligible = eligible & (o > 0)
    ok = jnp.any(eligible)
    weights = jnp.where(eligible, o, 0.0)
    # Inverse CDF over the float32 running sum of the weights, as torch.multinomial (gsplat)
    # draws: O(N log N). (jax.random.categorical with shape (N,) draws N x N Gumbel variables.)
    # A zero weight is an empty interval of the running sum, so it is never drawn.
    draws = jax.random.choice(key, pool.size, (pool.size,), p=jnp.where(ok, weights, 1.0))
    takers = takers & ok
    sources = jnp.where(takers, draws, jnp.arange(pool.size))
    counts = jnp.zeros(pool.size, jnp.int32).at[sources].add(takers.astype(jnp.int32))
    return sources, counts, takers


def relocate(pool: Pool, opt_state, dead, key, min_opacity: float = 0.005):
    """Move the `dead` active Gaussians onto alive ones (module docstring). Returns (pool,
    opt_state, moved): moved marks the dead slots that were relocated (none if none is alive)."""
    dead = dead & pool.active
    sources, counts, moved = _sample(key, pool, pool.active & ~dead, dead)
    shared = _share(pool.params, sources, counts, min_opacity)
    params = {k: jnp.where(rows(moved, v), v[sources], v) for k, v in shared.items()}
    opt_state = carry_moments(opt_state, jnp.arange(pool.size), counts > 0)
    return Pool(params, pool.active), opt_state, moved


def sample_add(pool: Pool, opt_state, n, key, min_opacity: float = 0.005):
    """Add `n` Gaussians (at most the free slots) copied from active ones sampled ∝ opacity
    (module docstring). Returns (pool, opt_state, added mask)."""
    free = ~pool.active
    takers = free & (jnp.cumsum(free) <= n)
    sources, counts, added = _sample(key, pool, pool.active, takers)
    shared = _share(pool.params, sources, counts, min_opacity)
    params = {k: jnp.where(rows(added, v), v[sources], v) for k, v in shared.items()}
    opt_state = carry_moments(opt_state, jnp.arange(pool.size), added)
    return Pool(params, pool.active | added), opt_state, added


def inject_noise(pool: Pool, key, scaler, slots=None):
    """Perturb the active means (module docstring; gsplat's `inject_noise_to_position`); row i
    draws slot slots[i]'s ε (`StepInfo.slots`; None: slot i)."""
    p = pool.params
    r, s = _covariance_factor(p)
    o = jax.nn.sigmoid(p["logit_opacities"])
    gate = 1.0 / (1.0 + jnp.exp(-100.0 * ((1.0 - o) - 0.995)))
    eps = jax.random.normal(key, p["means"].shape, p["means"].dtype)
    if slots is not None:
        eps = jnp.take(eps, slots, axis=0)
    eps = eps * (gate * scaler)[:, None]
    # Σ·ε = R·diag(s²)·Rᵀ·ε, as multiply-adds (no TF32 on GPUs)
    local = jnp.sum(r * eps[:, :, None], 1) * s * s  # diag(s²)·Rᵀ·ε
    noise = jnp.sum(r * local[:, None, :], -1)
    means = jnp.where(pool.active[:, None], p["means"] + noise, p["means"])
    return Pool(dict(p, means=means), pool.active)
