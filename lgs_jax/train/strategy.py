"""Densification strategies: gsplat 1.5.3's `DefaultStrategy` and `MCMCStrategy`, in static shapes.

The interface (`Strategy`), optax-like: a frozen dataclass of settings with pure functions over
pytrees, called by `fit` as

    state = strategy.init(pool, scene_scale)
    loss += strategy.regularizer(params, active)                        # inside the loss
    state, pool, opt_state = strategy.step(state, pool, opt_state, info, s, key)   # every step
    if strategy.refine_due(s):                                          # on the host
        state, pool, opt_state, report = strategy.refine(state, pool, opt_state, s, key, cap)

`step` runs inside the jitted training step after the optimizer update (gsplat's
`step_post_backward` runs after `optimizer.step()` in simple_trainer), with s the 0-based index
of the step just taken; `refine` is jitted separately at the steps `refine_due` names, and its
report's `needed` / `free` counts of new slots let `fit` grow the pool and run it again before
anything is lost (`ops.allocate` ranks candidates when the cap leaves too few slots). A
strategy's state leaves with a leading axis of the pool size are per-Gaussian: `pool.grow` pads
them with zeros. To write one, subclass `Strategy` (a frozen dataclass) and override what differs.
"""

from __future__ import annotations

import dataclasses
from typing import Any

import jax
import jax.numpy as jnp

from . import ops
from .options import check, option
from .pool import Pool


@jax.tree_util.register_dataclass
@dataclasses.dataclass(frozen=True)
class StepInfo:
    """What a training step tells its strategy.

    screen_grads: (B, N, 2) ∂loss/∂mean2d per view (pixels), or None when the strategy does not
      ask for them (`needs_screen_grads`); visible: (B, N) bool, the Gaussians with tile pairs
      in each view (`RenderOutput.visible`); means_lr: the means' learning rate after this step
      (gsplat reads the scheduler after `scheduler.step()`); width, height: the image size;
      slots: (N,) int32, the slot each row of the pool holds where the rows are stored in
      another order (Gaussian-parallel training, `sharded`), or None (row i is slot i): draws
      per Gaussian are made per slot, so that they do not depend on the order.
    """

    screen_grads: Any
    visible: Any
    means_lr: Any
    width: int = dataclasses.field(metadata=dict(static=True))
    height: int = dataclasses.field(metadata=dict(static=True))
    slots: Any = None


@dataclasses.dataclass(frozen=True)
class Strategy:
    """A strategy that never densifies: the fixed-count base class (see the module docstring).

    init_opacity, init_scale: the initial opacity and the factor on the 3-nearest-neighbour
    distance that sets the initial scales (gsplat's simple_trainer `init_opa`, `init_scale`).
    """

    init_opacity: float = option(0.1, "the starting Gaussians' opacity", low=0, high=1)
    init_scale: float = option(
        1.0, "the starting scales: this times the distance to the 3 nearest points", low=0)
    needs_screen_grads = False  # class constant: whether `step` reads info.screen_grads

    def __post_init__(self):
        check(self, "strategy.")

    def init(self, pool: Pool, scene_scale: float):
        """The strategy's state (a pytree) for a new run on `pool`."""
        return {}

    def regularizer(self, params: dict, active):
        """A term added to the loss (traced; differentiated w.r.t. params)."""
        return jnp.zeros((), params["means"].dtype)

    def step(self, state, pool: Pool, opt_state, info: StepInfo, step, key):
        """Every step, after the optimizer update (traced): (state, pool, opt_state)."""
        return state, pool, opt_state

    def refine_due(self, step: int) -> bool:
        """Whether `refine` runs after 0-based step `step` (on the host: a Python int)."""
        return False

    def max_count(self, initial: int, steps: int, cap: int) -> int | None:
        """The most Gaussians a run of `steps` steps from `initial` can hold (on the host), or
        None where the strategy cannot bound it before the run: `fit` sizes the pool to the
        bound (no growth, so no recompile), else it doubles the pool when a refinement needs
        room."""
        return initial

    def refine(self, state, pool: Pool, opt_state, step, key, cap: int):
        """The densification (traced): (state, pool, opt_state, report), the report a dict of
        int32 counts holding at least `needed` (new slots it wanted) and `free` (free slots it
        found), and `ok`: False where the refinement would have made an active parameter
        non-finite and so changed nothing. When needed > free and the pool is below
        `cap`, `fit` grows the pool and calls it again with the same inputs. `fit` donates the
        state: a refinement that writes its rows in place holds the state once."""
        zero = jnp.int32(0)
        return state, pool, opt_state, dict(needed=zero, free=zero, ok=jnp.bool_(True))


def _count(mask):
    return jnp.sum(mask, dtype=jnp.int32)


def _select(flag, new, old):
    return jax.tree.map(lambda a, b: jnp.where(flag, a, b), new, old)



@dataclasses.dataclass(frozen=True)
class DefaultStrategy(Strategy):
    """The 3DGS adaptive density control, as gsplat 1.5.3's `DefaultStrategy` (same defaults).

    Every step s < refine_stop_iter: the screen-space gradient of each Gaussian visible in a view,
    scaled to [−1, 1] screen units as gsplat does (∂/∂x · W/2 · B, ∂/∂y · H/2 · B for a batch of
    B views; absgrad=False), adds its norm to `grad2d` and 1 to `count`.
    Refinement at s > refine_start_iter with s % refine_every == 0 (and s % reset_every >=
    pause_refine_after_reset), s < refine_stop_iter: with ḡ = grad2d / max(count, 1),
      clone  ḡ > grow_grad2d and max scale <= grow_scale3d · scene_scale;
      split  ḡ > grow_grad2d and larger (into 2, scales / 1.6; clones are not split);
      prune  opacity < prune_opa, or (s > reset_every) max scale > prune_scale3d · scene_scale
             (clones and split children included);
    then grad2d and count are zeroed. scene_scale is 1.1 x the largest camera distance from the
    cameras' mean centre. Visible: `RenderOutput.visible` (the 1/255 ellipse reaches a tile of
    the image) where gsplat counts radii > 0. At the cap (`fit`'s max_gaussians; gsplat has
    none) clones, then splits, take the free slots in order of ḡ, highest first. gsplat's
    screen-size rules (refine_scale2d_stop_iter, off by default) are not implemented.
    Opacity reset (opacities clamped to 2 · prune_opa at s % reset_every == 0, 0 < s <
    refine_stop_iter) is the 3DGS rule, but gsplat 1.5.3 never runs it: its test `step %
    reset_every == 0 & step > 0` parses as `step % reset_every == (0 & step) > 0`, always false
    (gsplat PR #776). So it is off by default (`opacity_reset=False`), like gsplat 1.5.3.
    """

    prune_opa: float = option(0.005, "prune below this opacity", low=0, high=1)
    grow_grad2d: float = option(0.0002, "clone or split above this mean screen gradient",
                                low=0)
    grow_scale3d: float = option(
        0.01, "clone up to this largest scale (times the scene scale), split above", low=0)
    prune_scale3d: float = option(
        0.1, "prune above this largest scale (times the scene scale) after the first "
             "opacity-reset period", low=0)
    refine_start_iter: int = option(500, "refine after this step", low=0)
    refine_stop_iter: int = option(15_000, "refine and accumulate gradients before this step",
                                   low=0)
    reset_every: int = option(3000, "steps between opacity resets (with --opacity-reset)",
                              low=1)
    refine_every: int = option(100, "steps between refinements", low=1)
    pause_refine_after_reset: int = option(
        0, "no refinement for this many steps after each reset period starts", low=0)
    revised_opacity: bool = option(
        False, "split children get the revised opacity 1 − sqrt(1 − o) (gsplat's "
               "revised_opacity)")
    opacity_reset: bool = option(
        False, "reset opacities every reset_every steps (3DGS; gsplat 1.5.3 never does, "
               "through a bug)")
    needs_screen_grads = True

    def init(self, pool: Pool, scene_scale: float):
        z = jnp.zeros(pool.size, pool.params["means"].dtype)  # the training arithmetic's
        return dict(grad2d=z, count=z, scene_scale=jnp.asarray(scene_scale, z.dtype))

    def step(self, state, pool: Pool, opt_state, info: StepInfo, step, key):
        g = info.screen_grads
        b = g.shape[0]
        g = g * jnp.asarray([info.width / 2.0 * b, info.height / 2.0 * b], g.dtype)
        norm = jnp.sqrt(jnp.sum(g * g, -1))
        vis = info.visible & pool.active[None]
        new = dict(state, grad2d=state["grad2d"] + jnp.sum(jnp.where(vis, norm, 0.0), 0),
                   count=state["count"] + jnp.sum(vis, 0, dtype=state["count"].dtype))
        return _select(step < self.refine_stop_iter, new, state), pool, opt_state

    def _grows(self, step):
        return ((step > self.refine_start_iter) & (step % self.refine_every == 0)
                & (step % self.reset_every >= self.pause_refine_after_reset)
                & (step < self.refine_stop_iter))

    def _resets(self, step):
        return (self.opacity_reset & (step > 0) & (step % self.reset_every == 0)
                & (step < self.refine_stop_iter))

    def refine_due(self, step: int) -> bool:
        return bool(self._grows(step) or self._resets(step))

    def max_count(self, initial: int, steps: int, cap: int) -> int | None:
        """None: clones and splits depend on the gradients (the pool doubles as needed)."""
        return None

    def refine(self, state, pool: Pool, opt_state, step, key, cap: int):
        """Clone, split, prune (class docstring), in place (`ops.clone_and_split`): nothing
        applied where a split child's value would not be finite (ok False)."""
        grows, resets = self._grows(step), self._resets(step)
        p = pool.params
        grads = state["grad2d"] / jnp.maximum(state["count"], 1.0)
        high = (grads > self.grow_grad2d) & pool.active & grows
        small = jnp.max(jnp.exp(p["log_scales"]), -1) <= self.grow_scale3d * state["scene_scale"]
        needed, free = _count(high), jnp.where(grows, _count(~pool.active), 0)
        pool, opt_state, cloned, split, ok = ops.clone_and_split(
            pool, opt_state, high & small, high & ~small, key, priority=grads,
            revised_opacity=self.revised_opacity)
        p = pool.params
        doomed = jax.nn.sigmoid(p["logit_opacities"]) < self.prune_opa
        too_big = jnp.max(jnp.exp(p["log_scales"]), -1) > self.prune_scale3d * state["scene_scale"]
        doomed = (doomed | ((step > self.reset_every) & too_big)) & pool.active & grows & ok
        pool, opt_state = ops.prune(pool, opt_state, doomed)
        zero = jnp.zeros_like(state["grad2d"])
        state = _select(grows & ok, dict(state, grad2d=zero, count=zero), state)
        reset_pool, reset_opt = ops.reset_opacity(pool, opt_state, 2.0 * self.prune_opa)
        pool, opt_state = _select(resets & ok, (reset_pool, reset_opt), (pool, opt_state))
        report = dict(cloned=_count(cloned), split=_count(split), pruned=_count(doomed),
                      needed=needed, free=free)
        return state, pool, opt_state, dict(report, reset=resets, ok=ok)


@dataclasses.dataclass(frozen=True)
class MCMCStrategy(Strategy):
    """3D Gaussian Splatting as Markov Chain Monte Carlo, as gsplat 1.5.3's `MCMCStrategy` with
    simple_trainer's MCMC recipe (init opacity 0.5, init scale 0.1, regularisers 0.01).

    Loss += opacity_reg · mean(opacity) + scale_reg · mean(scale) over the active Gaussians
    (all scale entries). Every step: `ops.inject_noise` with scaler = means_lr · noise_lr (the
    means' rate after this step). Refinement at refine_start_iter < s < refine_stop_iter,
    s % refine_every == 0: the Gaussians with opacity <= min_opacity are relocated onto alive
    ones (`ops.relocate`), then min(cap_max, cap, n + n // 20) − n Gaussians are added
    (`ops.sample_add`; n + n // 20 = int(1.05 · n) exactly, checked to n = 2·10⁷), where cap is
    the run's pool cap (`fit`'s max_gaussians).
    """

    init_opacity: float = option(0.5, "the starting Gaussians' opacity", low=0, high=1)
    init_scale: float = option(
        0.1, "the starting scales: this times the distance to the 3 nearest points", low=0)
    cap_max: int = option(1_000_000, "the number of Gaussians the additions stop at", low=1)
    noise_lr: float = option(5e5, "noise on the means: this times the means' learning rate",
                             low=0)
    refine_start_iter: int = option(500, "refine after this step", low=0)
    refine_stop_iter: int = option(25_000, "refine before this step", low=0)
    refine_every: int = option(100, "steps between refinements", low=1)
    min_opacity: float = option(0.005, "relocate Gaussians at or below this opacity", low=0,
                                high=1)
    opacity_reg: float = option(0.01, "weight of the mean opacity in the loss", low=0)
    scale_reg: float = option(0.01, "weight of the mean scale in the loss", low=0)

    def regularizer(self, params: dict, active):
        n = jnp.maximum(jnp.sum(active), 1).astype(params["means"].dtype)
        o = jnp.where(active, jax.nn.sigmoid(params["logit_opacities"]), 0.0)
        s = jnp.where(active[:, None], jnp.exp(params["log_scales"]), 0.0)
        return self.opacity_reg * jnp.sum(o) / n + self.scale_reg * jnp.sum(s) / (3 * n)

    def step(self, state, pool: Pool, opt_state, info: StepInfo, step, key):
        return (state, ops.inject_noise(pool, key, info.means_lr * self.noise_lr, info.slots),
                opt_state)

    def refine_due(self, step: int) -> bool:
        return (self.refine_start_iter < step < self.refine_stop_iter
                and step % self.refine_every == 0)

    def max_count(self, initial: int, steps: int, cap: int) -> int | None:
        """`refine`'s additions replayed over the run's refinements: n becomes
        min(cap_max, cap, n + n // 20) at each (relocation keeps n), an exact upper bound."""
        n, bound = initial, min(self.cap_max, cap)
        for step in range(steps):
            if n >= bound:
                break
            if self.refine_due(step):
                n = max(min(bound, n + n // 20), n)
        return n

    def refine(self, state, pool: Pool, opt_state, step, key, cap: int):
        o = jax.nn.sigmoid(pool.params["logit_opacities"])
        n = _count(pool.active)
        want = jnp.maximum(jnp.minimum(min(self.cap_max, cap), n + n // 20) - n, 0)
        free = _count(~pool.active)
        pool, opt_state, moved, added, ok = ops.relocate_and_add(
            pool, opt_state, o <= self.min_opacity, want, jax.random.split(key),
            self.min_opacity)
        return state, pool, opt_state, dict(relocated=_count(moved), added=_count(added),
                                            needed=want, free=free, ok=ok)

