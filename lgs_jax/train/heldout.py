"""Held-out evaluations during training that cost the run milliseconds (`Evaluations`), and
scikit-image's PSNR and SSIM on the device (`view_scores`).

At an evaluation step the held-out views are rendered from that step's pool and scored on the
device; only the scores (a few floats per view) cross to the host: no image is copied and no
scoring runs in Python, where scikit-image took seconds per evaluation. The loop waits for the
scores before its next step, so the renders' buffers never sit beside a training step's. The
pair buffer of the held-out renders is sized by counting the views' pairs first with the run's
pair headroom, so that it grows, a compile each, about as rarely as the training step's. The
programs are compiled ahead as the training step's are (`ahead.Stepper`, the run's mode): the
first evaluation's from the run's first step on (`Evaluations.ahead`), and after each
evaluation the pair capacity a growth would pick next; the same renders and scores, whichever
program runs them. The final evaluation (`outputs.finish`) renders through the same program
(`Evaluations.images`) and scores with scikit-image's own (`report.heldout_metrics`), on the
host.

`view_scores` computes scikit-image's defaults, `peak_signal_noise_ratio(data_range=1)` and
`structural_similarity(channel_axis=-1, data_range=1)` (7x7 uniform window, sample covariance
49/48, C1 = 0.01², C2 = 0.03², the mean over the pixels whose window lies inside the image and
over the channels), in float32 where scikit-image computes in float64: the same numbers up to
float32 rounding (tests/train/test_heldout.py compares them).
"""

from __future__ import annotations

import functools

import jax
import jax.numpy as jnp
import numpy as np

from ..config import RasterConfig
from ..render import count_pairs
from .ahead import Sizes, Stepper, signature
from .config import Setup
from .pool import Pool, render_gaussians
from .step import COMPILER_OPTIONS

WINDOW = 7  # scikit-image's default SSIM window (uniform)


def _uniform(x):
    """The mean over each WINDOW x WINDOW window of (H, W, C) x that lies inside the image:
    (H − 6, W − 6, C), scikit-image's uniform filter on the pixels its SSIM averages."""
    h, w = x.shape[0] - WINDOW + 1, x.shape[1] - WINDOW + 1
    rows = sum(x[k:k + h] for k in range(WINDOW))
    return sum(rows[:, k:k + w] for k in range(WINDOW)) / WINDOW**2


def view_scores(image, target):
    """(PSNR, SSIM) of an (H, W, C) image against its target, both in [0, 1] (the image
    clipped), as scikit-image's defaults compute them (module docstring)."""
    image = jnp.clip(image, 0.0, 1.0)
    psnr = -10.0 * jnp.log10(jnp.mean((target - image) ** 2))
    cov = WINDOW**2 / (WINDOW**2 - 1)
    ux, uy = _uniform(image), _uniform(target)
    vx = cov * (_uniform(image * image) - ux * ux)
    vy = cov * (_uniform(target * target) - uy * uy)
    vxy = cov * (_uniform(image * target) - ux * uy)
    c1, c2 = 0.01**2, 0.03**2
    s = ((2 * ux * uy + c1) * (2 * vxy + c2)) / ((ux**2 + uy**2 + c1) * (vx + vy + c2))
    return psnr, jnp.mean(s)


@functools.partial(jax.jit, static_argnames=("backend", "capacity", "config"),
                   compiler_options=COMPILER_OPTIONS)
def _scored(pool: Pool, cam, target, background, *, backend: str, capacity: int,
            config: RasterConfig):
    """(PSNR, SSIM, overflow, image) of one held-out view rendered from `pool`."""
    from ..render import render

    out = render(render_gaussians(pool.params, pool.active), cam, background=background,
                 backend=backend, capacity=capacity, config=config)
    psnr, ssim = view_scores(out.image, target)
    return psnr, ssim, out.stats.overflow, out.image


@functools.partial(jax.jit, static_argnames="antialiased")
def _pairs(pool: Pool, cam, antialiased: bool):
    return count_pairs(render_gaussians(pool.params, pool.active), cam, antialiased=antialiased)


def compiled_programs() -> tuple[int, int]:
    """How many programs `jax.jit` holds compiled for the evaluations' pair counts and
    renders (compiles ahead are not among them)."""
    return _pairs._cache_size(), _scored._cache_size()


class Evaluations:
    """The held-out views of a run, scored on the device (module docstring): `score(pool)` is
    the (PSNR, SSIM) of the pool over the views, averaged; `images(pool)` the renders.
    `capacity`: the held-out renders' pair buffer, grown here (a checkpoint keeps it). `mode`:
    the compiles ahead's (`ahead.Stepper`; None: none); `close` ends them."""

    def __init__(self, cams, targets, background, setup: Setup, capacity: int,
                 headroom: float, mode: str | None = None):
        self.cams, self.targets = list(cams), targets
        self.background = jnp.asarray(background)
        self.setup, self.capacity, self.headroom = setup, capacity, headroom
        raster = setup.recipe.raster
        self._counts = Stepper(_pairs, lambda size: dict(antialiased=raster.antialiased),
                               Sizes(headroom), mode)
        self._renders = Stepper(_scored, lambda size: dict(
            backend=setup.backend, capacity=size[0], config=raster), Sizes(headroom), mode)
        self.started = False  # `ahead` ran

    def _views(self, pool: Pool, targets=None) -> list[tuple]:
        """Per view, `_pairs`' and `_scored`'s arguments for `pool`."""
        targets = self.targets if targets is None else targets
        return [((pool, cam), (pool, cam, target, self.background))
                for cam, target in zip(self.cams, targets)]

    def ahead(self, pool: Pool) -> None:
        """Start compiling the programs of an evaluation of a pool shaped as `pool`, for each
        size of the views, at the current capacity (a no-op after the first call)."""
        if self.started:
            return
        self.started = True
        shapes = lambda x: jax.ShapeDtypeStruct(np.shape(x), x.dtype)
        for counted, rendered in self._views(pool, [shapes(t) for t in self.targets]):
            self._counts.ahead(counted, (0, None))
            self._renders.ahead(rendered, (self.capacity, None))

    def after_step(self, step: int, every: int, steps: int, pool) -> None:
        """After step `step` of `steps` (evaluations every `every` steps and at the end;
        `pool()` the pool): the first step starts the compiles `ahead`; half an interval
        before each evaluation, `prepare`."""
        if not self._renders.compiles_ahead:
            return
        if not self.started:
            self.ahead(pool())
        lead = max(1, min(every, steps) // 2)
        if (step + lead) % every == 0 or step + lead == steps:
            self.prepare(pool())

    def prepare(self, pool: Pool) -> None:
        """Ahead of an evaluation: where the views of `pool` need more pairs than the
        capacity, start compiling the render at the capacity they would grow it to (a growth
        by the evaluation takes it where it holds the evaluation's need)."""
        if not self._renders.compiles_ahead:
            return
        views = self._views(pool, [jnp.asarray(t) for t in self.targets])
        need = self._need(views, [(signature(c), signature(r)) for c, r in views])
        if need > self.capacity:
            size = Sizes(self.headroom).grown((self.capacity, None), (need, 0))
            self._renders.prepare_at(views[0][1], size, signature(views[0][1]))

    def _need(self, views: list[tuple], sigs: list[tuple]) -> int:
        """The most pairs of a view; every count dispatched before the one read."""
        return int(max(jax.device_get([self._counts.run(c, (0, None), s)
                                       for (c, _), (s, _) in zip(views, sigs)])))

    def _rendered(self, pool: Pool, then: bool = True) -> list[tuple]:
        """(PSNR, SSIM, overflow, image) per view, on the device, the pair buffer grown to
        the views' need first; with `then`, the next growth's render compiled ahead."""
        views = self._views(pool, [jnp.asarray(t) for t in self.targets])
        sigs = [(signature(c), signature(r)) for c, r in views]
        need = self._need(views, sigs)
        size = (self.capacity, None)
        if need > self.capacity:
            size = self._renders.grow(size, (need, 0), sigs[0][1])[0]
            self.capacity = size[0]
        out = [self._renders.run(r, size, s) for (_, r), (_, s) in zip(views, sigs)]
        if then:
            self._renders.prepare(views[0][1], size, sigs[0][1])  # the next growth's, ahead
        return out

    def score(self, pool: Pool) -> tuple[float, float]:
        scores = _read([o[:3] for o in self._rendered(pool)], flag=2)
        return (float(np.mean([p for p, _, _ in scores])),
                float(np.mean([s for _, s, _ in scores])))

    def images(self, pool: Pool) -> list[np.ndarray]:
        """Each held-out view of `pool` rendered, (H, W, 3) float numpy clipped to [0, 1]: the
        run's final evaluation, after which nothing is compiled ahead (a compile under way
        would hold the process's exit)."""
        return [np.clip(np.asarray(image), 0.0, 1.0)
                for _, image in _read([o[2:] for o in self._rendered(pool, False)], flag=0)]

    def close(self) -> None:
        """End the compiles ahead (a compile under way finishes unwaited)."""
        self._counts.close()
        self._renders.close()


def _read(outputs: list, flag: int) -> list[tuple]:
    """The views' outputs on the host, in one wait; o[flag] is each one's overflow."""
    got = jax.device_get(outputs)
    if any(bool(o[flag]) for o in got):  # the pairs were counted first: cannot happen
        raise RuntimeError("a held-out view overflowed its pair buffer")
    return got
