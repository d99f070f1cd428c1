"""The child process of tests/parallel/test_gaussian_parallel_training.py: `fit` with the
Gaussians split over 1, 2 and 4 simulated CPU devices (`--xla_force_host_platform_device_count`,
set before JAX starts), on a synthetic capture made here (`capture`), each run's folder left
under OUT for the parent to compare (`python -m tests.parallel.training_child OUT PART`).
OUT/logs.json holds what the folders cannot: each run's log lines.

The runs (`PARTS`): "fast", two views per step, the run on 1 device stopped (Ctrl-C) after step
`HALF` and resumed on 1 device and on a 2 x 2 mesh (devices=2 rows of gaussian_devices=2, a view
per row), the latter with buffers sized at the first view's needs exactly (they overflow and
grow), all on every view (nothing held out, an evaluation due at every step), then each
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
from lgs_jax.io.datasets import Dataset  # noqa: E402

W, H = 32, 64  # 2 x 4 tiles: a band of one tile row per device on 4 devices
VIEWS = 5  # view 0 held out
POINTS = 301  # blocks of 151 + 150 on 2 devices, 76 + 3 x 75 on 4: uneven shards
POOL = 1024  # slots; no growth in the runs
STEPS, HALF = 8, 4
# refinements at steps 3 and 6, clones only (no split: grow_scale3d beyond any Gaussian), and
# prunes, never short of slots (a refinement at the cap ranks its candidates by their
# gradients): the parameters' differences across device counts stay within
# `sharded.drift_bound`
STRATEGY = train.DefaultStrategy(refine_start_iter=2, refine_every=3, grow_grad2d=3e-4,
                                 prune_opa=0.02, grow_scale3d=100.0)
REFINED = dict(  # `STRATEGY` (its one-device program compiled by the runs) and MCMC's
    default=STRATEGY, mcmc=train.MCMCStrategy(refine_start_iter=0, refine_every=1, cap_max=400))
PARTS = dict(fast=("d1", "d1_resumed_on_2x2"),
             slow=("d1", "d2", "d4", "mcmc_views_d2", "mcmc_views_2x2"))
# SH degree 0: within the runs' steps the higher bands are masked anyway (`Recipe.sh_every`),
# and their evaluation costs each step's compile a third more; the fast part's two views per
# step split over the 2 rows of its 2 x 2 mesh
RECIPE = train.Recipe(batch=1, sh_degree=0)
BATCH = dict(fast=2, slow=1)
# the view the refinements balance their blocks' work over: 4 units in front of the points
VIEW = lgs_jax.Camera(viewmat=np.array([[1, 0, 0, 0], [0, 1, 0, 0], [0, 0, 1, 4], [0, 0, 0, 1]],
                                       np.float32), fx=np.float32(40), fy=np.float32(40),
                      cx=np.float32(32), cy=np.float32(16), width=64, height=32)

# the slow part's last run: MCMC (refinements at steps 3 and 6) with the views' own parameters
MCMC = train.MCMCStrategy(refine_start_iter=2, refine_every=3, cap_max=400)


def capture(path: str) -> Dataset:
    """`VIEWS` cameras on an arc 3 units from a box of `POINTS` coloured points, photos of
    smooth random colour waves (the same capture every call)."""
    rng = np.random.default_rng(0)
    cams, images = [], []
    y, x = np.mgrid[0:H, 0:W] / np.float32(H)
    for i in range(VIEWS):
        a = 0.15 * (i - VIEWS // 2)
        c, s = np.cos(a), np.sin(a)
        view = np.eye(4)
        view[:3, :3] = [[c, 0, -s], [0, 1, 0], [s, 0, c]]
        view[:3, 3] = [0.0, 0.0, 3.0]
        cams.append(lgs_jax.Camera(viewmat=view.astype(np.float32), fx=np.float32(40),
                                   fy=np.float32(40), cx=np.float32(W / 2),
                                   cy=np.float32(H / 2), width=W, height=H))
        f = rng.uniform(2, 6, 3)
        images.append(0.5 + 0.4 * np.sin(f * (x[..., None] + y[..., None] + a) + rng.uniform(
            0, 6, 3)))
    points = rng.uniform(-0.6, 0.6, (POINTS, 3)).astype(np.float32)
    points[:, 1] *= 2  # the image is twice as high as wide
    return Dataset(path=path, names=tuple(f"v{i}.png" for i in range(VIEWS)),
                   images=np.stack(images).astype(np.float32), cameras=tuple(cams),
                   points=points, colors=rng.uniform(0, 1, (POINTS, 3)).astype(np.float32),
                   train=np.arange(1, VIEWS), test=np.arange(1), background=np.zeros(3, np.float32))


def config(out: str, gaussians: int, **kwargs) -> train.FitConfig:
    """The runs' configuration with the Gaussians split over `gaussians` devices (kwargs: other
    fields)."""
    kwargs = dict(dict(pair_headroom=4.0, strategy=STRATEGY, recipe=RECIPE, eval_every=100),
                  **kwargs)
    return train.FitConfig(data=out, out=out, steps=STEPS, max_gaussians=POOL, pool_size=POOL,
                           backend="reference", gaussian_devices=gaussians,
                           checkpoint_every=100, **kwargs)


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
        # the views split over 2 rows, the Gaussians over the 2 devices of each
        fit("d1_resumed_on_2x2", 2, devices=2, resume=True, pair_headroom=1.0)
        logs["refinements"] = refinements()
    with open(os.path.join(out, "logs.json"), "w") as f:
        json.dump(logs, f)


if __name__ == "__main__":
    main(sys.argv[1], sys.argv[2])
