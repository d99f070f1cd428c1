"""`fit`'s watch hook (`Watch`): the Gaussians as rendered, handed to a callable while
training, at most every so many seconds."""

from __future__ import annotations

import time

import jax
import jax.numpy as jnp
import numpy as np

from ..parallel import to_host
from . import state
from .state import RunState


class Watch:
    """Calls `fn(step, gaussians, metrics)` with the pool as `render` sees it (inactive slots
    as culled placeholders, every SH band; on one device, or on the host where the pool is
    split over devices: `gathered`) when `every` seconds have passed since the last call, or
    when forced."""

    def __init__(self, fn, every: float, devices: int, gathered: bool = False):
        self.fn, self.every, self.devices, self.last = fn, every, devices, -float("inf")
        self.gathered = gathered

    def due(self) -> bool:
        """Whether a call now, unforced, would call `fn`."""
        return self.fn is not None and time.perf_counter() - self.last >= self.every

    def __call__(self, st: RunState, metrics: dict, force: bool = False) -> None:
        now = time.perf_counter()
        if self.fn is None or not (force or now - self.last >= self.every):
            return
        pool = state.scene(st)
        # copies: the next step donates the pool, whose arrays `shown` may pass through
        g = jax.tree.map(jnp.copy, state.shown(pool.params, pool.active))
        if self.gathered:  # split over devices: the rows whole on the host
            g = to_host(g)
        elif self.devices > 1:  # replicated: one device's copy, no transfer
            g = jax.tree.map(lambda x: x.addressable_data(0), g)
        self.fn(st.step, g, metrics)
        self.last = now


def check_hooks(watch, watch_every) -> None:
    """Raise `ValueError` for a watch that is not callable or a bad watch_every."""
    if watch is not None and not callable(watch):
        raise ValueError(f"watch: expected None or a callable, got {type(watch).__name__}")
    if not (isinstance(watch_every, (int, float, np.integer, np.floating))
            and not isinstance(watch_every, bool) and watch_every >= 0):
        raise ValueError(f"watch_every: expected seconds >= 0, got {watch_every!r}")
