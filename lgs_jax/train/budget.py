"""`BudgetStrategy`: 3DGS as MCMC with its Gaussian count on a budget schedule and the Gaussians
that no training view sees relocated; the strategy of the fast recipe (`recipes`).

Two techniques on top of `MCMCStrategy` (whose relocation of dead Gaussians, noise on the means
and opacity and scale regularisers it keeps), each a switch:

  growth "budget" (Taming 3DGS, Mallick et al. 2024, Eq. 2): at a refinement at step s the count
    is raised to the budget curve
        target(s) = S + (B − S)·(2t − t²),   t = clip((s − refine_start_iter) /
                                                      (budget_until − refine_start_iter), 0, 1),
    a parabola from the starting count S with its steepest rise first and zero slope where it
    reaches the budget B = min(budget·S, cap_max, cap) at budget_until (cap: the run's
    max_gaussians). growth "mcmc": MCMC's own n → min(B, n + n // 20) per refinement instead
    (gsplat), the same final count, so the two differ only in the schedule.
  unseen_after > 0 (Speedy-Splat, Hanson et al. 2025: remove the Gaussians that contribute
    nothing; here, in a pool of static size, by relocation): an active Gaussian that has had
    no tile pair in any training view for `unseen_after` steps (its `last_seen`, the last step
    at which some view of a step saw it) counts as dead, like one below `min_opacity`, and is
    relocated onto a live one. A relocated or added Gaussian starts its count afresh.

The pool holds B slots from the start (`max_count`): it never grows, so the step never
recompiles for it. The state: `start` (S, int32), `last_seen` (int32 per Gaussian).
"""

from __future__ import annotations

import dataclasses
from typing import Literal

import jax
import jax.numpy as jnp

from . import ops
from .options import option
from .pool import Pool
from .strategy import MCMCStrategy, StepInfo


def budget_curve(step, start: int, budget: int, begin: int, until: int):
    """Taming 3DGS's target count at refinement step `step` (module docstring): S + (B − S)·
    t·(2 − t) rounded down, t = clip((step − begin) / (until − begin), 0, 1), in float32
    (t·(2 − t) never falls as t rises, and is exactly 1 at t = 1): non-decreasing in `step`,
    `start` at or before `begin`, at most `budget` (callers clip it there, `BudgetStrategy`:
    float32 may round B − S up above 2^24) and `budget` from `until` on."""
    step = jnp.asarray(step, jnp.float32)
    t = jnp.clip((step - begin) / max(until - begin, 1), 0.0, 1.0)
    # 1 from `until` on exactly (XLA may divide by the constant as a multiplication by its
    # reciprocal, which can leave t a rounding below 1 there)
    t = jnp.where(step >= until, 1.0, t)
    rise = jnp.asarray(budget - start, jnp.float32) * (t * (2.0 - t))  # 2t − t², monotone
    return jnp.asarray(start, jnp.int32) + jnp.floor(rise).astype(jnp.int32)


def budget_count(start, multiple: int, limit: int):
    """min(multiple·start, limit) without int32 overflow (start an int or an int32 array)."""
    start = jnp.asarray(start, jnp.int32)
    return jnp.where(start > limit // multiple, jnp.int32(limit), start * multiple)


def _count(mask):
    return jnp.sum(mask, dtype=jnp.int32)


@dataclasses.dataclass(frozen=True)
class BudgetStrategy(MCMCStrategy):
    """MCMC with a budget schedule and the relocation of unseen Gaussians (module docstring).
    Its step defaults suit the fast recipe's 2,000-step run: refinements every 100 steps from
    step 300, the budget reached at step 1,000 (where the coarse-to-fine schedule reaches full
    resolution), relocations until step 1,700."""

    refine_start_iter: int = option(300, "refine after this step", low=0)
    refine_stop_iter: int = option(1_700, "refine before this step", low=0)
    budget: int = option(
        20, "the Gaussian count the schedule reaches: this times the starting count, at most "
            "cap_max (Taming 3DGS's multiplier budget)", low=1)
    budget_until: int = option(1_000, "the step at which the count reaches the budget", low=1)
    growth: Literal["budget", "mcmc"] = option(
        "budget", "how the count rises to the budget: budget (Taming 3DGS's parabola, steepest "
                  "first) or mcmc (5% per refinement, gsplat's MCMC)")
    unseen_after: int = option(
        500, "relocate Gaussians that no training view has seen for this many steps, as "
             "MCMC relocates dead ones (Speedy-Splat's pruning; 0: never)", low=0)

    def _limit(self, cap: int) -> int:
        return min(self.cap_max, cap)

    def init(self, pool: Pool, scene_scale: float):
        return dict(start=_count(pool.active), last_seen=jnp.zeros(pool.size, jnp.int32))

    def step(self, state, pool: Pool, opt_state, info: StepInfo, step, key):
        state, pool, opt_state = super().step(state, pool, opt_state, info, step, key)
        seen = jnp.any(info.visible, 0) & pool.active
        last_seen = jnp.where(seen, jnp.asarray(step, jnp.int32), state["last_seen"])
        return dict(state, last_seen=last_seen), pool, opt_state

    def max_count(self, initial: int, steps: int, cap: int) -> int | None:
        """The budget B = min(budget·initial, cap_max, cap) (growth "budget": no target exceeds
        it), or MCMC's replay of its additions up to B (growth "mcmc")."""
        bound = min(self.budget * initial, self._limit(cap))
        if self.growth == "budget":
            reached = any(self.refine_due(s) for s in range(steps))
            return bound if reached else initial
        return MCMCStrategy.max_count(dataclasses.replace(self, cap_max=bound), initial, steps,
                                      cap)

    def _target(self, state, n, step, cap: int):
        """The count after this refinement's additions (module docstring)."""
        top = budget_count(state["start"], self.budget, self._limit(cap))
        if self.growth == "budget":
            curve = budget_curve(step, state["start"], top, self.refine_start_iter,
                                 self.budget_until)
            return jnp.minimum(curve, top)
        return jnp.minimum(top, n + n // 20)

    def refine(self, state, pool: Pool, opt_state, step, key, cap: int):
        step = jnp.asarray(step, jnp.int32)
        o = jax.nn.sigmoid(pool.params["logit_opacities"])
        unseen = jnp.zeros(pool.size, bool)
        if self.unseen_after:
            unseen = pool.active & (step - state["last_seen"] >= self.unseen_after)
        dead = (o <= self.min_opacity) | unseen
        n = _count(pool.active)
        want = jnp.maximum(self._target(state, n, step, cap) - n, 0)
        free = _count(~pool.active)
        pool, opt_state, moved, added, ok = ops.relocate_and_add(
            pool, opt_state, dead, want, jax.random.split(key), self.min_opacity)
        last_seen = jnp.where(moved | added, step, state["last_seen"])
        report = dict(relocated=_count(moved), unseen=_count(moved & unseen), added=_count(added),
                      needed=want, free=free, ok=ok)
        return dict(state, last_seen=last_seen), pool, opt_state, report
