"""The child process of tests/parallel/test_gaussian_parallel_training.py: `fit` with the
Gaussians split over 1, 2 and 4 simulated CPU devices (`--xla_force_host_platform_device_count`,
set before JAX starts), on a synthetic capture (`tiny_run.capture`), each run's folder left
under OUT for the parent to compare (`python -m tests.parallel.training_child OUT PART`).
OUT/logs.json holds what the folders cannot: each run's log lines.

The runs (`PARTS`): "fast", two views per step, the run on 1 device stopped (Ctrl-C) after step
`HALF` and resumed on 1 device and on a 2 x 2 mesh (devices=2 rows of gaussian_devices=2, a view
per row), the latter with its exchange sized at the first view's needs exactly (it overflows and
grows), all on every view (nothing held out, an evaluation due at every step), then each
strategy's refinement of one state on 1 and 4 devices (`refinements`); "slow", one view per
step, the same run on 1, 2 and 4 devices, view 0 held out and evaluated, and an MCMC run on 2
devices optimizing the views' poses, colours and bilateral grids, and on a 2 x 2 mesh (two
views per step). Few compiles (each costs
seconds on a CPU): the runs share one configuration (`RECIPE`, the part's `BATCH`) but for
their devices and buffers."""

import dataclasses
import json
import os
import shutil
import signal
import sys

os.environ["XLA_FLAGS"] = "--xla_force_host_platform_device_count=4"
os.environ.setdefault("JAX_PLATFORMS", "cpu")

import jax  # noqa: E402
import numpy as np  # noqa: E402

if os.environ.get("LGS_JAX_CACHE"):
    from lgs_jax.cli import cache_into  # the parent's lock (its test workers share the folder)

    cache_into(os.environ["LGS_JAX_CACHE"], least_seconds=0.5)

import jax.numpy as jnp  # noqa: E402
import lgs_jax  # noqa: E402
from lgs_jax import train  # noqa: E402
from lgs_jax.train import sharded, sharded_state, step  # noqa: E402
from tests.parallel.tiny_run import (  # noqa: E402
    HALF, POINTS, POOL, RECIPE, STEPS, STRATEGY, capture, config)

REFINED = dict(  # `STRATEGY` (its one-device program compiled by the runs) and MCMC's
    default=STRATEGY, mcmc=train.MCMCStrategy(refine_start_iter=0, refine_every=1, cap_max=400))
PARTS = dict(fast=("d1", "d1_resumed_on_2x2"),
             slow=("d1", "d2", "d4", "mcmc_views_d2", "mcmc_views_2x2"))
BATCH = dict(fast=2, slow=1)
# the view the refinements balance their blocks' work over: 4 units in front of the points
VIEW = lgs_jax.Camera(viewmat=np.array([[1, 0, 0, 0], [0, 1, 0, 0], [0, 0, 1, 4], [0, 0, 0, 1]],
                                       np.float32), fx=np.float32(40), fy=np.float32(40),
                      cx=np.float32(32), cy=np.float32(16), width=64, height=32)

# the slow part's last run: MCMC (refinements at steps 3 and 6) with the views' own parameters
MCMC = train.MCMCStrategy(refine_start_iter=2, refine_every=3, cap_max=400)


def refinements() -> dict:
    """Each strategy's refinement (`REFINED`) of one state of `POOL` slots, a third of its
    Gaussians above the default strategy's gradient threshold, on one device (`step.refine`)
    and on 4 (`sharded_state.refine`): whether the 4 devices' result, back in slot order, is
    the same bits; the Gaussians before and after; the blocks' active counts."""
    rng = np.random.default_rng(1)
    n = POINTS
    g = lgs_jax.Gaussians(
        rng.normal(size=(n, 3)).astype(np.float32), rng.normal(size=(n, 4)).astype(np.float32),
        rng.normal(-2, 0.7, (n, 3)).astype(np.float32), rng.normal(-3, 2, n).astype(np.float32),
        rng.normal(size=(n, (RECIPE.sh_degree + 1) ** 2, 3)).astype(np.float32))
    pool = train.from_gaussians(g, POOL)
    opt = train.optimizer(RECIPE, STEPS, 1.0).init(pool.params)
    key, out, mesh = jax.random.key(5), {}, sharded.mesh(4)
    for name, strategy in REFINED.items():
        state = strategy.init(pool, 1.0)
        if "grad2d" in state:
            state = dict(state, grad2d=jnp.asarray(rng.uniform(0, 4.5 * STRATEGY.grow_grad2d,
                                                               POOL), jnp.float32),
                         count=jnp.ones(POOL, jnp.float32))
        one = step.refine(strategy, state, pool, opt, 3, key, POOL)
        parts, order = sharded_state.balanced(mesh, (pool, opt, state),
                                              sharded_state.work(pool, [VIEW], False))
        s4, p4, o4, report, order = sharded_state.refine(strategy, parts[2], parts[0], parts[1],
                                                         order, 3, key, POOL, mesh, [VIEW])
        back = sharded_state.in_slot_order(mesh, (p4, o4, s4), order)
        same = [bool(np.array_equal(a, b)) for a, b in zip(
            jax.tree.leaves((one[1], one[2], one[0])), jax.tree.leaves(back))]
        out[name] = dict(same=same, per_device=report["per_device"],
                         per_device_work=report["per_device_work"], heaviest=report["heaviest"],
                         before=int(np.sum(pool.active)), after=int(np.sum(one[1].active)))
    return out


def main(out: str, part: str):
    data = capture(os.path.join(out, "data"))
    logs = {name: [] for name in PARTS[part]}
    where = lambda name: os.path.join(out, name)

    def fit(name, gaussians, watch=None, **kwargs):
        # the fast part trains on every view and evaluates nothing (its compiles would cost
        # more than its steps), though an evaluation is due after every step
        fast = dict(train_on_all=True, eval_every=1) if part == "fast" else {}
        kwargs = dict(dict(recipe=dataclasses.replace(RECIPE, batch=BATCH[part])), **kwargs)
        train.fit(config(where(name), gaussians, **fast, **kwargs), data, log=logs[name].append,
                  watch=watch, watch_every=0)

    if part == "slow":
        fit("d1", 1)
        fit("d2", 2)
        fit("d4", 4)
        views = dataclasses.replace(RECIPE, pose_opt=True, color_opt=True, bilateral_grid=True)
        fit("mcmc_views_d2", 2, strategy=MCMC, recipe=views)
        # and on a 2 x 2 mesh, a view per row (the held-out view rendered on both rows)
        fit("mcmc_views_2x2", 2, devices=2, strategy=MCMC,
            recipe=dataclasses.replace(views, batch=2))
    else:
        stop = lambda step, *_: step == HALF and os.kill(os.getpid(), signal.SIGINT)
        try:
            fit("d1", 1, watch=stop)
        except train.Interrupted:
            pass
        shutil.copytree(where("d1"), where("d1_resumed_on_2x2"))
        fit("d1", 1, resume=True)  # the same bits as a run that never stopped
        # the views split over 2 rows, the Gaussians over the 2 devices of each; the buffers
        # sized at the first view's pairs and records exactly: the exchange overflows after the
        # refinement at step 6 and both grow at once (one recompile; the render counts the
        # pairs of the records it left behind)
        first_sizes = sharded_state.first_sizes

        def exact(m, pool, cam, antialiased, headroom):
            return first_sizes(m, pool, cam, antialiased, 1.0)

        sharded_state.first_sizes = exact
        try:
            fit("d1_resumed_on_2x2", 2, devices=2, resume=True)
        finally:
            sharded_state.first_sizes = first_sizes
        logs["refinements"] = refinements()
    with open(os.path.join(out, "logs.json"), "w") as f:
        json.dump(logs, f)


if __name__ == "__main__":
    main(sys.argv[1], sys.argv[2])
