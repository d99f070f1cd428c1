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

In place: `relocate_and_add` (MCMC's refinement) and `clone_and_split` (3DGS's growth) plan
their moves first (the slots; the new opacity and scale columns, or the split children's
columns from their parents'), check that what they would write is finite, then write: the
copies row by row in chunks (`copy_rows`), the new columns and the moments elementwise
(`optim.zero_moments`). With the state donated, XLA then holds the pool once; a gather of
every row (x[sources] over the pool) would hold it twice.
"""

from __future__ import annotations

import math
from typing import NamedTuple

import jax
import jax.numpy as jnp
import numpy as np
from jax import lax

from ..projection import quat_to_rotmat
from .optim import zero_moments
from .pool import Pool, rows

N_MAX = 51  # largest share count of `relocation` (gsplat's binomial table is 51 x 51)
COPY_CHUNK = 16_384  # rows a step of `copy_rows` copies


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
    return (Pool(copy_rows(pool.params, filled, src), pool.active | filled),
            zero_moments(opt_state, filled), granted)


def _covariance_factor(params):
    """(R, s): rotation matrices of the normalised quaternions and scales exp(log_scales)."""
    return quat_to_rotmat(params["quats"]), jnp.exp(params["log_scales"])


SPLIT_COLUMNS = ("means", "quats", "log_scales", "logit_opacities")  # what a child's values read


def _split_values(params, src, filled, key, revised_opacity: bool) -> dict:
    """The split children's new columns, every row as if it held its parent (row src[i]; the
    columns a child's values read, gathered alone): means, log_scales (and logit_opacities)."""
    p = {k: params[k][src] for k in SPLIT_COLUMNS}  # child 2's slots hold their parent
    r, s = _covariance_factor(p)
    eps = jax.random.normal(key, (2,) + p["means"].shape, p["means"].dtype)
    eps = jnp.where(filled[:, None], eps[1][src], eps[0])  # child k of Gaussian i: ε_k[i]
    offset = jnp.sum(r * (s * eps)[:, None, :], -1)  # R·diag(s)·ε as multiply-adds
    new = dict(means=p["means"] + offset, log_scales=jnp.log(s / 1.6))
    if revised_opacity:
        o = 1.0 - jnp.sqrt(1.0 - jax.nn.sigmoid(p["logit_opacities"]))
        new["logit_opacities"] = jnp.log(o / (1.0 - o))
    return new


def _write_split(pool: Pool, opt_state, src, filled, child, new, ok=True):
    """The split made (where ok): parents copied into their second child's slot, the children's
    new columns written, their moments zeroed."""
    filled, child = filled & ok, child & ok
    params = copy_rows(pool.params, filled, src)
    params = {k: jnp.where(rows(child, v), new[k], v) if k in new else v
              for k, v in params.items()}
    return Pool(params, pool.active | filled), zero_moments(opt_state, child)


def split(pool: Pool, opt_state, mask, key, priority=None, revised_opacity: bool = False):
    """Split the active Gaussians in `mask` in two (module docstring). Returns (pool, opt_state,
    granted)."""
    src, filled, granted = allocate(mask & pool.active, ~pool.active, priority)
    new = _split_values(pool.params, src, filled, key, revised_opacity)
    return *_write_split(pool, opt_state, src, filled, granted | filled, new), granted


def clone_and_split(pool: Pool, opt_state, clone, split_mask, key, priority=None,
                    revised_opacity: bool = False):
    """`duplicate` of `clone` then `split` of `split_mask` (clones are not split), the same
    bits, applied only where every value the split writes is finite, and in place: the split is
    planned (its slots, and its children's columns from their parents') before a row is
    written, then both are written row by row (`copy_rows`). Returns (pool, opt_state, cloned,
    split, ok)."""
    active = pool.active
    c_src, c_filled, cloned = allocate(clone & active, ~active, priority)
    s_src, s_filled, split_ = allocate(split_mask & active, ~(active | c_filled), priority)
    new = _split_values(pool.params, s_src, s_filled, key, revised_opacity)
    child = split_ | s_filled
    ok = _finite_on(child, *new.values())
    c_filled = c_filled & ok
    pool = Pool(copy_rows(pool.params, c_filled, c_src), active | c_filled)
    opt_state = zero_moments(opt_state, c_filled)
    pool, opt_state = _write_split(pool, opt_state, s_src, s_filled, child, new, ok)
    return pool, opt_state, cloned & ok, split_ & ok, ok


def prune(pool: Pool, opt_state, mask):
    """Free the active slots in `mask`, zeroing their moments. Returns (pool, opt_state)."""
    gone = mask & pool.active
    return (Pool(pool.params, pool.active & ~gone),
            zero_moments(opt_state, gone))


def reset_opacity(pool: Pool, opt_state, value: float):
    """Clamp opacities to at most `value` (gsplat: logit(value) in float32, then a clamp) and
    zero the opacity group's moments. Returns (pool, opt_state)."""
    lo = pool.params["logit_opacities"]
    v = jnp.asarray(value, lo.dtype)
    params = dict(pool.params, logit_opacities=jnp.minimum(lo, jnp.log(v / (1 - v))))
    fresh = jnp.ones(pool.size, bool)
    return Pool(params, pool.active), zero_moments(opt_state, fresh, groups=("logit_opacities",))


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


def copy_rows(params: dict, takers, sources, chunk: int = COPY_CHUNK) -> dict:
    """params with row j set to row sources[j] for every j in `takers` (no taker a source),
    in a loop over chunks of `chunk` takers: the temporaries are one chunk's rows and the
    params are written in place where they are donated (a gather of the whole pool would hold
    a second copy of it). Takers are copied in slot order; each row is written once."""
    n = takers.shape[0]
    chunk = min(chunk, n)
    count = jnp.sum(takers, dtype=jnp.int32)
    padded = -(-n // chunk) * chunk
    targets = jnp.nonzero(takers, size=padded, fill_value=n)[0].astype(jnp.int32)
    froms = jnp.take(sources, jnp.minimum(targets, n - 1), axis=0)

    def body(i, p):
        at = lax.dynamic_slice(targets, (i * chunk,), (chunk,))
        src = lax.dynamic_slice(froms, (i * chunk,), (chunk,))
        return {k: v.at[at].set(jnp.take(v, src, axis=0), mode="drop") for k, v in p.items()}

    return lax.fori_loop(0, (count + chunk - 1) // chunk, body, params)


def _share(logit_opacities, log_scales, counts, min_opacity: float):
    """The opacity and scale columns with each sampled source (counts > 0) given its relocated
    opacity and scale for counts + 1 shares, opacity clamped to [min_opacity, 1 − float32 ε]
    (gsplat)."""
    o = jax.nn.sigmoid(logit_opacities)
    new_o, new_s = relocation(o, jnp.exp(log_scales), counts + 1)
    new_o = jnp.clip(new_o, min_opacity, 1.0 - float(np.finfo(np.float32).eps))
    hit = counts > 0
    return (jnp.where(hit, jnp.log(new_o / (1 - new_o)), logit_opacities),
            jnp.where(hit[:, None], jnp.log(new_s), log_scales))


def _sample(key, logit_opacities, eligible, takers):
    """(sources, counts, takers): for every slot in `takers` a Gaussian drawn from `eligible`
    with probability ∝ opacity (sources[j] = j elsewhere), and how often each was drawn. None
    is drawn (takers all False) when no eligible Gaussian has opacity > 0."""
    n = logit_opacities.shape[0]
    o = jax.nn.sigmoid(logit_opacities)
    eligible = eligible & (o > 0)
    ok = jnp.any(eligible)
    weights = jnp.where(eligible, o, 0.0)
    # Inverse CDF over the float32 running sum of the weights, as torch.multinomial (gsplat)
    # draws: O(N log N). (jax.random.categorical with shape (N,) draws N x N Gumbel variables.)
    # A zero weight is an empty interval of the running sum, so it is never drawn.
    draws = jax.random.choice(key, n, (n,), p=jnp.where(ok, weights, 1.0))
    takers = takers & ok
    sources = jnp.where(takers, draws, jnp.arange(n))
    counts = jnp.zeros(n, jnp.int32).at[sources].add(takers.astype(jnp.int32))
    return sources, counts, takers


def _finite_on(mask, *columns):
    """Whether the per-Gaussian `columns` are finite on the rows in `mask`."""
    return jnp.all(jnp.stack([jnp.all(jnp.isfinite(x) | rows(~mask, x)) for x in columns]))


def _columns(pool: Pool):
    return pool.params["logit_opacities"], pool.params["log_scales"]


class _Moves(NamedTuple):
    """A relocation's or addition's plan: each of `takers` gets a copy of row sources[j]; the
    opacity and scale columns with the drawn sources' (`shared`) new values, the copies not yet
    made; `fresh`: the rows whose moments become zero."""

    sources: jax.Array
    takers: jax.Array
    logit_opacities: jax.Array
    log_scales: jax.Array
    shared: jax.Array
    fresh: jax.Array

    def finite(self):
        """Whether the values it writes are finite: the shared rows' new columns (the takers
        copy shared rows; the rest of a row is copied as it is)."""
        return _finite_on(self.shared, self.logit_opacities, self.log_scales)

    def columns_after(self):
        """The opacity and scale columns once the copies are made."""
        src = self.sources
        return (jnp.where(self.takers, self.logit_opacities[src], self.logit_opacities),
                jnp.where(self.takers[:, None], self.log_scales[src], self.log_scales))


def _plan(key, logit_opacities, log_scales, eligible, takers, min_opacity, fresh_sources):
    sources, counts, takers = _sample(key, logit_opacities, eligible, takers)
    lo, ls = _share(logit_opacities, log_scales, counts, min_opacity)
    shared = counts > 0
    return _Moves(sources, takers, lo, ls, shared, shared if fresh_sources else takers)


def _apply(pool: Pool, opt_state, moves: _Moves, ok=True):
    """The plan made (where ok): the columns written, the rows copied, the takers active."""
    takers = moves.takers & ok
    p = dict(pool.params, logit_opacities=jnp.where(ok, moves.logit_opacities,
                                                      pool.params["logit_opacities"]),
             log_scales=jnp.where(ok, moves.log_scales, pool.params["log_scales"]))
    return (Pool(copy_rows(p, takers, moves.sources), pool.active | takers),
            zero_moments(opt_state, moves.fresh & ok))


def _relocation_plan(pool: Pool, dead, key, min_opacity, columns=None) -> _Moves:
    """`relocate`'s plan, on the pool's opacity and scale columns or on `columns`."""
    dead = dead & pool.active
    return _plan(key, *(columns or _columns(pool)), pool.active & ~dead, dead, min_opacity,
                 True)


def _addition_plan(pool: Pool, n, key, min_opacity, columns=None) -> _Moves:
    """`sample_add`'s plan, on the pool's opacity and scale columns or on `columns`."""
    free = ~pool.active
    return _plan(key, *(columns or _columns(pool)), pool.active,
                 free & (jnp.cumsum(free) <= n), min_opacity, False)


def relocate(pool: Pool, opt_state, dead, key, min_opacity: float = 0.005):
    """Move the `dead` active Gaussians onto alive ones (module docstring). Returns (pool,
    opt_state, moved): moved marks the dead slots that were relocated (none if none is alive)."""
    moves = _relocation_plan(pool, dead, key, min_opacity)
    return *_apply(pool, opt_state, moves), moves.takers


def sample_add(pool: Pool, opt_state, n, key, min_opacity: float = 0.005):
    """Add `n` Gaussians (at most the free slots) copied from active ones sampled ∝ opacity
    (module docstring). Returns (pool, opt_state, added mask)."""
    moves = _addition_plan(pool, n, key, min_opacity)
    return *_apply(pool, opt_state, moves), moves.takers


def relocate_and_add(pool: Pool, opt_state, dead, n, keys, min_opacity: float = 0.005):
    """`relocate` then `sample_add` (keys: theirs), the same bits, applied only where every
    value they write is finite, and in place: both are planned on the opacity and scale columns
    before a row is written (the addition draws from the columns the relocation leaves), then
    written (`copy_rows`). `n` is counted before the relocation (which changes no slot's
    activity). Returns (pool, opt_state, moved, added, ok)."""
    first = _relocation_plan(pool, dead, keys[0], min_opacity)
    second = _addition_plan(pool, n, keys[1], min_opacity, first.columns_after())
    ok = first.finite() & second.finite()
    pool, opt_state = _apply(pool, opt_state, first, ok)
    pool, opt_state = _apply(pool, opt_state, second, ok)
    return pool, opt_state, first.takers & ok, second.takers & ok, ok


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
